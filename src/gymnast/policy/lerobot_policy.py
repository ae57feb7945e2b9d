"""A LeRobot policy behind gymnast's `Policy` contract: what every kind of LeRobot policy shares.

The LeRobot policy (a ``PreTrainedPolicy``) stays itself: its own pre- and post-processors
normalise the inputs and unnormalise the actions, and its own modules predict. What gymnast adds
is the exploration RL needs, with exact log-probabilities, in the policy's normalised action
units: a stochastic flow sampler for flow-matching policies (`gymnast.policy.lerobot_flow`) and a
Gaussian head on the predicted chunk for the others (`gymnast.policy.lerobot_gaussian`). Its
deterministic action (`act`) is exactly what LeRobot's ``predict_action_chunk`` gives, so after RL
`export` writes a LeRobot ``pretrained_model`` folder that LeRobot's ``from_pretrained`` loads and
that acts as the policy did in gymnast.

A gymnast checkpoint of such a policy saves the LeRobot folder's small files (config and
processor JSON, the processors' statistics) in its spec, and all weights (the LeRobot policy's
and the exploration head's) as usual, so an RL run loads and resumes without the folder it
started from.

Legend: B batch, K chunk length gymnast executes, A action dimensions, N = K * A.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import torch
from torch import nn

from gymnast.policy.lerobot_features import ACTION, LeRobotFeatures
from gymnast.policy.lerobot_import import require_lerobot
from gymnast.policy.observation import simulator_cameras
from gymnast.utils.atomic import read_json

WEIGHTS = "model.safetensors"
"""The LeRobot policy's weights in a pretrained_model folder (gymnast's checkpoint holds them)."""


@dataclass(frozen=True)
class ExplorationConfig:
    """The exploration noise gymnast adds for RL, in the policy's normalised action units."""

    sigma_min: float = 0.02
    """Smallest standard deviation of a step (flow) or an action (Gaussian head)."""
    sigma_max: float = 0.3
    """Largest standard deviation."""
    sigma_init: float = 0.1
    """The standard deviation before RL trains it."""

    def __post_init__(self) -> None:
        if not 0 < self.sigma_min < self.sigma_init < self.sigma_max:
            raise ValueError(f"ExplorationConfig needs 0 < sigma_min < sigma_init < sigma_max, got "
                             f"{self.sigma_min}, {self.sigma_init}, {self.sigma_max}")


@dataclass(frozen=True)
class LeRobotArchitecture:
    """What gymnast reads off a policy's ``config``: the views it renders and the chunk it executes."""

    type: str
    image_size: int
    chunk_size: int
    action_dim: int
    cameras: tuple[str, ...]
    """The cameras the policy reads side by side (`LeRobotFeatures.cameras`)."""

    @property
    def env_cameras(self) -> tuple[str, ...]:
        """The simulator's views that show the policy its cameras (`simulator_cameras`)."""
        return simulator_cameras(self.cameras)


