"""The RL loop end to end: the CLI on every env, resume after SIGKILL, and the update's invariances."""

import copy
import dataclasses
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from gymnast.cli import main
from gymnast.policy.load import load_policy
from gymnast.envs.starts import start_options
from gymnast.rl.rollout import collect_rollouts, dataset_starts
from gymnast.rl.config import RL_PRESETS
from gymnast.rl.train import update_policy
from gymnast.utils.metrics import read_metrics
from gymnast.utils.video import decode_video

from rl_helpers import JUDGE, POLICY, WORLD_MODEL

SUMMARY_KEYS = {"env", "reward", "steps", "start_success", "end_success", "curve"}


def _rl_args(env, reward, out, data, *extra):
    args = ["rl", "--policy", str(POLICY), "--env", env, "--reward", reward, "--out", str(out), "--data", str(data),
            "--preset", "debug", *extra]
    return args + (["--wm", str(WORLD_MODEL)] if env == "imagined" or reward == "verified" else [])


@pytest.mark.parametrize("env, reward", [("imagined", f"judge:{JUDGE}"), ("imagined", "verified"),
                                         ("sim", "sim-dense"), ("real", "sim")])
def test_rl_debug_preset_runs_on_every_env(env, reward, rl_dataset, tmp_path, capsys):
    out = tmp_path / "run"
    main(_rl_args(env, reward, out, rl_dataset))
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= summary.keys()
    assert summary["env"] == env and summary["reward"] == reward and summary["steps"] == 2
    assert [point["step"] for point in summary["curve"]] == [0, 2]
    metrics = read_metrics(out)
    assert [m["step"] for m in metrics if "time/step_s" in m] == [1, 2]
    assert all(m["rollout/kept_groups"] >= 0 for m in metrics if "rollout/kept_groups" in m)
    assert (out / "checkpoints" / "000002" / "model.safetensors").exists()
    assert list((out / "videos").glob("*.mp4")) and list((out / "tensorboard").iterdir())
    if reward.startswith("sim"):  # the simulator's reward reads no frame inside a chunk, nor does its video
        _assert_each_chunk_shows_one_frame(sorted((out / "videos").glob("*.mp4"))[-1])
    assert summary["eval_real_interactions"] > 0  # every run is evaluated in the real world, counted apart
    if env == "real":
        assert summary["real_interactions"] > 0 and summary["watch_real_interactions"] == 0
    else:
        assert summary["real_interactions"] == 0
        watched = [m for m in metrics if "eval/watch_real_success" in m]
        assert [m["step"] for m in watched] == [1, 2]
        assert all(("eval/watch_agreement" in m) == (reward != "verified") for m in watched)


def _assert_each_chunk_shows_one_frame(video):
    frames = decode_video(video).astype(np.float32)  # (1 + S * K, H, G * W, 3): the start frame, then each action's
    chunk = load_policy(POLICY).chunk_size
    change = np.abs(np.diff(frames[1:], axis=0)).mean(axis=(1, 2, 3))  # between consecutive actions' frames
    boundary = np.arange(1, len(change) + 1) % chunk == 0  # from a chunk's last action to the next chunk's first
    assert change[~boundary].max() < 0.5, "frames inside a chunk were rendered"
    assert change[boundary].max() > 2 * change[~boundary].max() + 0.5, "the video never moves"


def test_rl_with_the_vlm_judge_talks_to_a_served_judge(rl_dataset, tmp_path):
    from gymnast.reward.chat.serve import judge_server

    with judge_server(JUDGE) as server:
        main(_rl_args("imagined", f"vlm:gymnast-judge@{server.url}", tmp_path / "run", rl_dataset))
    metrics = read_metrics(tmp_path / "run")
    assert [m["step"] for m in metrics if "reward/mean" in m] == [1, 2]
    assert all(m["reward/nan_fraction"] == 0 for m in metrics if "reward/nan_fraction" in m)
    assert [m["reward/vlm_requests"] for m in metrics if "reward/vlm_requests" in m][-1] > 0


def test_rl_in_a_simulator_can_start_from_fresh_scenes_without_a_dataset(tmp_path):
    out = tmp_path / "run"
    main(["rl", "--policy", str(POLICY), "--env", "sim", "--reward", "sim-dense", "--out", str(out), "--preset", "debug",
          "--fresh-scenes"])
    saved = json.loads((out / "config.json").read_text())
    assert saved["rl"]["fresh_scenes"] and saved["data"] is None
    assert [m["step"] for m in read_metrics(out) if "reward/mean" in m] == [1, 2]


