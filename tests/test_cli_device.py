"""`--device` on every command that trains, imagines or judges, and the presets sized for a GPU."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch
from robot_datasets import write_robot_dataset

from gymnast.cli import main
from gymnast.experiment.config import EXPERIMENT_PRESETS
from gymnast.reward.judges.train import JUDGE_PRESETS
from gymnast.rl.config import RL_PRESETS
from gymnast.world_model.base import load_world_model
from gymnast.world_model.train import WM_PRESETS

no_gpu = pytest.mark.skipif(torch.cuda.is_available(), reason="checks what a machine without a GPU says")
needs_gpu = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
TRAINERS = [["train-wm", "--preset", "debug"], ["sft", "--preset", "debug"], ["train-judge", "--preset", "debug"]]


@pytest.mark.slow
def test_every_model_trains_and_is_measured_on_the_device_asked_for(tmp_path, capsys):
    # 6 episodes: the scene hash holds out episodes 4 and 5, so eval-wm and eval-judge have some to measure.
    data = write_robot_dataset(tmp_path / "data", episodes=6, steps=10, height=32, width=32)
    for command in TRAINERS:
        main([*command, "--data", str(data), "--out", str(tmp_path / command[0]), "--device", "cpu"])
        saved = json.loads((tmp_path / command[0] / "config.json").read_text())
        assert saved["sft" if command[0] == "sft" else "train"]["device"] == "cpu"
    main(["eval-wm", "--wm", str(tmp_path / "train-wm"), "--data", str(data), "--out", str(tmp_path / "wm.json"),
          "--videos", "0", "--control-scenes", "0", "--device", "cpu"])
    main(["eval-judge", "--reward", f"judge:{tmp_path / 'train-judge'}", "--data", str(data),
          "--out", str(tmp_path / "judge.json"), "--device", "cpu"])
    assert json.loads((tmp_path / "wm.json").read_text())["config"]["device"] == "cpu"
    assert "real_tpr" in json.loads((tmp_path / "judge.json").read_text())
    capsys.readouterr()


@no_gpu
@pytest.mark.parametrize("command", [*TRAINERS, ["experiment", "--preset", "debug"]], ids=lambda c: c[0])
def test_cuda_without_a_gpu_is_one_line_before_anything_is_written(command, tiny_dataset, tmp_path, capsys):
    data = [] if command[0] == "experiment" else ["--data", str(tiny_dataset)]
    with pytest.raises(SystemExit) as exit_info:
        main([*command, *data, "--out", str(tmp_path / "run"), "--device", "cuda"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "--device cuda: torch" in err and "sees no CUDA GPU" in err
    assert not (tmp_path / "run" / "checkpoints").exists()


def test_a_run_started_on_one_device_resumes_on_another(tiny_dataset, tmp_path, capsys):
    run = tmp_path / "wm"
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(run), "--preset", "debug", "--steps", "2", "--device", "cpu"])
    config = json.loads((run / "config.json").read_text())
    config["train"] |= {"device": "cuda:7", "steps": 4}  # as if started on a GPU machine, for 4 steps
    (run / "config.json").write_text(json.dumps(config))
    main(["train-wm", "--out", str(run), "--resume", "--device", "cpu"])
    assert json.loads((run / "config.json").read_text())["train"]["device"] == "cpu"
    assert (run / "checkpoints" / "000004").is_dir()
    capsys.readouterr()


def test_the_gpu_presets_are_larger_than_the_full_ones():
    assert WM_PRESETS["gpu"].model.latent_channels > WM_PRESETS["full"].model.latent_channels
    assert WM_PRESETS["gpu"].batch_size > WM_PRESETS["full"].batch_size
    assert JUDGE_PRESETS["gpu"].judge.width > JUDGE_PRESETS["full"].judge.width
    rl = RL_PRESETS["gpu"]
    assert (rl.steps, rl.starts_per_step * rl.group_size) == (400, 256)
    experiment = EXPERIMENT_PRESETS["gpu"].resolved()
    views = experiment.cameras  # the experiment's, told to every stage
    assert experiment.world_model == dataclasses.replace(WM_PRESETS["gpu"], cameras=views)
    assert experiment.judge == dataclasses.replace(JUDGE_PRESETS["gpu"], cameras=views)
    assert (experiment.rl.steps, experiment.rl.starts_per_step * experiment.rl.group_size) == (400, 256)


@needs_gpu
@pytest.mark.slow
def test_a_model_trained_on_the_gpu_loads_on_the_cpu_and_imagines_alike(tiny_dataset, tmp_path, capsys):
    main(["train-wm", "--data", str(tiny_dataset), "--out", str(tmp_path / "wm"), "--preset", "debug", "--device", "cuda"])
    model = load_world_model(tmp_path / "wm")
    assert next(model.parameters()).device.type == "cpu"
    context = torch.randint(0, 256, (2, 2, model.image_size, model.image_size, 3), dtype=torch.uint8)
    actions = torch.rand(2, 3, model.action_dim) * 2 - 1
    on_cpu = model.step(model.init_state(context), actions)[1]
    gpu = model.to("cuda")
    on_gpu = gpu.step(gpu.init_state(context.cuda()), actions.cuda())[1].cpu()
    assert (on_cpu.int() - on_gpu.int()).abs().float().mean() < 2  # bf16 kernels differ by a rounding or two
    capsys.readouterr()
