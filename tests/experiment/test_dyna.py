"""`gymnast dyna --preset debug`: three rounds end to end on tiny models, resumed without redoing a
round, with the real interactions counted exactly."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect
from gymnast.data.lerobot import EpisodeDataset
from gymnast.experiment.dyna import DYNA_PRESETS, DynaInputs, run_dyna
from gymnast.reward.judges.train import JUDGE_PRESETS, build_judge, train_judge
from gymnast.world_model.train import WM_PRESETS, train_world_model

pytestmark = pytest.mark.slow

POLICY = Path(__file__).resolve().parents[2] / "results" / "sft" / "policy"  # small, at 96 px


@pytest.fixture(scope="module", autouse=True)
def one_rl_step_per_round():
    """`--preset debug` with one RL step per round, not two, for every test here (reruns included):
    the rounds, their rollouts and fine-tuning are the same, the RL half as long."""
    debug = DYNA_PRESETS["debug"]
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(DYNA_PRESETS, "debug", dataclasses.replace(debug, rl=dataclasses.replace(debug.rl, steps=1)))
        yield


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, Path]:
    """A tiny world model and judge trained on a few reach-v3 episodes at the policy's 96 px."""
    root = tmp_path_factory.mktemp("dyna_models")
    data = root / "data"
    collect(CollectConfig(tasks="reach-v3", episodes_per_task=4, noise=(0.0,), failure_fraction=0.5, workers=1,
                          env=EnvConfig(image_size=96, horizon=100)), data, progress=False)
    train_world_model(data, root / "wm", WM_PRESETS["debug"], progress=False)
    train_judge(data, root / "judge", dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.0,
                                                          validation_fraction=0.0), progress=False)
    return {"data": data, "wm": root / "wm", "judge": root / "judge"}


