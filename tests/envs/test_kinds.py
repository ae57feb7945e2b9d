"""Every env kind declares what it is, and the factory builds each kind from its declarations."""

import dataclasses

import pytest

from gymnast.envs.kinds import ENV_KINDS, IMAGINED, REAL, SIM, EnvKind, env_kind


def test_every_env_kind_declares_real_interactions_success_and_imagination():
    for name, kind in ENV_KINDS.items():
        assert isinstance(kind, EnvKind) and kind.name == name == str(kind)
        declared = {field.name: getattr(kind, field.name) for field in dataclasses.fields(kind) if field.name != "name"}
        assert declared.keys() == {"real_interactions", "reports_success", "imagined"}
        assert all(isinstance(value, bool) for value in declared.values()), name
    # Only the real world's actions are real interactions; only simulators report success.
    assert [k.name for k in ENV_KINDS.values() if k.real_interactions] == ["real"]
    assert [k.name for k in ENV_KINDS.values() if k.reports_success] == ["sim", "real"]
    assert [k.name for k in ENV_KINDS.values() if k.imagined] == ["imagined"]
    assert (IMAGINED, SIM, REAL) == tuple(ENV_KINDS.values())


def test_an_unknown_env_name_lists_the_kinds():
    assert env_kind("sim") is SIM
    with pytest.raises(ValueError, match="unknown env 'mujoco'; the envs are imagined, sim, real"):
        env_kind("mujoco")
