"""An example of one's own world model and policy in gymnast.

`diffusion` is an action-conditioned video diffusion model written as an outside project would
write one, knowing nothing of gymnast; `gymnast_plugin` wraps it in gymnast's `WorldModel`
contract; `policy` is a small policy of one's own that keeps the `Policy` contract. The package's
pyproject.toml registers both factories under short names (``plugin:tiny-video``,
``plugin:tiny-policy``); docs/world_model.md and docs/policy.md walk through it.
"""