def test_rl_in_imagination_can_start_from_fresh_scenes_whose_first_frames_are_counted(tmp_path):
    out = tmp_path / "run"
    main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--out", str(out), "--preset", "debug", "--fresh-scenes", "--watch-every", "0"])
    summary = json.loads((out / "summary.json").read_text())
    debug = RL_PRESETS["debug"]  # one round a step: each step renders the first frames of its start states
    assert summary["reset_frames"] == debug.steps * debug.starts_per_step * debug.max_rounds
    assert summary["real_interactions"] == 0  # a reset takes no action
    assert [m["rollout/reset_frames"] for m in read_metrics(out) if "rollout/reset_frames" in m] == [2, 4]


def _recorded_starts(monkeypatch):
    from gymnast.rl import rollout

    seen = []

    def recording(starts):
        seen.extend(starts)
        return start_options(starts)

    monkeypatch.setattr(rollout, "start_options", recording)
    return seen


def test_test_time_practice_trains_and_evaluates_on_the_named_scene_only(tmp_path, monkeypatch):
    seen = _recorded_starts(monkeypatch)
    out = tmp_path / "run"
    main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--out", str(out), "--preset", "debug", "--scenes", "push-v3:1000007", "--watch-every", "0"])
    assert seen and {(start.task, start.seed) for start in seen} == {("push-v3", 1000007)}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["eval_episodes"] == 1 and summary["reset_frames"] == 1
    assert json.loads((out / "config.json").read_text())["rl"]["scenes"] == "push-v3:1000007"


def test_scenes_that_are_not_task_and_seed_are_named(tmp_path, capsys):
    for scenes, message in (("reach-v3", "is not task:seed"), ("rech-v3:5", "unknown task 'rech-v3'")):
        with pytest.raises(SystemExit):
            main(["rl", "--policy", str(POLICY), "--env", "sim", "--reward", "sim-dense", "--out", str(tmp_path / "run"),
                  "--preset", "debug", "--scenes", scenes])
        assert message in capsys.readouterr().err


def test_rl_practises_and_evaluates_on_a_users_own_instruction(rl_dataset, tmp_path, monkeypatch, capsys):
    starts = _recorded_starts(monkeypatch)
    sentence = "touch the red dot with the gripper"
    main(_rl_args("sim", "sim-dense", tmp_path / "run", rl_dataset, "--instruction", sentence))
    assert starts and {start.instruction for start in starts} == {sentence}  # every training and evaluation rollout
    assert json.loads((tmp_path / "run" / "config.json").read_text())["rl"]["instruction"] == sentence
    with pytest.raises(SystemExit):
        main(_rl_args("sim", "sim-dense", tmp_path / "two", rl_dataset, "--tasks", "reach-v3,push-v3",
                      "--instruction", sentence))
    assert "--instruction is one sentence for one task" in capsys.readouterr().err


def test_without_tasks_a_preset_trains_on_the_tasks_the_data_has(tmp_path):
    from gymnast.config import EnvConfig
    from gymnast.data.collect import CollectConfig, collect
    from gymnast.rl.rollout import tasks_with_starts

    data = tmp_path / "drawers"  # no reach-v3, the debug preset's task
    collect(CollectConfig(tasks="drawer-close-v3", episodes_per_task=1, noise=(0.0,), failure_fraction=0.0, workers=1,
                          env=EnvConfig(image_size=96, horizon=100)), data, progress=False)
    main(["rl", "--policy", str(POLICY), "--env", "sim", "--reward", "sim-dense", "--out", str(tmp_path / "run"),
          "--data", str(data), "--preset", "debug"])
    assert json.loads((tmp_path / "run" / "config.json").read_text())["rl"]["tasks"] == "drawer-close-v3"
    # The preset's own tasks where the data has them; otherwise as many of the data's.
    assert tasks_with_starts(data, ("drawer-close-v3", "reach-v3")) == ("drawer-close-v3",)
    assert tasks_with_starts(data, ("reach-v3", "push-v3")) == ("drawer-close-v3",)