class LeRobotPolicy(nn.Module):
    """Base of the adapters: loading, inputs, the deterministic chunk, persistence and imitation.

    Args:
        policy: the LeRobot ``PreTrainedPolicy`` (a submodule: RL trains its parameters).
        preprocessor: its input pipeline (normalisation, tokenisation).
        postprocessor: its output pipeline (unnormalisation).
        files: the pretrained folder's small files (`read_folder`), written back by `export`.
        source: where it came from, for messages.
        exploration: the exploration noise's settings.
    """

    def __init__(self, policy: nn.Module, preprocessor, postprocessor, files: dict, source: str,
                 exploration: ExplorationConfig) -> None:
        super().__init__()
        self.policy, self.preprocessor, self.postprocessor = policy, preprocessor, postprocessor
        self.files, self.source, self.exploration = files, source, exploration
        self.features = LeRobotFeatures.of(policy.config, source)
        self.chunk_size, self.action_dim = self.features.chunk_size, self.features.action_dim
        self.state_dim = self.features.state_dim
        self.config = LeRobotArchitecture(policy.config.type, self.features.image_size, self.chunk_size,
                                          self.action_dim, self.features.cameras)
        self.eval()

    # -- what the kinds of policy provide ------------------------------------------------------------

    def mean_chunk(self, batch: dict[str, Any]) -> torch.Tensor:
        """(B, predicted, A) the deterministic chunk in normalised units, from a preprocessed batch."""
        raise NotImplementedError

    # -- the Policy protocol ------------------------------------------------------------------------

    @torch.no_grad()
    def act(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, K, A) what LeRobot's ``predict_action_chunk`` gives, unnormalised: the first K actions."""
        return self.to_actions(self.mean_chunk(self.inputs(obs, instructions, states))[:, : self.chunk_size])

    def chunk_tokens(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, A) actions -> the record of a greedy rollout, which is never trained on."""
        raise NotImplementedError

    def log_prob_and_entropy(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                             temperature: float = 1.0, states: torch.Tensor | None = None
                             ) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, N) log-density of each sampled action element (differentiable) and its entropy."""
        raise NotImplementedError

    def log_prob(self, obs: torch.Tensor, instructions: Sequence[str], tokens: torch.Tensor,
                 temperature: float = 1.0, states: torch.Tensor | None = None) -> torch.Tensor:
        """(B, N) log-density of each sampled action element; differentiable."""
        return self.log_prob_and_entropy(obs, instructions, tokens, temperature, states)[0]

    # -- inputs and outputs -------------------------------------------------------------------------

    def inputs(self, obs: torch.Tensor, instructions: Sequence[str], states: torch.Tensor | None = None,
               actions: torch.Tensor | None = None) -> dict[str, Any]:
        """The preprocessed batch for (B, H, V*W, 3) uint8 images (V cameras side by side),
        instructions, (B, D) robot states where the policy reads them, and optionally
        (B, predicted, A) actions in env units, on the policy's device."""
        batch = self.features.batch(obs.cpu(), instructions, None if states is None else states.cpu())
        if actions is not None:
            batch[ACTION] = actions.float().cpu()
        batch = self.preprocessor(batch)
        device = self.device
        return {key: value.to(device) if isinstance(value, torch.Tensor) else value for key, value in batch.items()}

    def to_actions(self, chunk: torch.Tensor) -> torch.Tensor:
        """(B, k, A) normalised actions -> (B, k, A) float32 actions in env units, on the host."""
        return self.postprocessor(chunk.detach().float().cpu()).float()

    @property
    def device(self) -> torch.device:
        return next(self.policy.parameters()).device

    # -- supervised learning (the imitation anchor) ------------------------------------------------

    def imitation_loss(self, images: torch.Tensor, texts: Sequence[str], chunks: torch.Tensor, valid: torch.Tensor,
                       bf16: bool = False, generator: torch.Generator | None = None,
                       states: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
        """LeRobot's own training loss (its ``forward``) on expert chunks (B, K, A) with (B, K) valid
        (and the (B, D) robot states they were taken in, for a policy that reads them).

        The chunk is padded to the policy's predicted length with its last valid action, marked as
        padding; LeRobot's own random draws (flow times, noise) come from `generator`.
        """
        predicted = self.features.predicted
        steps = torch.arange(chunks.shape[1])
        last = torch.where(valid, steps, 0).cummax(dim=1).values[:, -1]  # (B,) the last valid action
        held = chunks[torch.arange(len(chunks)), last][:, None].expand(-1, predicted, -1).clone()  # (B, P, A)
        held[:, : chunks.shape[1]] = torch.where(valid[:, :, None], chunks, held[:, : chunks.shape[1]])
        pad = torch.ones(len(chunks), predicted, dtype=torch.bool)
        pad[:, : chunks.shape[1]] = ~valid
        batch = self.inputs(images, texts, states, held)
        # ACT names the padding action_is_pad; SmolVLA reads actions_id_pad.
        batch |= {"action_is_pad": pad.to(self.device), "actions_id_pad": pad.to(self.device)}
        seed = int(torch.randint(2**62, (1,), generator=generator)) if generator is not None else None
        # In training mode, as LeRobot trains it (ACT's VAE encoder only runs then); back to eval
        # after, since sampling and log-probabilities must see one and the same network.
        self.policy.train()
        try:
            with torch.random.fork_rng(devices=[]):
                if seed is not None:
                    torch.manual_seed(seed)
                loss = self.policy.forward(batch)[0]
        finally:
            self.policy.eval()
        return loss, {"train/loss": loss.item()}

    # -- persistence --------------------------------------------------------------------------------

    def spec(self) -> dict:
        """What rebuilds this policy (saved as config.json): the LeRobot folder's small files."""
        return {"lerobot": {"files": self.files, "exploration": asdict(self.exploration), "source": self.source}}

    def export(self, out: Path) -> Path:
        """Writes a LeRobot ``pretrained_model`` folder to `out` (weights as trained, the
        processors as loaded) and returns it; the exploration head stays in gymnast's checkpoint."""
        out = Path(out)
        staging = out.with_name(out.name + ".tmp")  # written whole, then swapped in: never half a folder
        shutil.rmtree(staging, ignore_errors=True)
        write_folder({name: content for name, content in self.files.items() if name != "config.json"}, staging)
        self.policy.save_pretrained(staging)
        shutil.rmtree(out, ignore_errors=True)
        staging.rename(out)
        return out


def read_folder(folder: Path) -> dict:
    """A pretrained_model folder's files except the weights: JSON as dicts, the processors'
    safetensors (their statistics, a few numbers) as {key: nested lists}."""
    from safetensors.torch import load_file

    files: dict[str, Any] = {}
    for path in sorted(Path(folder).iterdir()):
        if path.suffix == ".json":
            files[path.name] = read_json(path)
        elif path.suffix == ".safetensors" and path.name != WEIGHTS:
            files[path.name] = {key: {"dtype": str(value.dtype).removeprefix("torch."), "data": value.tolist()}
                                for key, value in load_file(path).items()}
    if "config.json" not in files:
        raise FileNotFoundError(f"{folder} has no config.json: a LeRobot pretrained_model folder has config.json, "
                                f"{WEIGHTS} and its processors' files")
    return files


def write_folder(files: dict, out: Path) -> None:
    """Writes what `read_folder` read into `out` (created if needed)."""
    from safetensors.torch import save_file

    out.mkdir(parents=True, exist_ok=True)
    for name, content in files.items():
        if name.endswith(".json"):
            (out / name).write_text(json.dumps(content, indent=4))
        else:
            save_file({key: torch.tensor(value["data"], dtype=getattr(torch, value["dtype"]))
                       for key, value in content.items()}, str(out / name))


def load_parts(folder: Path, weights: bool) -> tuple[nn.Module, Any, Any]:
    """LeRobot's own loading of a pretrained_model folder: (policy, preprocessor, postprocessor).

    Without `weights` the policy is built from its config alone (a gymnast checkpoint fills it).
    The processors run on the host; `LeRobotPolicy.inputs` moves their output to the policy.
    """
    require_lerobot()
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    config = PreTrainedConfig.from_pretrained(str(folder))
    config.device = "cpu"  # gymnast moves the policy where the run says
    cls = get_policy_class(config.type)
    policy = cls.from_pretrained(str(folder), config=config) if weights else cls(config)
    preprocessor, postprocessor = make_pre_post_processors(
        config, pretrained_path=str(folder), preprocessor_overrides={"device_processor": {"device": "cpu"}},
        postprocessor_overrides={"device_processor": {"device": "cpu"}})
    return policy, preprocessor, postprocessor


def parts_from_files(files: dict) -> tuple[nn.Module, Any, Any]:
    """`load_parts` of a folder saved in a spec, without weights."""
    with tempfile.TemporaryDirectory() as folder:
        write_folder(files, Path(folder))
        return load_parts(Path(folder), weights=False)
