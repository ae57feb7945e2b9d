"""results/practice/summary.json gathers SFT (a run's step-0 evaluation) and each RL arm's last
real-world evaluation, by task set."""

from __future__ import annotations

import json

import pytest

from gymnast.cli import main
from gymnast.experiment.practice_summary import practice_summary


def _run(tmp_path, name, env, start, end, interactions):
    run = tmp_path / name
    run.mkdir()
    episodes = "eval/own_episodes" if env == "real" else "eval/real_episodes"
    curve = [{"step": 0, episodes: 100, "eval/real_success/reach-v3": start, "eval/real_interactions": 50},
             {"step": 40, episodes: 100, "eval/real_success/reach-v3": end, "eval/real_interactions": 123}]
    (run / "summary.json").write_text(json.dumps({
        "env": env, "reward": "x", "steps": 40, "start_real_success": start, "start_real_ci": [start - 0.1, start + 0.1],
        "end_real_success": end, "end_real_ci": [end - 0.1, end + 0.1], "eval_episodes": 50,
        "real_interactions": interactions, "eval_real_interactions": 123, "watch_real_interactions": 7,
        "curve": curve}))
    return run


def test_the_summary_reads_sft_from_the_start_and_each_arm_from_its_end(tmp_path):
    imagined = _run(tmp_path, "imagined", "imagined", 0.2, 0.3, 0)
    real = _run(tmp_path, "real", "real", 0.2, 0.4, 5000)
    summary = practice_summary({"weak": {"imagined_rl": imagined, "real_rl": real}}, tmp_path / "summary.json")
    weak = summary["weak"]
    assert weak["sft"]["success"] == 0.2 and weak["sft"]["real_interactions"] == 0
    assert weak["sft"]["eval_real_interactions"] == 50 and weak["imagined_rl"]["eval_real_interactions"] == 123
    assert weak["imagined_rl"]["success"] == 0.3 and weak["imagined_rl"]["watch_real_interactions"] == 7
    assert weak["real_rl"]["real_interactions"] == 5000 and weak["real_rl"]["ci_low"] == pytest.approx(0.3)
    assert weak["sft"]["episodes"] == weak["real_rl"]["episodes"] == 100
    assert json.loads((tmp_path / "summary.json").read_text()) == summary


def test_an_unfinished_run_or_a_malformed_name_is_refused(tmp_path, capsys):
    with pytest.raises(FileNotFoundError, match="has the run finished"):
        practice_summary({"weak": {"imagined_rl": tmp_path / "missing"}}, tmp_path / "s.json")
    with pytest.raises(ValueError, match="unknown arm"):
        practice_summary({"weak": {"dreaming": tmp_path}}, tmp_path / "s.json")
    with pytest.raises(SystemExit):
        main(["practice-summary", "--out", str(tmp_path / "s.json"), "--run", "weak=runs/x"])
    assert "TASKSET:ARM=RUN" in capsys.readouterr().err
