"""`gymnast experiment --preset debug` end to end: every stage, the report, and a rerun that skips."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.experiment.arms import ARM_NAMES

pytestmark = pytest.mark.slow


OWN_SENTENCE = "move the gripper onto the red dot"


@pytest.fixture(scope="module")
def experiment(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("experiment")
    sentences = root / "sentences.txt"
    sentences.write_text(f"# the language check in our own words\nreach-v3: {OWN_SENTENCE}\n")
    out = root / "exp"
    main(["experiment", "--preset", "debug", "--out", str(out), "--workers", "1", "--sentences", str(sentences)])
    return out


def test_the_summary_has_every_arm_with_its_interval_cost_and_time(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    assert {"arms", "wm_rl_over_sft", "wm_rl_over_sim_rl", "worldgym_pearson", "worldgym_spearman"} <= set(summary)
    assert list(summary["arms"]) == list(ARM_NAMES)
    for name, row in summary["arms"].items():
        assert 0 <= row["ci_low"] <= row["success"] <= row["ci_high"] <= 1, name
        assert row["real_interactions"] >= 0 and row["wall_s"] > 0, name
        report = json.loads((experiment / "eval" / f"{name}.json").read_text())
        assert row["success"] == report["success"] and row["episodes"] == report["episodes"] == 2, name
    # Only the real-world arm spends real interactions on training.
    assert summary["arms"]["rl_real"]["real_interactions"] > 0
    assert all(summary["arms"][name]["real_interactions"] == 0 for name in ARM_NAMES if name != "rl_real")


def test_robustness_language_and_worldgym_are_measured(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    for name in ("sft", "rl_wm_judge", "rl_wm_verified"):
        assert set(summary["robustness"][name]) == {"none", "minor", "major"}
        assert summary["language"][name]["heldout"]["episodes"] == 1
        own = json.loads((experiment / "eval" / f"{name}_heldout.json").read_text())
        assert {record["instruction"] for record in own["records"]} == {OWN_SENTENCE}
        perturbed = json.loads((experiment / "eval" / f"{name}_major.json").read_text())
        assert perturbed["config"]["perturb"] == "major"
    policies = [row["policy"] for row in summary["worldgym"]]
    assert len(policies) >= 6 and set(ARM_NAMES) <= set(policies) and "sft_step_3" in policies
    assert all(0 <= row["imagined"] <= 1 and 0 <= row["real"] <= 1 for row in summary["worldgym"])
    ladder = {row["policy"]: row for row in summary["worldgym"] if row["noise"] is not None}
    assert {name: row["noise"] for name, row in ladder.items()} == {"sft_noise_0.5": 0.5, "sft_random": "inf"}
    assert all(row["real_ci"][0] <= row["real"] <= row["real_ci"][1] for row in ladder.values())


def test_the_sft_policy_imagination_is_measured_against_the_real_world(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    figures = summary["imagination"]
    assert figures["episodes"] == 1 and sum(figures["confusion"].values()) == 1  # worldgym_episodes x reach-v3
    assert summary["imagination_agreement"] == figures["agreement"] in (0.0, 1.0)
    assert "imagination" in summary["stage_wall_s"]
    report = json.loads((experiment / "imagination" / "imagination.json").read_text())
    assert report["overall"]["agreement"] == figures["agreement"] and report["settings"]["horizon"] == 40
    assert "](imagination/imagination.md)" in (experiment / "report.md").read_text()


def test_the_report_and_plots_are_written(experiment: Path):
    report = (experiment / "report.md").read_text()
    assert "| RL in the world model, judge (World-Gymnast) |" in report and "WorldGym" in report
    for plot in ("per_task", "learning_curves", "worldgym"):
        assert (experiment / "plots" / f"{plot}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"plots/{plot}.png" in report


def test_a_rerun_skips_every_finished_stage_and_prints_the_table(experiment: Path, capsys):
    records = {path.name: path.read_text() for path in (experiment / "stages").glob("*.json")}
    began = time.perf_counter()
    main(["experiment", "--preset", "debug", "--out", str(experiment), "--workers", "1", "--sentences",
          str(experiment.parent / "sentences.txt")])
    assert time.perf_counter() - began < 60  # nothing is trained or evaluated again
    assert {path.name: path.read_text() for path in (experiment / "stages").glob("*.json")} == records
    out = capsys.readouterr().out
    assert "RL in the real world" in out and "WorldGym Pearson r" in out


def test_resume_continues_with_the_saved_settings_whatever_the_preset(experiment: Path, capsys):
    main(["experiment", "--out", str(experiment), "--resume"])
    assert "WorldGym Pearson r" in capsys.readouterr().out


def test_other_settings_in_the_same_directory_are_refused(experiment: Path, capsys):
    with pytest.raises(SystemExit):
        main(["experiment", "--preset", "demo", "--out", str(experiment)])
    assert "holds an experiment with other settings" in capsys.readouterr().err


def test_a_sentences_file_missing_a_task_is_refused_before_anything_runs(tmp_path: Path, capsys):
    sentences = tmp_path / "ours.txt"
    sentences.write_text("reach-v3: touch the red dot\n")
    with pytest.raises(SystemExit):
        main(["experiment", "--preset", "demo", "--out", str(tmp_path / "exp"), "--sentences", str(sentences)])
    assert f"{sentences} has no sentence for" in capsys.readouterr().err
    assert not (tmp_path / "exp").exists()