def test_rl_rejects_a_reward_the_env_cannot_give(rl_dataset, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(_rl_args("imagined", "sim", tmp_path / "run", rl_dataset))
    error = capsys.readouterr().err
    assert "simulator" in error
    assert "--reward sim cannot score rollouts of --env imagined" in error


def test_what_the_reward_sees_must_fit_the_reward_and_differ_from_the_rollouts_own(rl_dataset, tmp_path, capsys):
    # The simulator's verdict cannot be read off a world model's re-imagining of real actions...
    with pytest.raises(SystemExit):
        main(_rl_args("real", "sim", tmp_path / "a", rl_dataset, "--reward-sees", "imagined", "--wm", str(WORLD_MODEL)))
    assert "--reward sim cannot score rollouts of --env imagined" in capsys.readouterr().err
    # ... and replaying imagined rollouts in imagination again says nothing new.
    with pytest.raises(SystemExit):
        main(_rl_args("imagined", f"judge:{JUDGE}", tmp_path / "b", rl_dataset, "--reward-sees", "imagined"))
    assert "leave --reward-sees out" in capsys.readouterr().err
    assert not (tmp_path / "a" / "checkpoints").exists() and not (tmp_path / "b" / "checkpoints").exists()


def _comparable(metrics):
    return [{k: v for k, v in m.items() if not k.startswith("time/")} for m in metrics]


def test_rl_killed_and_resumed_matches_an_uninterrupted_run(rl_dataset, tmp_path):
    args = ["--steps", "5"]
    whole, broken = tmp_path / "whole", tmp_path / "broken"
    main(_rl_args("real", "sim-dense", whole, rl_dataset, *args))
    command = [sys.executable, "-m", "gymnast.cli", *_rl_args("real", "sim-dense", broken, rl_dataset, *args)]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    last = broken / "checkpoints" / "last"
    deadline = time.monotonic() + 300
    while not (last.exists() and last.read_text() >= "000002") and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    process.send_signal(signal.SIGKILL)  # nothing if poll() already reaped it: the assert below says so
    assert process.wait() == -signal.SIGKILL, "the run finished before it could be killed"
    killed_at = int(last.read_text())
    assert killed_at < 5
    main(["rl", "--out", str(broken), "--resume"])
    resumed_metrics, expected_metrics = _comparable(read_metrics(broken)), _comparable(read_metrics(whole))
    assert [m.keys() for m in resumed_metrics] == [m.keys() for m in expected_metrics]
    for resumed_line, expected_line in zip(resumed_metrics, expected_metrics):
        assert resumed_line == pytest.approx(expected_line, rel=1e-5, abs=1e-7)
    resumed = json.loads((broken / "summary.json").read_text())
    expected = json.loads((whole / "summary.json").read_text())
    assert resumed["curve"] == expected["curve"] and resumed["end_success"] == expected["end_success"]


def test_a_crash_in_the_last_evaluation_keeps_the_steps_and_resume_runs_it_again(rl_dataset, tmp_path, monkeypatch):
    import gymnast.rl.train as train

    out, evaluate, calls = tmp_path / "run", train.evaluate_in_env, []

    def lost_after_the_first(*args, **kwargs):  # step 0's evaluation runs; the one after the steps fails
        calls.append(args)
        if len(calls) > 1:
            raise RuntimeError("simulator worker lost")
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(train, "evaluate_in_env", lost_after_the_first)
    with pytest.raises((RuntimeError, SystemExit)):
        main(_rl_args("imagined", f"judge:{JUDGE}", out, rl_dataset, "--no-real-eval"))
    assert int((out / "checkpoints" / "last").read_text()) == 2  # both trained steps were kept
    assert not (out / "summary.json").exists()
    monkeypatch.setattr(train, "evaluate_in_env", evaluate)
    main(["rl", "--out", str(out), "--resume"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 2 and [entry["step"] for entry in summary["curve"]] == [0, 2]
    evaluations = [m["step"] for m in read_metrics(out) if "eval/own_episodes" in m]
    assert evaluations == [0, 2]


def test_update_does_not_depend_on_the_micro_batch_size(rl_dataset):
    from gymnast.envs.sim_vector import SimVectorEnv
    from gymnast.config import EnvConfig

    policy = load_policy(POLICY)
    starts = [s for s in dataset_starts(rl_dataset) for _ in range(2)]
    with SimVectorEnv(len(starts), policy.chunk_size, EnvConfig(image_size=96, horizon=15)) as env:
        batch = collect_rollouts(env, policy, starts, 1.6, torch.Generator().manual_seed(0))
    advantages = torch.tensor([1.0, -1.0, 0.5, -0.5])
    results = []
    for micro_batch in (1, 5, 1000):
        model = copy.deepcopy(policy)
        optimizer = torch.optim.SGD(model.parameters(), lr=0.1)
        config = dataclasses.replace(RL_PRESETS["debug"], micro_batch=micro_batch, max_grad_norm=1e9)
        metrics = update_policy(model, optimizer, batch, advantages, config)
        results.append((torch.cat([p.detach().flatten() for p in model.parameters()]), metrics))
    for params, metrics in results[1:]:
        assert torch.allclose(params, results[0][0], atol=1e-6)
        assert metrics == pytest.approx(results[0][1], rel=1e-4, abs=1e-6)


def test_a_positive_advantage_makes_the_sampled_chunk_more_likely(rl_dataset):
    from gymnast.envs.sim_vector import SimVectorEnv
    from gymnast.config import EnvConfig

    policy = load_policy(POLICY)
    starts = dataset_starts(rl_dataset)[:1] * 2
    with SimVectorEnv(2, policy.chunk_size, EnvConfig(image_size=96, horizon=5)) as env:
        batch = collect_rollouts(env, policy, starts, 1.6, torch.Generator().manual_seed(0))
    config = RL_PRESETS["debug"]
    before = policy.log_prob(batch.observations[:, 0], batch.instructions, batch.tokens[:, 0], 1.6).sum(-1)
    update_policy(policy, torch.optim.SGD(policy.parameters(), lr=0.05), batch, torch.tensor([1.0, -1.0]), config)
    after = policy.log_prob(batch.observations[:, 0], batch.instructions, batch.tokens[:, 0], 1.6).sum(-1)
    assert after[0] > before[0] and after[1] < before[1]


def test_per_call_credit_trains_on_the_dense_reward_and_refuses_a_whole_video_reward(rl_dataset, tmp_path, capsys):
    out = tmp_path / "run"
    main(_rl_args("real", "sim-dense", out, rl_dataset, "--credit", "reward-to-go"))
    assert json.loads((out / "config.json").read_text())["rl"]["credit"] == "reward-to-go"
    assert [m["step"] for m in read_metrics(out) if "train/policy_loss" in m] == [1, 2]
    with pytest.raises(SystemExit):
        main(_rl_args("real", "sim", tmp_path / "binary", rl_dataset, "--credit", "reward-to-go"))
    assert "scores whole videos only" in capsys.readouterr().err


def test_per_call_advantages_move_each_call_by_its_own_sign(rl_dataset):
    from gymnast.envs.sim_vector import SimVectorEnv
    from gymnast.config import EnvConfig

    policy = load_policy(POLICY)
    starts = dataset_starts(rl_dataset)[:1]
    with SimVectorEnv(1, policy.chunk_size, EnvConfig(image_size=96, horizon=2 * policy.chunk_size)) as env:
        batch = collect_rollouts(env, policy, starts, 1.6, torch.Generator().manual_seed(0))
    def logp():
        return torch.stack([policy.log_prob(batch.observations[:, s], batch.instructions, batch.tokens[:, s], 1.6).sum()
                            for s in range(2)])
    before = logp()
    update_policy(policy, torch.optim.SGD(policy.parameters(), lr=0.05), batch, torch.tensor([[1.0, -1.0]]),
                  RL_PRESETS["debug"])
    after = logp()
    assert after[0] > before[0] and after[1] < before[1]


def test_frozen_parts_of_the_policy_stay_as_they_were_while_the_rest_learns(tmp_path):
    out = tmp_path / "run"
    main(["rl", "--policy", str(POLICY), "--env", "sim", "--reward", "sim-dense", "--out", str(out), "--preset", "debug",
          "--fresh-scenes", "--freeze", "vision", "--lr", "1e-3"])
    before, after = load_policy(POLICY).state_dict(), load_policy(out).state_dict()
    changed = {name for name in before if not torch.equal(before[name], after[name])}
    assert changed and not any(name.startswith("vision.") for name in changed)
    assert json.loads((out / "config.json").read_text())["rl"]["freeze"] == ["vision"]
    # The frozen encoder's tokens of the rollouts' observations served the update again.
    reused = [line["train/vision_reused"] for line in read_metrics(out) if "train/vision_reused" in line]
    assert reused and all(share >= 0.5 for share in reused)


def test_a_part_to_freeze_that_the_policy_lacks_is_named_with_the_parts_it_has():
    from gymnast.rl.train import learning_parameters

    policy = load_policy(POLICY)
    learning = learning_parameters(policy, ("vision",))
    assert len(learning) < len(list(policy.parameters())) and all(parameter.requires_grad for parameter in learning)
    assert not any(parameter.requires_grad for parameter in policy.vision.parameters())
    with pytest.raises(ValueError, match="no parameter named 'backbone'.*its parts are .*decoder.*vision"):
        learning_parameters(policy, ("backbone",))
    parts = tuple({name.split(".")[0] for name, _ in policy.named_parameters()})
    with pytest.raises(ValueError, match="nothing to learn"):
        learning_parameters(policy, parts)
