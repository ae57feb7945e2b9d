"""Presets, overrides and --resume (`gymnast.cli.settings`), and settings read back from a run's JSON."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import tyro

from gymnast.cli.flags import RLFlags
from gymnast.cli.settings import resolve
from gymnast.experiment.config import EXPERIMENT_PRESETS, ExperimentConfig
from gymnast.policy.sft import SFT_PRESETS
from gymnast.rl.config import RL_PRESETS, RLConfig
from gymnast.utils.settings import from_json
from gymnast.world_model.train import WM_PRESETS, WorldModelTrainConfig

DEBUG = SFT_PRESETS["debug"]


def _no_run() -> tuple:
    raise AssertionError("a new run reads no saved settings")


def _sft(resume: bool, saved=_no_run, data: Path | None = None, **overrides):
    return resolve("sft", Path("runs/x"), resume, DEBUG, overrides=overrides, inputs={"data": data}, saved=saved,
                   required=("data",))


def test_a_new_run_is_the_preset_with_the_given_fields_replaced():
    config, inputs = _sft(False, data=Path("data/a"), steps=7, seed=None, **{"vla.vision": "efficientnet"})
    assert config == dataclasses.replace(DEBUG, steps=7, vla=dataclasses.replace(DEBUG.vla, vision="efficientnet"))
    assert inputs == {"data": Path("data/a")}


def test_a_new_run_without_a_required_input_names_its_flag():
    with pytest.raises(ValueError, match=r"gymnast sft needs --data \(or --resume"):
        _sft(False, steps=7)
    with pytest.raises(ValueError, match="gymnast rl needs --policy and --reward"):
        resolve("rl", Path("runs/x"), False, RL_PRESETS["debug"], overrides={}, saved=_no_run,
                inputs={"policy": None, "env": "sim", "reward": None}, required=("policy", "env", "reward"))


def test_resume_takes_the_saved_settings_and_inputs_and_refuses_a_flag_that_disagrees():
    saved_config = dataclasses.replace(DEBUG, steps=9)

    def saved():
        return saved_config, {"data": Path("data/a")}

    assert _sft(True, saved) == (saved_config, {"data": Path("data/a")})  # --preset is not looked at
    # Flags that agree with the run pass; paths agree by where they point.
    assert _sft(True, saved, data=Path("data/a").resolve(), steps=9, **{"vla.vision": "cnn"})[0] == saved_config
    with pytest.raises(ValueError, match=r"--steps 5 disagrees with the run in runs/x, which has steps=9"):
        _sft(True, saved, steps=5)
    with pytest.raises(ValueError, match=r"--vision efficientnet disagrees .* vla.vision=cnn"):
        _sft(True, saved, **{"vla.vision": "efficientnet"})
    with pytest.raises(ValueError, match=r"--data data/b disagrees .* data=data/a"):
        _sft(True, saved, data=Path("data/b"))


def test_resume_may_continue_on_another_device_but_not_with_other_settings():
    saved_config = dataclasses.replace(DEBUG, steps=9, device="cuda")

    def saved():
        return saved_config, {"data": Path("data/a")}

    config, _ = _sft(True, saved, device="cpu")  # started on a GPU, finished on a CPU
    assert config == dataclasses.replace(saved_config, device="cpu")
    assert _sft(True, saved)[0].device == "cuda"  # without the flag, where the run said


def test_rl_flags_are_the_fields_of_rlconfig_with_their_docstrings_and_preset_values(capsys):
    assert [f.name for f in dataclasses.fields(RLFlags)] == [f.name for f in dataclasses.fields(RLConfig)]
    flags = tyro.cli(RLFlags, args=["--steps", "3", "--fresh-scenes", "--no-real-eval", "--tasks", "reach-v3"])
    given = {name: value for name, value in dataclasses.asdict(flags).items() if value is not None}
    assert given == {"steps": 3, "fresh_scenes": True, "real_eval": False, "tasks": "reach-v3"}
    with pytest.raises(SystemExit):
        tyro.cli(RLFlags, args=["--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "RL steps (one policy update each). (default: the preset's: debug 2, demo 30, full 100, gpu 400)" in help_text
    assert "--clip-low FLOAT PPO ratio clip below 1. (default: 0.2)" in help_text


def test_settings_read_back_from_json_are_the_ones_saved():
    for name, config in EXPERIMENT_PRESETS.items():
        config = config.resolved()
        assert from_json(ExperimentConfig, json.loads(json.dumps(dataclasses.asdict(config)))) == config, name
    world_model = dataclasses.replace(WM_PRESETS["debug"], init=Path("runs/wm"), extra_data=(Path("data/b"),))
    saved = {**dataclasses.asdict(world_model), "init": "runs/wm", "extra_data": ["data/b"]}
    assert from_json(WorldModelTrainConfig, json.loads(json.dumps(saved))) == world_model
    with pytest.raises(ValueError, match="WorldModelTrainConfig has no field 'colour'"):
        from_json(WorldModelTrainConfig, {"colour": "red"})
