"""Every env kind declares what it is, and the factory builds each kind from its declarations."""

import dataclasses

import pytest

from gymnast.envs.kinds import ANCHORED, ENV_KINDS, IMAGINED, REAL, SIM, EnvKind, env_kind


def test_every_env_kind_declares_real_interactions_success_and_imagination():
    for name, kind in ENV_KINDS.items():
        assert isinstance(kind, EnvKind) and kind.name == name == str(kind)
        declared = {field.name: getattr(kind, field.name) for field in dataclasses.fields(kind) if field.name != "name"}
        assert declared.keys() == {"real_interactions", "reports_success", "imagined"}
        assert all(isinstance(value, bool) for value in declared.values()), name
    # Only actions taken in the real world are real interactions; only simulators report success,
    # the anchored env the real world's; the anchored env's frames are imagined as well.
    assert [k.name for k in ENV_KINDS.values() if k.real_interactions] == ["real", "anchored"]
    assert [k.name for k in ENV_KINDS.values() if k.reports_success] == ["sim", "real", "anchored"]
    assert [k.name for k in ENV_KINDS.values() if k.imagined] == ["imagined", "anchored"]
    # What the policy sees is the real world only in the real world: the others are evaluated there.
    assert [k.name for k in ENV_KINDS.values() if k.real_sight] == ["real"]
    assert (IMAGINED, SIM, REAL, ANCHORED) == tuple(ENV_KINDS.values())


def test_an_unknown_env_name_lists_the_kinds():
    assert env_kind("sim") is SIM
    with pytest.raises(ValueError, match="unknown env 'mujoco'; the envs are imagined, sim, real, anchored"):
        env_kind("mujoco")
