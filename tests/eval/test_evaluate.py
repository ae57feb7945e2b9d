"""`gymnast eval`: the expert reference, a do-nothing policy, seeds, the report, videos, workers."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np
import pytest
import torch

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.envs.tasks import EVAL_SEEDS, eval_seed
from gymnast.eval import actors
from gymnast.eval.evaluate import EvalConfig, evaluate, plan_episodes
from gymnast.eval.stats import wilson_interval
from gymnast.policy.base import ActionSample
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.utils.checkpoint import save_checkpoint
from gymnast.utils.video import decode_video

SMALL = EnvConfig(image_size=32)  # the expert needs the full 150-step horizon
SHORT = EnvConfig(image_size=32, horizon=30)
REPORT_KEYS = {"success", "ci_low", "ci_high", "episodes", "per_task", "records", "policy", "config",
               "wall_s", "real_interactions", "videos"}


class ZeroPolicy:
    """A `Policy` that never moves: every action of every chunk is zero."""

    action_dim = 4

    def __init__(self, chunk_size: int = 4) -> None:
        self.chunk_size = chunk_size
        self.calls: list[tuple[tuple[int, ...], torch.dtype, list[str]]] = []

    def act(self, obs: torch.Tensor, instructions: Sequence[str]) -> torch.Tensor:
        self.calls.append((tuple(obs.shape), obs.dtype, list(instructions)))
        return torch.zeros(len(obs), self.chunk_size, self.action_dim)

    def sample(self, obs, instructions, temperature=1.0, generator=None) -> ActionSample:
        tokens = torch.zeros(len(obs), self.chunk_size * self.action_dim, dtype=torch.int64)
        return ActionSample(self.act(obs, instructions), tokens, torch.zeros(tokens.shape))  # a point mass

    def log_prob(self, obs, instructions, tokens, temperature=1.0) -> torch.Tensor:
        return torch.zeros(tokens.shape)


@pytest.fixture(scope="module")
def expert_report(tmp_path_factory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("expert") / "report.json"
    config = EvalConfig(tasks="reach-v3,drawer-open-v3", episodes=3, workers=1, videos_per_task=1, env=SMALL)
    return evaluate("expert", config, out, progress=False), out


def test_expert_solves_reach_and_drawer_open_on_every_evaluation_seed(expert_report):
    report, _ = expert_report
    assert report["success"] == 1.0 and report["episodes"] == 6
    for task in ("reach-v3", "drawer-open-v3"):
        assert report["per_task"][task]["success"] == 1.0
        assert report["per_task"][task]["ci_high"] == 1.0
    assert all(record["steps"] < SMALL.horizon for record in report["records"])  # terminated on success


def test_episodes_run_from_evaluation_seeds_only(expert_report):
    report, _ = expert_report
    assert [r["seed"] for r in report["records"] if r["task"] == "reach-v3"] == [eval_seed(i) for i in range(3)]
    assert all(r["seed"] in EVAL_SEEDS for r in report["records"])
    later = EvalConfig(tasks="reach-v3", episodes=2, first_eval_index=7)
    assert [job.seed for job in plan_episodes(later, "expert", Path("videos"))] == [EVAL_SEEDS[7], EVAL_SEEDS[8]]
    with pytest.raises(ValueError, match="evaluation seed index"):
        EvalConfig(episodes=2, first_eval_index=len(EVAL_SEEDS) - 1)


def test_report_file_has_the_summary_records_and_resolved_config(expert_report):
    report, out = expert_report
    written = json.loads(out.read_text())
    assert written == report
    assert REPORT_KEYS <= set(written)
    assert set(written["per_task"]) == {"reach-v3", "drawer-open-v3"}
    assert all({"success", "ci_low", "ci_high", "episodes"} <= set(s) for s in written["per_task"].values())
    assert [set(r) for r in written["records"]] == [{"task", "seed", "instruction", "success", "steps"}] * 6
    assert written["real_interactions"] == sum(r["steps"] for r in written["records"]) > 0
    assert written["policy"] == "expert"
    assert written["config"]["tasks"] == "reach-v3,drawer-open-v3"
    assert written["config"]["seeds"] == [eval_seed(i) for i in range(3)]
    assert written["config"]["env"]["image_size"] == 32 and written["wall_s"] > 0


def test_first_episode_of_each_task_is_saved_as_a_decodable_video(expert_report):
    report, out = expert_report
    folder = f"{out.stem}_videos"  # one video folder per report, beside it
    assert report["videos"] == [f"{folder}/reach-v3_{eval_seed(0)}.mp4", f"{folder}/drawer-open-v3_{eval_seed(0)}.mp4"]
    for path, task in zip(report["videos"], ("reach-v3", "drawer-open-v3")):
        frames = decode_video(out.parent / path)
        steps = next(r["steps"] for r in report["records"] if r["task"] == task and r["seed"] == eval_seed(0))
        assert frames.shape == (steps + 1, 32, 32, 3)  # the first frame, then one per step
    assert len(list((out.parent / folder).iterdir())) == 2


def test_a_policy_that_never_moves_never_succeeds_and_acts_once_per_chunk(tmp_path: Path):
    policy = ZeroPolicy(chunk_size=4)
    config = EvalConfig(tasks="reach-v3", episodes=3, workers=1, videos_per_task=0, env=SHORT)
    report = evaluate(policy, config, tmp_path / "zero.json", progress=False)
    assert report["success"] == 0.0 and report["ci_low"] == 0.0
    assert report["ci_high"] == pytest.approx(wilson_interval(0, 3)[1])
    assert [r["steps"] for r in report["records"]] == [SHORT.horizon] * 3
    assert len(policy.calls) == 3 * math.ceil(SHORT.horizon / policy.chunk_size)
    shape, dtype, instructions = policy.calls[0]
    assert shape == (1, 32, 32, 3) and dtype == torch.uint8 and instructions == [report["records"][0]["instruction"]]
    assert "ZeroPolicy (in-process)" in report["policy"]


def test_a_users_own_instruction_reaches_the_policy_in_every_episode(tmp_path: Path, capsys):
    policy = ZeroPolicy(chunk_size=10)
    sentence = "nudge the little red dot with the gripper"
    config = EvalConfig(tasks="reach-v3", episodes=2, workers=1, videos_per_task=0, env=SHORT, instruction=sentence)
    report = evaluate(policy, config, tmp_path / "own.json", progress=False)
    assert [r["instruction"] for r in report["records"]] == [sentence] * 2
    assert {text for _, _, texts in policy.calls for text in texts} == {sentence}
    main(["eval", "--policy", "expert", "--tasks", "reach-v3", "--episodes", "1", "--workers", "1",
          "--videos-per-task", "0", "--instruction", sentence, "--out", str(tmp_path / "cli.json")])
    assert json.loads((tmp_path / "cli.json").read_text())["records"][0]["instruction"] == sentence
    capsys.readouterr()


def test_an_own_instruction_is_one_non_empty_sentence_for_one_task():
    with pytest.raises(ValueError, match="one sentence for one task.*names 2"):
        EvalConfig(tasks="reach-v3,push-v3", instruction="push it")
    with pytest.raises(ValueError, match="instruction is empty"):
        EvalConfig(tasks="reach-v3", instruction="  ")


def test_a_sentences_file_words_every_episode_of_every_task(tmp_path: Path, capsys):
    sentences = tmp_path / "ours.txt"
    sentences.write_text("# our wording\nreach-v3: touch the red dot\nreach-v3: go to the red dot\n\n"
                         "push-v3: slide the puck onto the green mark\n")
    policy = ZeroPolicy(chunk_size=10)
    config = EvalConfig(tasks="reach-v3,push-v3", episodes=4, workers=1, videos_per_task=0, env=SHORT,
                        sentences=sentences)
    records = evaluate(policy, config, tmp_path / "own.json", progress=False)["records"]
    reach = {r["instruction"] for r in records if r["task"] == "reach-v3"}
    assert reach <= {"touch the red dot", "go to the red dot"} and len(reach) == 2  # the seed picks, both get used
    assert {r["instruction"] for r in records if r["task"] == "push-v3"} == {"slide the puck onto the green mark"}
    again = evaluate(ZeroPolicy(chunk_size=10), config, tmp_path / "again.json", progress=False)["records"]
    assert [r["instruction"] for r in again] == [r["instruction"] for r in records]  # chosen by seed, not by chance
    main(["eval", "--policy", "expert", "--tasks", "push-v3", "--episodes", "1", "--workers", "1",
          "--videos-per-task", "0", "--sentences", str(sentences), "--out", str(tmp_path / "cli.json")])
    assert json.loads((tmp_path / "cli.json").read_text())["records"][0]["instruction"] == "slide the puck onto the green mark"
    capsys.readouterr()


@pytest.mark.parametrize("text, message", [
    ("reach-v3 touch the dot\n", "line 1: expected 'task: sentence'"),
    ("# fine\nreach-v3:   \n", "line 2: the sentence for 'reach-v3' is empty"),
    ("rech-v3: touch the dot\n", "line 1: Unknown Meta-World v3 task 'rech-v3'"),
    ("# nothing\n", "no 'task: sentence' lines"),
    ("push-v3: push it\n", "has no sentence for reach-v3"),
])
def test_a_bad_sentences_file_is_named_with_its_line(text, message, tmp_path: Path):
    sentences = tmp_path / "ours.txt"
    sentences.write_text(text)
    with pytest.raises(ValueError, match=message) as error:
        EvalConfig(tasks="reach-v3", sentences=sentences)
    assert str(sentences) in str(error.value)


def test_a_saved_vla_run_is_loaded_once_per_process_and_evaluated(tmp_path: Path):
    torch.manual_seed(0)
    model = EmbeddedVLA(VLAConfig(width=32, layers=1, heads=2, chunk_size=8, image_size=32))
    run = tmp_path / "run"
    save_checkpoint(run, 1, model, {"model": model.spec()})
    actors.load_run_policy.cache_clear()
    try:
        config = EvalConfig(tasks="reach-v3", episodes=2, workers=1, videos_per_task=0, env=SHORT)
        report = evaluate(str(run), config, tmp_path / "run.json", progress=False)
        assert actors.load_run_policy.cache_info().misses == 1  # loaded once, reused for episode 2
    finally:
        actors.load_run_policy.cache_clear()
    assert report["policy"] == str(run.resolve())
    assert report["episodes"] == 2 and report["real_interactions"] <= 2 * SHORT.horizon


def test_a_temperature_samples_the_policy_seeded_by_each_episode(tmp_path: Path):
    class SamplingSpy(ZeroPolicy):
        def __init__(self) -> None:
            super().__init__()
            self.draws: list[tuple[float, float]] = []

        def sample(self, obs, instructions, temperature=1.0, generator=None) -> ActionSample:
            self.draws.append((temperature, torch.rand(1, generator=generator).item()))
            return super().sample(obs, instructions, temperature, generator)

    def draws(temperature: float, name: str) -> list[tuple[float, float]]:
        policy = SamplingSpy()
        config = EvalConfig(tasks="reach-v3", episodes=2, workers=1, videos_per_task=0, env=SHORT,
                            temperature=temperature)
        report = evaluate(policy, config, tmp_path / f"{name}.json", progress=False)
        assert report["config"]["temperature"] == temperature
        return policy.draws

    assert draws(0.0, "greedy") == []  # greedy decoding never samples
    sampled = draws(1.3, "a")
    first_of_episode = [torch.rand(1, generator=torch.Generator().manual_seed(eval_seed(i))).item() for i in range(2)]
    assert {temperature for temperature, _ in sampled} == {1.3}
    assert [draw for _, draw in sampled if draw in first_of_episode] == first_of_episode  # each episode's own seed
    assert draws(1.3, "b") == sampled  # the same evaluation repeats exactly
    with pytest.raises(ValueError, match="temperature must be a finite number >= 0"):
        EvalConfig(temperature=-1.0)
    with pytest.raises(ValueError, match="scripted expert has no action tokens"):
        evaluate("expert", EvalConfig(tasks="reach-v3", episodes=1, temperature=1.0), tmp_path / "e.json")


def test_a_policy_with_the_wrong_chunk_shape_is_a_clear_error(tmp_path: Path):
    class WrongShape(ZeroPolicy):
        def act(self, obs, instructions):
            return torch.zeros(len(obs), self.chunk_size, 7)

    config = EvalConfig(tasks="reach-v3", episodes=1, workers=1, videos_per_task=0, env=SHORT)
    with pytest.raises(ValueError, match=r"returned shape \(1, 4, 7\)"):
        evaluate(WrongShape(), config, tmp_path / "r.json", progress=False)


def test_bad_policy_arguments_are_refused_before_any_episode(tmp_path: Path):
    with pytest.raises(FileNotFoundError, match="policy run directory not found"):
        evaluate(str(tmp_path / "missing"), EvalConfig(tasks="reach-v3", episodes=1), tmp_path / "r.json")
    with pytest.raises(ValueError, match="workers=1"):
        evaluate(ZeroPolicy(), EvalConfig(tasks="reach-v3", episodes=1, workers=2), tmp_path / "r.json")
    with pytest.raises(ValueError, match="even image size"):
        EvalConfig(env=EnvConfig(image_size=33))
    with pytest.raises(ValueError, match="perturbation level"):
        EvalConfig(perturb="huge")
    assert not (tmp_path / "r.json").exists()


def test_perturbation_reaches_the_environment(tmp_path: Path):
    first_frames = {}
    for perturb in ("none", "major:robot"):
        config = EvalConfig(tasks="reach-v3", episodes=1, workers=1, perturb=perturb, env=SMALL)
        report = evaluate("expert", config, tmp_path / perturb / "r.json", progress=False)
        first_frames[perturb] = decode_video(tmp_path / perturb / report["videos"][0])[0].astype(np.float32)
    assert np.abs(first_frames["none"] - first_frames["major:robot"]).mean() > 1.0  # the hand starts 5 cm away


@pytest.mark.slow  # starting spawned workers takes seconds
def test_two_workers_give_the_same_records_as_one(tmp_path: Path):
    def records(workers: int) -> list[dict]:
        config = EvalConfig(tasks="reach-v3", episodes=3, workers=workers, videos_per_task=0, env=SMALL)
        return evaluate("expert", config, tmp_path / f"w{workers}.json", progress=False)["records"]

    assert records(2) == records(1)


def test_cli_eval_prints_each_task_and_the_overall_rate(tmp_path: Path, capsys):
    out = tmp_path / "eval.json"
    main(["eval", "--policy", "expert", "--tasks", "reach-v3", "--episodes", "2", "--out", str(out),
          "--workers", "1", "--env.image-size", "32"])
    printed = capsys.readouterr().out
    assert "reach-v3" in printed and "overall" in printed and "100.0%" in printed
    assert json.loads(out.read_text())["episodes"] == 2
    assert (tmp_path / "eval_videos" / f"reach-v3_{eval_seed(0)}.mp4").exists()


def test_cli_eval_with_a_missing_run_directory_exits_with_a_message(tmp_path: Path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["eval", "--policy", str(tmp_path / "nope"), "--tasks", "reach-v3", "--out", str(tmp_path / "r.json")])
    assert exit_info.value.code == 2
    assert "policy run directory not found" in capsys.readouterr().err


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_eval_on_a_gpu_that_is_not_there_is_refused_before_any_episode(tmp_path: Path, capsys):
    with pytest.raises(SystemExit):
        main(["eval", "--policy", "expert", "--tasks", "reach-v3", "--episodes", "1", "--device", "cuda",
              "--out", str(tmp_path / "gpu.json")])
    assert "sees no CUDA GPU here" in capsys.readouterr().err
    assert not (tmp_path / "gpu.json").exists()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_eval_on_a_gpu_gives_the_cpus_episodes(tmp_path: Path):
    torch.manual_seed(0)
    model = EmbeddedVLA(VLAConfig(width=32, layers=1, heads=2, chunk_size=8, image_size=32))
    run = tmp_path / "run"
    save_checkpoint(run, 1, model, {"model": model.spec()})
    reports = {device: evaluate(str(run), EvalConfig(tasks="reach-v3", episodes=2, workers=1, videos_per_task=0,
                                                     env=SHORT, device=device), tmp_path / f"{device}.json",
                                progress=False) for device in ("cpu", "cuda")}
    assert [r["success"] for r in reports["cuda"]["records"]] == [r["success"] for r in reports["cpu"]["records"]]
