"""`gymnast experiment --preset debug` end to end: every stage, the report, and a rerun that skips."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from gymnast.cli import main
from gymnast.data.lerobot import EpisodeDataset
from gymnast.envs.tasks import eval_seed, resolve_tasks
from gymnast.experiment.arms import ARM_NAMES
from gymnast.experiment.config import EXPERIMENT_PRESETS
from gymnast.experiment.export import export_run
from gymnast.experiment.pipeline import saved_experiment_config
from gymnast.experiment.stages import measured_elsewhere
from gymnast.experiment.status import experiment_plan

pytestmark = pytest.mark.slow


OWN_SENTENCE = "move the gripper onto the red dot"


# The debug preset with half its RL horizon (20 actions, not 40): every rollout, evaluation, watch
# and replay of the pipeline is as many steps long, and rendering them is most of the run's time.
HORIZON = 20


@pytest.fixture(scope="module", autouse=True)
def shorter_debug_preset():
    """`--preset debug` means the shorter preset for every test here, reruns included."""
    debug = EXPERIMENT_PRESETS["debug"]
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(EXPERIMENT_PRESETS, "debug", dataclasses.replace(debug, rl=dataclasses.replace(debug.rl, horizon=HORIZON)))
        yield


@pytest.fixture(scope="module")
def experiment(shorter_debug_preset, tmp_path_factory) -> Path:
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
    # Only the real-world arm and Dyna's recorded rollouts spend real interactions on training.
    assert summary["arms"]["rl_real"]["real_interactions"] > 0 and summary["arms"]["dyna"]["real_interactions"] > 0
    assert all(summary["arms"][name]["real_interactions"] == 0 for name in ARM_NAMES if name not in ("rl_real", "dyna"))
    assert summary["real_rl_real_interactions"] == summary["arms"]["rl_real"]["real_interactions"]


def test_every_stage_sees_the_experiments_two_cameras(experiment: Path):
    views = ("front", "gripper")  # the presets' default
    assert EXPERIMENT_PRESETS["debug"].cameras == views
    assert EpisodeDataset(experiment / "data", cameras=views).cameras == views  # both recorded
    for run in ("sft", "world_model", "judge"):  # each saved with both views
        spec = json.dumps(json.loads((experiment / run / "config.json").read_text()))
        assert '"front", "gripper"' in spec, run
    # Real rollouts recorded along the way are in the policy's views, for the refitted models.
    for rollouts in (experiment / "arms" / "dyna" / "round_1" / "rollouts", experiment / "equal_budget" / "rollouts"):
        assert EpisodeDataset(rollouts, cameras=views).cameras == views, rollouts
    # WorldGym's real and imagined rollouts started from the world model's two views.
    assert json.loads((experiment / "summary.json").read_text())["worldgym"]


def test_the_judge_learns_from_the_sft_policys_own_real_rollouts(experiment: Path):
    recorded = EpisodeDataset(experiment / "judge_rollouts", cameras=("front", "gripper"))
    assert len(recorded) == EXPERIMENT_PRESETS["debug"].judge_rollouts == 1  # one task
    setting = json.loads((experiment / "judge_rollouts" / "gymnast_collect.json").read_text())["env"]
    assert setting["terminate_on_success"] is False and list(recorded.lengths) == [HORIZON]  # past any success
    assert recorded.episodes[0].seed == 300_000  # scenes no other stage records
    judge = json.loads((experiment / "judge" / "config.json").read_text())
    assert [Path(path).resolve() for path in judge["train"]["extra_data"]] == [(experiment / "judge_rollouts").resolve()]
    summary = json.loads((experiment / "summary.json").read_text())
    assert summary["judge_rollouts"]["real_interactions"] == sum(recorded.lengths)
    assert summary["judge_rollouts"]["episodes"] == 1
    assert "It also learned from 1 real rollouts of the SFT policy" in (experiment / "report.md").read_text()


def test_dyna_counts_its_rollouts_and_is_watched_every_round(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    rounds = sorted((experiment / "arms" / "dyna").glob("round_[1-9]"))
    assert [path.name for path in rounds] == ["round_1", "round_2"]  # debug: 2 steps in 2 rounds
    assert [(path / "rollouts").exists() for path in rounds] == [True, False]  # only between rounds
    recorded = sum(EpisodeDataset(rounds[0] / "rollouts").lengths)
    assert summary["dyna_real_interactions"] == summary["arms"]["dyna"]["real_interactions"] == recorded
    # The arm's policy is its last round's; the learning curve has the start and every round's end.
    assert json.loads((experiment / "stages" / "arm_dyna.json").read_text())["path"] == str(rounds[-1] / "rl")
    assert [point["step"] for point in summary["curves"]["dyna"]] == [0, 1, 2]
    assert [row["step"] for row in summary["watch"]["dyna"]] == [1, 2]
    assert set(summary["watch_false_success"]) == {"rl_wm_judge", "rl_wm_verified", "rl_wm_state", "dyna"}
    weak = summary["weak_tasks"]
    assert weak["tasks"] == ["reach-v3"] and set(weak["arms"]) == set(ARM_NAMES)
    assert weak["arms"]["dyna"]["success"] == summary["arms"]["dyna"]["per_task"]["reach-v3"]["success"]
    assert set(summary["goals"]) >= {"wm_rl_2x_sft_on_weak_tasks", "dyna_reaches_real_rl_with_10pct",
                                     "watch_false_success_at_most_10pct"}
    # One table and one plot: Dyna's real success against its real interactions, beside real-world RL's.
    assert [row["round"] for row in summary["dyna"]["rounds"]] == [0, 1, 2]
    assert summary["dyna"]["real_rl"]["curve"][-1]["real_interactions"] == summary["real_rl_real_interactions"]
    report = (experiment / "report.md").read_text()
    assert "## Dyna against RL in the real world" in report and "](plots/dyna.png)" in report
    assert (experiment / "plots" / "dyna.png").read_bytes()[:4] == b"\x89PNG"


def test_the_rl_arms_are_also_set_side_by_side_at_equal_wall_clock(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    timing = summary["equal_wall_clock"]
    assert timing["reference"]["arm"] == "rl_real" and timing["reference"]["steps"] == summary["rl_steps"]
    assert set(timing["arms"]) == {"rl_sim", "rl_wm_judge", "rl_wm_verified", "rl_wm_state"}  # Dyna's rounds aside
    for name, row in timing["arms"].items():
        assert row["steps"] == summary["rl_steps"] and row["train_s"] > 0, name
        assert 0 <= row["reference_steps_in_that_time"] <= summary["rl_steps"], name
    assert "## At equal wall-clock" in (experiment / "report.md").read_text()


def test_one_small_real_budget_is_spent_three_ways_and_every_interaction_is_counted(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    budget, setup = summary["equal_budget"], summary["equal_budget_setup"]
    assert set(budget) == {"real_grpo", "imagined", "iter_sft"}
    for name, row in budget.items():
        assert 0 <= row["ci_low"] <= row["success"] <= row["ci_high"] <= 1 and row["episodes"] == 2, name
    # debug: 2 rollouts of reach, recorded once for the refit and for Iter-SFT, counted from the dataset
    recorded = EpisodeDataset(experiment / "equal_budget" / "rollouts")
    assert len(recorded) == setup["recorded"]["episodes"] == 2
    spent = sum(recorded.lengths)
    assert budget["imagined"]["real_interactions"] == budget["iter_sft"]["real_interactions"] == spent > 0
    # GRPO in the real world spends as many rollouts of its own (one group of 2), counted by its run
    grpo = experiment / "equal_budget" / "real_grpo"
    settings = json.loads((grpo / "config.json").read_text())["rl"]
    assert settings["steps"] * settings["starts_per_step"] * settings["group_size"] == len(recorded)
    assert settings["max_rounds"] == 1 and setup["real_grpo_steps"] == settings["steps"]
    assert budget["real_grpo"]["real_interactions"] == json.loads((grpo / "summary.json").read_text())["real_interactions"] > 0
    # practice in imagination on the world model and the judge refitted on the recorded rollouts
    imagined = experiment / "equal_budget" / "imagined"
    run = json.loads((imagined / "rl" / "config.json").read_text())["run"]
    assert run["wm"] == str(imagined / "world_model") and run["reward"] == f"judge:{imagined / 'judge'}"
    for model in ("world_model", "judge"):
        refit = json.loads((imagined / model / "config.json").read_text())
        assert str(recorded.root) in json.dumps(refit), model
    assert summary["goals"]["imagined_beats_real_grpo_at_equal_budget"] in (True, False)
    report = (experiment / "report.md").read_text()
    assert "## Equal real budgets" in report and "Practice in imagination above GRPO on the same real budget" in report


def test_the_sft_policy_practises_on_a_new_scene_in_imagination_and_is_measured_there_for_real(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    practice = summary["new_scenes"]
    (scene,) = practice["scenes"]  # debug: one new scene of reach
    assert (scene["task"], scene["seed"]) == ("reach-v3", eval_seed(0))
    run = experiment / "new_scenes" / f"reach-v3_{eval_seed(0)}"
    settings = json.loads((run / "config.json").read_text())
    assert settings["rl"]["scenes"] == f"reach-v3:{eval_seed(0)}" and settings["run"]["env"] == "imagined"
    assert settings["run"]["reward"] == f"judge:{experiment / 'judge'}" and settings["run"]["policy"] == str(experiment / "sft")
    assert settings["rl"]["freeze"] == ["vision"] and settings["rl"]["kl_coef"] == 0.1  # the shared recipe
    # practice takes no real interaction; the evaluations before and after and the watch measure, counted apart
    assert practice["totals"]["real_interactions"] == scene["real_interactions"] == 0
    assert scene["eval_real_interactions"] > 0 and scene["reset_frames"] > 0
    assert scene["real_before"] in (True, False) and scene["real_after"] in (True, False)
    assert practice["totals"]["real_after"]["success"] == float(scene["real_after"])
    assert "## Test-time practice on new scenes" in (experiment / "report.md").read_text()


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
    assert report["overall"]["agreement"] == figures["agreement"] and report["settings"]["horizon"] == HORIZON
    assert "](imagination/imagination.md)" in (experiment / "report.md").read_text()


def test_the_practice_signal_of_imagination_is_measured_and_reported(experiment: Path):
    summary = json.loads((experiment / "summary.json").read_text())
    figures = summary["signal"]
    report = json.loads((experiment / "signal" / "signal.json").read_text())
    # debug: one reach start as the world-model arms draw theirs (the dataset's first frames), a group
    # of the RL preset's size, the RL horizon
    saved = json.loads((experiment / "config.json").read_text())
    settings = saved["rl"]
    # The weak tasks take their own number of starts (reach is one).
    assert report["settings"]["task_starts"] == {"reach-v3": saved["signal_weak_scenes"]}
    assert report["settings"]["data"] == str(experiment / "data") and report["settings"]["keyframes"] == settings["keyframes"]
    assert figures["rollouts"] == len(report["rollouts"]) == 2 and figures["horizon"] == settings["horizon"] == HORIZON
    assert figures["real_interactions"] == report["interactions"] == 2 * HORIZON
    longest = {row["readout"]: row for row in report["readouts"] if row["horizon"] == HORIZON}
    assert figures["imagined"]["advantage_correlation"] == longest["score"]["advantage_correlation"]
    assert figures["real_dense"]["signal_groups"] == longest["real dense reward (reference)"]["signal_groups"]
    # The debug experiment's only task is a weak one: the weak tasks' readout pools the same groups.
    weak = summary["signal_weak"]
    assert weak["tasks"] == ["reach-v3"] and weak["rollouts"] == 2
    assert weak["real_dense"]["signal_groups"] == figures["real_dense"]["signal_groups"]
    # The state model's reward head is read on the same starts and rollouts: the same real outcomes.
    state = json.loads((experiment / "signal_state" / "signal.json").read_text())
    assert [r["real_return"] for r in state["rollouts"]] == [r["real_return"] for r in report["rollouts"]]
    assert state["settings"]["reward"] == f"state:{experiment / 'state_model'}"
    assert figures["imagined_state"] == weak["imagined_state"]  # one task: the same groups
    # ... and it rewards the grounded arm.
    arm = json.loads((experiment / "arms" / "rl_wm_state" / "config.json").read_text())["run"]
    assert arm["env"] == "imagined" and arm["reward"] == f"state:{experiment / 'state_model'}"
    assert "signal" in summary["stage_wall_s"]
    assert "](signal/signal.md)" in (experiment / "report.md").read_text()


def test_the_report_and_plots_are_written(experiment: Path):
    report = (experiment / "report.md").read_text()
    assert "| RL in the world model, judge (World-Gymnast) |" in report and "WorldGym" in report
    for plot in ("per_task", "learning_curves", "worldgym"):
        assert (experiment / "plots" / f"{plot}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"plots/{plot}.png" in report


def test_the_sft_regime_is_a_setting_saved_and_reported(experiment: Path, capsys):
    per_task = EXPERIMENT_PRESETS["debug"].sft.demos_per_task
    tasks = len(resolve_tasks(EXPERIMENT_PRESETS["debug"].tasks))
    summary = json.loads((experiment / "summary.json").read_text())
    assert summary["sft_demonstrations"] == {"per_task": per_task, "episodes": per_task * tasks}
    assert f"behaviour-cloned on {per_task} expert demonstrations per task" in (experiment / "report.md").read_text()
    # --demos-per-task sets the SFT stage's count: a resumed run refuses another one, naming both.
    with pytest.raises(SystemExit):
        main(["experiment", "--out", str(experiment), "--resume", "--demos-per-task", str(per_task + 1)])
    err = capsys.readouterr().err
    assert f"--demos-per-task {per_task + 1} disagrees" in err and f"sft.demos_per_task={per_task}" in err


def test_a_rerun_skips_every_finished_stage_and_prints_the_table(experiment: Path, capsys):
    records = {path.name: path.read_text() for path in (experiment / "stages").glob("*.json")}
    began = time.perf_counter()
    main(["experiment", "--preset", "debug", "--out", str(experiment), "--workers", "1", "--sentences",
          str(experiment.parent / "sentences.txt")])
    assert time.perf_counter() - began < 60  # nothing is trained or evaluated again
    assert {path.name: path.read_text() for path in (experiment / "stages").glob("*.json")} == records
    out = capsys.readouterr().out
    assert "RL in the real world" in out and "WorldGym Pearson r" in out


def test_status_of_a_finished_experiment_lists_every_stage_it_ran_as_done(experiment: Path, capsys):
    main(["experiment", "--out", str(experiment), "--status"])
    lines = capsys.readouterr().out.splitlines()
    recorded = sorted(path.stem for path in (experiment / "stages").glob("*.json"))
    planned = experiment_plan(experiment, saved_experiment_config(experiment))
    assert sorted(planned) == recorded  # the plan is the stages the pipeline runs, no more, no fewer
    assert lines[0].startswith(f"{experiment}: {len(recorded)} of {len(recorded)} stages finished")
    assert [line.split()[1] for line in lines[1:]] == planned and all(line.split()[0] == "done" for line in lines[1:])


def test_status_of_an_interrupted_experiment_says_where_a_rerun_goes_on(experiment: Path, tmp_path: Path, capsys):
    copy = tmp_path / "copy"
    copy_experiment(experiment, copy, judge_rollouts=True)
    planned = experiment_plan(copy, saved_experiment_config(copy))
    open_from = planned.index("arm_rl_real")
    for stage in planned[open_from:]:  # as if the run had stopped inside real RL's training
        (copy / "stages" / f"{stage}.json").unlink()
    main(["experiment", "--out", str(copy), "--status"])
    lines = capsys.readouterr().out.splitlines()
    rows = {next(word for word in line.split() if word in planned): line for line in lines[1:]}
    steps = EXPERIMENT_PRESETS["debug"].rl.steps
    assert f"{open_from} of {len(planned)} stages finished" in lines[0]
    assert rows["arm_rl_real"].split()[:2] == ["under", "way"]
    assert f"checkpoint at step {steps} of {steps}" in rows["arm_rl_real"]
    assert all(rows[stage].split()[:2] == ["to", "run"] for stage in planned[open_from + 1:])
    assert all(rows[stage].split()[0] == "done" for stage in planned[:open_from])


def test_status_of_a_directory_without_an_experiment_names_it(tmp_path: Path, capsys):
    with pytest.raises(SystemExit):
        main(["experiment", "--out", str(tmp_path / "none"), "--status"])
    assert f"{tmp_path / 'none'} holds no experiment" in capsys.readouterr().err


def test_report_of_an_experiment_under_way_gives_its_figures_so_far_and_the_stages_left(experiment: Path, tmp_path: Path,
                                                                                           capsys):
    copy = tmp_path / "copy"
    copy_experiment(experiment, copy, judge_rollouts=True)
    planned = experiment_plan(copy, saved_experiment_config(copy))
    open_from = planned.index("arm_rl_wm_judge")
    for stage in planned[open_from:]:  # as if the run had stopped in world-model RL's training
        (copy / "stages" / f"{stage}.json").unlink()
    for written in ("summary.json", "report.md"):
        (copy / written).unlink()
    main(["experiment", "--out", str(copy), "--report"])
    assert f"({len(planned) - open_from} stages still to run)" in capsys.readouterr().out
    summary = json.loads((copy / "summary.json").read_text())
    finished = json.loads((experiment / "summary.json").read_text())
    assert summary["stages_to_run"] == planned[open_from:] and summary["goals"] is None
    assert summary["arms"] == {} and summary["worldgym_pearson"] is None and summary["robustness"] == {}
    assert summary["signal"] == finished["signal"] and summary["imagination"] == finished["imagination"]
    assert summary["judge"] == finished["judge"] and summary["dataset"] == finished["dataset"]
    assert set(summary["curves"]) == {"rl_sim"}  # trained, not yet evaluated
    report = (copy / "report.md").read_text()
    assert "(under way)" in report and "No arm evaluated yet." in report and "`worldgym`" in report
    assert "Does practice in imagination point the right way?" in report
    # The SFT policy's evaluation done: it is in the table and the weak tasks' line.
    shutil.copy(experiment / "stages" / "eval_sft.json", copy / "stages")
    main(["experiment", "--out", str(copy), "--report"])
    summary = json.loads((copy / "summary.json").read_text())
    assert list(summary["arms"]) == ["sft"] and summary["arms"]["sft"] == finished["arms"]["sft"]
    assert "eval_sft" not in summary["stages_to_run"]
    assert summary["weak_tasks"] == {**finished["weak_tasks"], "arms": {"sft": finished["weak_tasks"]["arms"]["sft"]}}
    assert "| SFT" in (copy / "report.md").read_text()
    # Exported under way (no dataset, no report written before): the report says the dataset is not there to count.
    shared = export_run(copy, tmp_path / "shared").destination
    (shared / "summary.json").unlink()
    stages = json.loads((shared / "stages" / "collect.json").read_text())
    (shared / "stages" / "collect.json").write_text(json.dumps({**stages, "path": str(shared / "data")}))
    main(["experiment", "--out", str(shared), "--report"])
    assert json.loads((shared / "summary.json").read_text())["dataset"] is None
    assert "not here to count" in (shared / "report.md").read_text()


def test_report_of_a_finished_experiment_is_the_one_its_last_stage_wrote(experiment: Path, tmp_path: Path, capsys):
    copy = tmp_path / "copy"
    copy_experiment(experiment, copy, judge_rollouts=True)
    (copy / "report.md").unlink()
    main(["experiment", "--out", str(copy), "--report"])
    assert capsys.readouterr().out.strip().endswith("report.md")
    rewritten = json.loads((copy / "summary.json").read_text())
    assert rewritten["stages_to_run"] == [] and rewritten["goals"] == json.loads((experiment / "summary.json").read_text())["goals"]
    assert "(under way)" not in (copy / "report.md").read_text() and (copy / "plots" / "per_task.png").is_file()


def test_an_experiment_from_before_an_arm_existed_trains_only_that_arm(experiment: Path, tmp_path: Path):
    older = tmp_path / "older"
    copy_experiment(experiment, older, judge_rollouts=False)  # Dyna's refit of the judge reads them: recorded again
    for stage in ("arm_dyna", "eval_dyna"):  # as if Dyna had not been an arm yet
        (older / "stages" / f"{stage}.json").unlink()
    shutil.rmtree(older / "arms" / "dyna")
    settings = json.loads((older / "config.json").read_text())
    del settings["dyna"], settings["weak_tasks"]
    (older / "config.json").write_text(json.dumps(settings))
    records = {path.name: path.read_text() for path in (older / "stages").glob("*.json")}
    main(["experiment", "--preset", "debug", "--out", str(older), "--workers", "1", "--sentences",
          str(experiment.parent / "sentences.txt")])
    now = {path.name: path.read_text() for path in (older / "stages").glob("*.json")}
    assert set(now) - set(records) == {"arm_dyna.json", "eval_dyna.json"}
    assert {name: now[name] for name in records} == records
    assert "dyna" in json.loads((older / "summary.json").read_text())["arms"]
    first, again = (EpisodeDataset(run / "judge_rollouts").load(0) for run in (experiment, older))
    assert again.info.seed == first.info.seed == 300_000
    assert np.array_equal(again.actions, first.actions) and np.array_equal(again.env_states, first.env_states)


def test_a_finished_experiment_copied_without_its_judge_rollouts_does_not_record_them(experiment: Path,
                                                                                       tmp_path: Path):
    copy = tmp_path / "copy"
    copy_experiment(experiment, copy, judge_rollouts=False)
    main(["experiment", "--out", str(copy), "--resume"])
    assert not (copy / "judge_rollouts").exists()  # no stage left to run reads them


def test_an_exported_experiment_put_back_where_it_ran_skips_every_stage(experiment: Path, tmp_path: Path, capsys):
    records = {path.name: path.read_text() for path in (experiment / "stages").glob("*.json")}
    written = {name: (experiment / name).read_text() for name in ("summary.json", "report.md")}
    with exported_in_place(experiment, tmp_path):
        assert not list(experiment.rglob("meta/info.json"))  # no datasets, the newest checkpoints, no optimizer states
        capsys.readouterr()
        main(["experiment", "--out", str(experiment), "--resume"])
        assert "WorldGym Pearson r" in capsys.readouterr().out
        assert {path.name: path.read_text() for path in (experiment / "stages").glob("*.json")} == records
        assert {name: (experiment / name).read_text() for name in written} == written  # the dataset's count included
        assert not list(experiment.rglob("meta/info.json"))  # no stage left to run reads a dataset: none recorded


def test_an_exported_experiment_records_its_dataset_again_only_for_a_stage_that_reads_it(experiment: Path,
                                                                                         tmp_path: Path):
    first = EpisodeDataset(experiment / "data")
    with exported_in_place(experiment, tmp_path):
        (experiment / "stages" / "eval_sft.json").unlink()  # an evaluation reads only the dataset's frame size
        main(["experiment", "--out", str(experiment), "--resume"])
        assert (experiment / "stages" / "eval_sft.json").is_file() and not (experiment / "data").exists()
        for stage in ("equal_budget_iter_sft", "eval_equal_budget_iter_sft"):  # Iter-SFT learns from its demos
            (experiment / "stages" / f"{stage}.json").unlink()
        shutil.rmtree(experiment / "equal_budget" / "iter_sft")
        main(["experiment", "--out", str(experiment), "--resume"])
        again = EpisodeDataset(experiment / "data")
        assert [info.seed for info in again.episodes] == [info.seed for info in first.episodes]
        assert all(np.array_equal(again.load(i).actions, first.load(i).actions) for i in range(len(first)))
        assert (experiment / "stages" / "equal_budget_iter_sft.json").is_file()


@contextlib.contextmanager
def exported_in_place(experiment: Path, tmp_path: Path):
    """`experiment` exported (`gymnast export`) and put where it ran, for the body; then as it was."""
    export_run(experiment, tmp_path / "export")
    aside = tmp_path / "aside"
    experiment.rename(aside)
    try:
        (tmp_path / "export").rename(experiment)
        yield
    finally:
        shutil.rmtree(experiment, ignore_errors=True)
        aside.rename(experiment)


def test_judge_rollouts_recorded_in_part_are_finished_before_dyna_refits_the_judge(experiment: Path, tmp_path: Path):
    partial = tmp_path / "partial"
    copy_experiment(experiment, partial, judge_rollouts=True)
    for stage in ("arm_dyna", "eval_dyna"):  # Dyna still to run: it refits the judge on them
        (partial / "stages" / f"{stage}.json").unlink()
    shutil.rmtree(partial / "arms" / "dyna")
    settings = json.loads((partial / "config.json").read_text())
    settings["judge_rollouts"] = 2  # the recording holds one of the two it plans, as if it had been interrupted
    (partial / "config.json").write_text(json.dumps(settings))
    main(["experiment", "--out", str(partial), "--resume"])
    recorded = EpisodeDataset(partial / "judge_rollouts", cameras=("front", "gripper"))
    assert sorted(info.seed for info in recorded.episodes) == [300_000, 300_001]
    assert np.array_equal(recorded.load(0).actions, EpisodeDataset(experiment / "judge_rollouts").load(0).actions)


def test_a_reused_judges_rollouts_are_recorded_again_in_the_experiment_it_learnt_them_in(experiment: Path,
                                                                                          tmp_path: Path):
    maker, here = tmp_path / "maker", tmp_path / "here"  # `here` reuses the judge `maker` trained on its rollouts
    copy_experiment(experiment, maker, judge_rollouts=False)
    copy_experiment(experiment, here, judge_rollouts=False)
    shutil.rmtree(here / "judge")
    made = json.loads((maker / "stages" / "judge.json").read_text())
    (maker / "stages" / "judge.json").write_text(json.dumps({**made, "path": str(maker / "judge")}))  # made there
    reused = {"stage": "judge", "path": str(maker / "judge"), "reused": True, "wall_s": None,
              **measured_elsewhere("judge", maker / "judge")}
    (here / "stages" / "judge.json").write_text(json.dumps(reused))
    for stage in ("arm_dyna", "eval_dyna"):  # Dyna still to run here: it refits that judge on them
        (here / "stages" / f"{stage}.json").unlink()
    shutil.rmtree(here / "arms" / "dyna")
    main(["experiment", "--out", str(here), "--resume"])
    assert not (here / "judge_rollouts").exists()  # not this experiment's to record
    first, again = (EpisodeDataset(run / "judge_rollouts") for run in (experiment, maker))
    assert [info.seed for info in again.episodes] == [info.seed for info in first.episodes]  # the maker's settings
    assert all(np.array_equal(again.load(i).actions, first.load(i).actions) for i in range(len(first)))
    assert (here / "stages" / "arm_dyna.json").is_file()


def test_the_equal_budgets_rollouts_are_recorded_again_when_an_arm_still_to_run_reads_them(experiment: Path,
                                                                                            tmp_path: Path):
    copy = tmp_path / "copy"
    copy_experiment(experiment, copy, judge_rollouts=True, left_out=("equal_budget/rollouts",))
    for stage in ("equal_budget_iter_sft", "eval_equal_budget_iter_sft"):  # Iter-SFT fine-tunes on their successes
        (copy / "stages" / f"{stage}.json").unlink()
    shutil.rmtree(copy / "equal_budget" / "iter_sft")
    main(["experiment", "--out", str(copy), "--resume"])
    first, again = (EpisodeDataset(run / "equal_budget" / "rollouts") for run in (experiment, copy))
    assert [info.seed for info in again.episodes] == [info.seed for info in first.episodes]
    assert all(np.array_equal(again.load(i).actions, first.load(i).actions) for i in range(len(first)))
    assert (copy / "stages" / "equal_budget_iter_sft.json").is_file()


def test_resume_continues_with_the_saved_settings_whatever_the_preset(experiment: Path, capsys):
    main(["experiment", "--out", str(experiment), "--resume"])
    assert "WorldGym Pearson r" in capsys.readouterr().out


def test_parts_to_freeze_that_the_policy_lacks_are_refused_before_the_world_model_trains(experiment: Path,
                                                                                         tmp_path: Path, capsys):
    out = tmp_path / "exp"
    with pytest.raises(SystemExit):
        main(["experiment", "--preset", "debug", "--out", str(out), "--workers", "1", "--reuse",
              f"collect={experiment / 'data'}", "--reuse", f"sft={experiment / 'sft'}", "--freeze", "backbone"])
    err = capsys.readouterr().err
    assert f"{experiment / 'sft'}: RLConfig.freeze: the policy has no parameter named 'backbone'" in err
    assert "vision" in err and "--freeze" in err  # its parts listed, and the way out
    assert not (out / "world_model").exists()


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


def copy_experiment(experiment: Path, copy: Path, judge_rollouts: bool, left_out: tuple[str, ...] = ()) -> None:
    """`experiment` copied, with or without the judge's real rollouts and without the folders
    `left_out` (relative to it), its judge reading the copy's rollouts (as a run started with a
    relative --out does wherever it is copied to)."""
    left_out = {*left_out, *([] if judge_rollouts else ["judge_rollouts"])}

    def ignore(folder: str, names: list[str]) -> list[str]:
        return [name for name in names if (Path(folder) / name).relative_to(experiment).as_posix() in left_out]

    shutil.copytree(experiment, copy, ignore=ignore)
    config = copy / "judge" / "config.json"
    settings = json.loads(config.read_text())
    settings["train"]["extra_data"] = [str(copy / "judge_rollouts")]
    config.write_text(json.dumps(settings))