@pytest.fixture(scope="module")
def dyna_run(one_rl_step_per_round, models, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dyna") / "run"
    main(["dyna", "--preset", "debug", "--out", str(out), "--policy", str(POLICY), "--wm", str(models["wm"]),
          "--judge", str(models["judge"]), "--data", str(models["data"])])
    return out


def test_rounds_report_real_success_against_counted_real_interactions(dyna_run: Path):
    summary = json.loads((dyna_run / "summary.json").read_text())
    assert [row["round"] for row in summary["rounds"]] == [0, 1, 2, 3]
    spent = 0
    for row in summary["rounds"]:
        assert 0 <= row["ci_low"] <= row["success"] <= row["ci_high"] <= 1 and row["episodes"] == 1
        if row["round"] in (1, 2):
            # Exactly the actions of the round's recorded episodes, and nothing measured on the side.
            dataset = EpisodeDataset(dyna_run / f"round_{row['round']}" / "rollouts")
            assert len(dataset) == row["rollout_episodes"] == 1
            spent += sum(len(dataset.load(i).actions) for i in range(len(dataset)))
        assert row["real_interactions"] == spent
    assert summary["dyna_real_interactions"] == spent > 0
    # Nothing would learn from the last round's rollouts, so none are taken.
    assert summary["rounds"][-1]["rollout_episodes"] == 0 and not (dyna_run / "round_3" / "rollouts").exists()
    # Each round records new scenes, from data seeds no dataset of the test used.
    scenes = [[info.seed for info in EpisodeDataset(dyna_run / f"round_{k}" / "rollouts").episodes] for k in (1, 2)]
    first = DYNA_PRESETS["debug"].first_rollout_seed
    assert scenes == [[first], [first + 1]]
    curve = summary["real_rl"]["curve"]
    assert [point["step"] for point in curve] == [0, 1, 2, 3]  # evaluated at every round's boundary (1 step each)
    assert curve[-1]["real_interactions"] == summary["real_rl_real_interactions"] > 0
    assert (dyna_run / "dyna.png").stat().st_size > 0
    assert (dyna_run / "dyna.md").read_text().count("| Dyna |") == 4


def test_a_ladder_reports_a_dyna_loop_as_a_fix_arm_with_its_steps_counted_across_rounds(dyna_run: Path, tmp_path):
    from gymnast.experiment.ladder_records import fixed_arms, rung_record

    ladder = tmp_path / "ladder"
    ladder.mkdir()
    (ladder / "fixed_dyna").symlink_to(dyna_run, target_is_directory=True)
    (arm,) = fixed_arms(ladder)
    assert arm.name == "fixed_dyna" and arm.reward == "judge"
    assert "gymnast dyna, 3 rounds of 1 steps" in arm.what and "1 real rollouts a task" in arm.what
    assert arm.what.startswith("a fix:") and arm.what.endswith("the world model and the judge are refit on")
    # In a ladder of another policy the loop names the policy it started from.
    (ladder / "config.json").write_text(json.dumps({"inputs": {"policy": "the/ladders/policy"}}))
    loop_policy = json.loads((dyna_run / "config.json").read_text())["inputs"]["policy"]
    (other,) = fixed_arms(ladder)
    assert other.what.endswith(f"are refit on, from {loop_policy}") and other.own_start and not arm.own_start
    (ladder / "config.json").unlink()
    record = rung_record(arm, ladder / "fixed_dyna", steps=3)
    summary = json.loads((dyna_run / "summary.json").read_text())
    assert [point["step"] for point in record["curve"]] == [0, 1, 2, 3]  # round k at step k x 1
    assert [point["success"] for point in record["curve"]] == [row["success"] for row in summary["rounds"]]
    assert record["real_interactions"] == summary["dyna_real_interactions"] > 0  # the recorded rollouts only
    assert record["steps_done"] == 3 and record["finished"]
    assert record["eval_real_interactions"] > 0


def test_a_loop_that_refits_nothing_is_reported_as_a_control(dyna_run: Path, tmp_path):
    from gymnast.experiment.ladder_records import fixed_arms

    saved = json.loads((dyna_run / "config.json").read_text())

    def described(**refits) -> str:
        loop = tmp_path / "_".join(refits) / "fixed_loop"
        loop.mkdir(parents=True)
        (loop / "config.json").write_text(json.dumps({**saved, "dyna": {**saved["dyna"], **refits}}))
        (arm,) = fixed_arms(loop.parent)
        return arm.what

    assert described(wm_steps=0).endswith("a task that the judge is refit on")
    control = described(wm_steps=0, judge_steps=0)
    assert control.startswith("a control:") and control.endswith("nothing refit between them")


def test_each_round_fine_tunes_from_the_last_and_learns_from_every_recorded_rollout(dyna_run: Path, models):
    second = json.loads((dyna_run / "round_2" / "world_model" / "config.json").read_text())["train"]
    assert second["extra_data"] == [str(dyna_run / f"round_{k}" / "rollouts") for k in (1, 2)]
    assert Path(second["init"]).parent.parent == dyna_run / "round_1" / "world_model"
    judge = json.loads((dyna_run / "round_2" / "judge" / "config.json").read_text())
    assert judge["train"]["init"] == str(dyna_run / "round_1" / "judge")
    assert judge["train"]["extra_data"] == second["extra_data"]
    rl = json.loads((dyna_run / "round_2" / "rl" / "config.json").read_text())["run"]
    assert rl["policy"] == str(dyna_run / "round_1" / "rl") and rl["reward"] == f"judge:{dyna_run / 'round_1' / 'judge'}"
    last = json.loads((dyna_run / "round_3" / "rl" / "config.json").read_text())["run"]
    assert last["wm"] == str(dyna_run / "round_2" / "world_model") and last["reward"] == f"judge:{dyna_run / 'round_2' / 'judge'}"
    assert not (dyna_run / "round_3" / "world_model").exists()  # the last round fine-tunes nothing


def test_a_rerun_skips_finished_rounds_and_a_changed_setting_is_refused(dyna_run: Path, models, monkeypatch):
    import gymnast.rl.train

    def fail(*args, **kwargs):
        raise AssertionError("a finished round ran again")

    monkeypatch.setattr(gymnast.rl.train, "train_rl", fail)
    before = json.loads((dyna_run / "summary.json").read_text())
    main(["dyna", "--out", str(dyna_run), "--resume"])
    after = json.loads((dyna_run / "summary.json").read_text())
    assert after["rounds"] == before["rounds"] and after["real_rl"] == before["real_rl"]
    inputs = DynaInputs(POLICY, models["wm"], models["judge"], models["data"])
    with pytest.raises(ValueError, match="other settings"):
        run_dyna(dataclasses.replace(DYNA_PRESETS["debug"], rounds=4), inputs, dyna_run, progress=False)


def test_bad_inputs_are_refused_before_anything_runs(models, tmp_path):
    with pytest.raises(SystemExit):
        main(["dyna", "--preset", "debug", "--out", str(tmp_path / "a"), "--policy", str(POLICY),
              "--wm", str(models["wm"])])  # no judge
    with pytest.raises(FileNotFoundError, match="--wm .*no run there"):
        run_dyna(DYNA_PRESETS["debug"], DynaInputs(POLICY, tmp_path, models["judge"]), tmp_path / "b")
    with pytest.raises(ValueError, match="rounds must be at least 1"):
        dataclasses.replace(DYNA_PRESETS["debug"], rounds=0)


def test_a_judge_fine_tunes_from_the_given_judge_and_only_one_of_its_own_kind(models):
    import torch

    from gymnast.reward.judges.train import load_judge, saved_judge_config

    source = load_judge(models["judge"])
    config = dataclasses.replace(saved_judge_config(models["judge"]), init=models["judge"], seed=7)
    for key, value in build_judge(config).state_dict().items():
        torch.testing.assert_close(value, source.state_dict()[key], msg=key)
    with pytest.raises(ValueError, match="--init .*frame"):
        build_judge(dataclasses.replace(config, kind="video"))


@pytest.fixture(scope="module")
def state_ensemble(models) -> Path:
    """Two tiny state models (seeds 0 and 1) on the models' episodes, as one ensemble."""
    from gymnast.world_model.state_model import write_state_ensemble
    from gymnast.world_model.train_state import StateTrainConfig, train_state_model

    root = models["data"].parent
    members = []
    for seed in (0, 1):
        settings = StateTrainConfig(steps=2, batch_size=8, unroll=4, hidden=16, checkpoint_every=2, seed=seed)
        train_state_model(models["data"], root / f"state_s{seed}", settings, progress=False)
        members.append(root / f"state_s{seed}")
    write_state_ensemble(root / "state_ens", members)
    return root / "state_ens"


def test_a_state_model_ensemble_rewards_practice_from_the_newest_rollouts_and_every_member_is_refit(
        one_rl_step_per_round, models, state_ensemble, tmp_path):
    out = tmp_path / "run"
    main(["dyna", "--preset", "debug", "--out", str(out), "--policy", str(POLICY), "--wm", str(models["wm"]),
          "--state", str(state_ensemble), "--data", str(models["data"]), "--rounds", "2", "--real-rl", "False",
          "--keyframes", "uniform", "--horizon", "5", "--eval-horizon", "10", "--practice-from-rollouts", "True",
          "--state-steps", "2", "--wm-steps", "0"])
    first = json.loads((out / "round_1" / "rl" / "config.json").read_text())["run"]
    assert first["reward"] == f"state:{state_ensemble}" and first["data"] == str(models["data"])
    # Round 2 practises on the refitted ensemble, from the real rollouts round 1 recorded.
    second = json.loads((out / "round_2" / "rl" / "config.json").read_text())["run"]
    assert second["reward"] == f"state:{out / 'round_1' / 'state'}"
    assert second["data"] == str(out / "round_1" / "rollouts")
    # --wm-steps 0: every round imagines in the given world model.
    assert second["wm"] == str(models["wm"]) and not (out / "round_1" / "world_model").exists()
    for i, member in enumerate(("state_s0", "state_s1")):
        train = json.loads((out / "round_1" / "state" / f"member_{i}" / "config.json").read_text())["train"]
        assert Path(train["init"]).parent.parent.resolve() == (models["data"].parent / member).resolve()
        assert train["extra_data"] == [str(out / "round_1" / "rollouts")] and train["steps"] == 2
    from gymnast.world_model.state_model import load_state_models
    assert len(load_state_models(out / "round_1" / "state")) == 2
    # Segments of 5 actions are practised; the real rollouts and evaluations are whole 10-action episodes.
    assert json.loads((out / "round_1" / "rl" / "config.json").read_text())["rl"]["horizon"] == 5
    recorded = EpisodeDataset(out / "round_1" / "rollouts")
    assert max(len(recorded.load(i).actions) for i in range(len(recorded))) == 10
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rounds"][1]["judge_fpr_on_rollouts"] is None and summary["real_rl"] is None


def test_dyna_practises_on_exactly_one_reward_model(models, state_ensemble, tmp_path):
    with pytest.raises(ValueError, match="not both"):
        DynaInputs(POLICY, models["wm"], models["judge"], state=state_ensemble).check()
    with pytest.raises(ValueError, match="not neither"):
        DynaInputs(POLICY, models["wm"]).check()
    with pytest.raises(FileNotFoundError, match="--state .*no run there"):
        DynaInputs(POLICY, models["wm"], state=tmp_path).check()


def test_a_round_can_record_the_policys_imagined_plans_executed_for_real(models, tmp_path):
    from gymnast.data.schema import policy_behaviour
    from gymnast.eval.record import policy_tag
    from gymnast.experiment.dyna import record_rollouts

    config = dataclasses.replace(DYNA_PRESETS["debug"], record="plans")
    plans = tmp_path / "plans"
    counts = record_rollouts(1, POLICY, None, config, plans, progress=False, planned_in=models["wm"])
    dataset = EpisodeDataset(plans)
    assert counts["episodes"] == len(dataset) == config.rollouts_per_task
    assert counts["real_interactions"] == int(sum(dataset.lengths)) > 0
    # Named by the world model they were planned in: neither the policy's real rollouts nor another model's plans.
    planned = policy_behaviour(policy_tag(POLICY, config.rollout_temperature, models["wm"]))
    assert {info.behaviour for info in dataset.episodes} == {planned}
    assert planned != policy_behaviour(policy_tag(POLICY, config.rollout_temperature))
    with pytest.raises(ValueError, match="record must be rollouts or plans"):
        dataclasses.replace(DYNA_PRESETS["debug"], record="dreams")


def test_a_recipe_gives_every_round_its_grpo_settings_and_the_loop_keeps_its_own(tmp_path):
    from gymnast.experiment.dyna import with_recipe
    from gymnast.rl.config import RLConfig

    ladder = tmp_path / "ladder"
    ladder.mkdir()
    saved = RLConfig(steps=10, lr=3e-5, kl_coef=0.1, freeze=("vision",), fresh_scenes=True, real_eval=True,
                     eval_every=5, watch_every=5, video_every=7, checkpoint_every=2)
    (ladder / "config.json").write_text(json.dumps({"rl": dataclasses.asdict(saved), "inputs": {}}))
    rl = with_recipe(DYNA_PRESETS["full"], ladder, steps=3).rl
    assert (rl.lr, rl.kl_coef, rl.freeze, rl.fresh_scenes) == (3e-5, 0.1, ("vision",), True)
    assert (rl.steps, rl.real_eval, rl.eval_every) == (3, False, 0)  # the round's length, the round's evaluation
    assert (rl.watch_every, rl.video_every, rl.checkpoint_every) == (3, 3, 2)  # at most a round apart
    off = dataclasses.replace(saved, watch_every=0)
    (ladder / "config.json").write_text(json.dumps({"rl": dataclasses.asdict(off)}))
    assert with_recipe(DYNA_PRESETS["full"], ladder, steps=3).rl.watch_every == 0  # no watch stays none
    assert with_recipe(DYNA_PRESETS["full"], ladder).rl.steps == DYNA_PRESETS["full"].rl.steps


def test_every_rounds_imagined_evaluation_has_as_many_seeds_as_its_real_one(tmp_path):
    from gymnast.experiment.dyna import with_recipe
    from gymnast.rl.config import RLConfig

    (tmp_path / "config.json").write_text(json.dumps({"rl": dataclasses.asdict(RLConfig(eval_episodes=100))}))
    config = dataclasses.replace(with_recipe(DYNA_PRESETS["full"], tmp_path), eval_episodes=50)
    assert config.rl.eval_episodes == 100  # the recipe's, for its own evaluations
    assert config.imagined_rl_config.eval_episodes == 50  # the loop's, as its real evaluation
    assert dataclasses.replace(config.imagined_rl_config, eval_episodes=100) == config.rl  # nothing else changes


def test_a_recipe_without_rl_settings_or_given_with_resume_is_refused(tmp_path, capsys):
    from gymnast.experiment.dyna import with_recipe

    with pytest.raises(FileNotFoundError, match="holds no config.json"):
        with_recipe(DYNA_PRESETS["full"], tmp_path / "nowhere")
    (tmp_path / "config.json").write_text(json.dumps({"train": {}}))
    with pytest.raises(ValueError, match=r"config.json holds no rl settings"):
        with_recipe(DYNA_PRESETS["full"], tmp_path)
    with pytest.raises(SystemExit):
        main(["dyna", "--out", str(tmp_path / "run"), "--resume", "--recipe", str(tmp_path)])
    assert "--recipe starts a new run" in capsys.readouterr().err


def test_a_model_whose_training_data_is_gone_is_named_before_anything_runs_unless_it_is_kept(models, tmp_path):
    import shutil

    judge = tmp_path / "judge"
    shutil.copytree(models["judge"], judge)
    saved = json.loads((judge / "config.json").read_text())
    saved["train"]["extra_data"] = [str(tmp_path / "gone")]
    (judge / "config.json").write_text(json.dumps(saved))
    inputs = DynaInputs(POLICY, models["wm"], judge, models["data"])
    with pytest.raises(FileNotFoundError, match=r"--judge .*judge was trained on .*gone, which is not here.*--judge-steps 0"):
        run_dyna(DYNA_PRESETS["debug"], inputs, tmp_path / "refused", progress=False)
    assert not (tmp_path / "refused").exists()  # refused before anything was written


def test_with_no_judge_steps_every_round_judges_with_the_given_judge(one_rl_step_per_round, models, tmp_path):
    config = dataclasses.replace(DYNA_PRESETS["debug"], rounds=2, judge_steps=0, real_rl=False)
    run_dyna(config, DynaInputs(POLICY, models["wm"], models["judge"], models["data"]), tmp_path / "run",
             progress=False)
    second = json.loads((tmp_path / "run" / "round_2" / "rl" / "config.json").read_text())["run"]
    assert second["reward"] == f"judge:{models['judge']}"
    assert second["wm"] == str(tmp_path / "run" / "round_1" / "world_model")  # the world model is still refit
    assert not (tmp_path / "run" / "round_1" / "judge").exists()
