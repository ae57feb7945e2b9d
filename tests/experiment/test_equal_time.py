import json
from pathlib import Path

from gymnast.experiment.report.equal_time import equal_wall_clock, training_seconds


def _run(root: Path, name: str, step_seconds: list[float], repeat: int | None = None) -> Path:
    run = root / name
    run.mkdir()
    lines = [{"step": 0, "eval/own_success": 0.2}]  # an evaluation line carries no step time
    lines += [{"step": i + 1, "time/step_s": seconds} for i, seconds in enumerate(step_seconds)]
    if repeat is not None:  # a resumed run logs the steps after its last checkpoint again
        lines.append({"step": repeat, "time/step_s": step_seconds[repeat - 1]})
    (run / "metrics.jsonl").write_text("".join(json.dumps(line) + "\n" for line in lines))
    return run


def test_training_time_is_summed_over_steps_once_each(tmp_path: Path):
    assert training_seconds(_run(tmp_path, "run", [10.0, 20.0, 30.0], repeat=2)) == [10.0, 30.0, 60.0]


def test_imagined_arms_are_set_against_real_rl_at_the_same_minutes(tmp_path: Path):
    runs = {"rl_real": _run(tmp_path, "real", [10.0] * 4), "rl_wm_judge": _run(tmp_path, "wm", [5.0] * 4),
            "rl_sim": _run(tmp_path, "sim", [1.0] * 4)}
    curve = [{"step": step, "real": success, "real_ci": [success / 2, success * 2]}
             for step, success in ((0, 0.2), (2, 0.3), (4, 0.5))]
    timing = equal_wall_clock(runs, curve)
    assert timing["reference"] == {"arm": "rl_real", "steps": 4, "train_s": 40.0}
    judge = timing["arms"]["rl_wm_judge"]
    # 20 s of imagined training: real RL had finished 2 steps by then and was evaluated at step 2.
    assert (judge["steps"], judge["train_s"], judge["reference_steps_in_that_time"]) == (4, 20.0, 2)
    assert judge["reference_at_that_time"] == {"step": 2, "success": 0.3, "ci_low": 0.15, "ci_high": 0.6}
    assert judge["steps_in_reference_time"] == 8  # 40 s at 5 s a step
    # 4 s: real RL had not finished a step; its step-0 evaluation (the SFT policy) is what it had.
    sim = timing["arms"]["rl_sim"]
    assert sim["reference_steps_in_that_time"] == 0 and sim["reference_at_that_time"]["step"] == 0
    assert sim["steps_in_reference_time"] == 40


def test_without_real_rl_there_is_nothing_to_time_against(tmp_path: Path):
    assert equal_wall_clock({"rl_wm_judge": _run(tmp_path, "wm", [5.0])}, []) is None
