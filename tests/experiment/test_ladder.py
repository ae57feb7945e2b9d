"""`gymnast ladder` end to end at the debug size, with the committed models: one part swapped per
rung, the real outcome held against each rung's reward at every step, reruns that continue."""

import json
import os
from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.experiment.ladder import LadderInputs, parse_rungs
from gymnast.experiment.rungs import RUNGS
from gymnast.experiment.ladder_records import fixed_arms
from gymnast.experiment.ladder_report import write_ladder_index
from gymnast.utils.metrics import read_metrics

RESULTS = Path(__file__).resolve().parents[2] / "results"
POLICY, WORLD_MODEL, JUDGE = RESULTS / "sft" / "policy", RESULTS / "world_model" / "wm", RESULTS / "judge" / "one_camera" / "judge"

RUNG_KEYS = {"success", "ci_low", "ci_high", "episodes", "real_interactions", "agreement_by_step", "curve", "watch"}


def _ladder(out, *rungs, models=True):
    args = ["ladder", "--out", str(out), "--preset", "debug", "--rungs", ",".join(rungs)]
    return args + (["--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--judge", str(JUDGE)] if models else [])


def test_the_ladder_swaps_one_part_per_rung_and_holds_each_reward_to_the_real_outcome(tmp_path, capsys):
    out = tmp_path / "ladder" / "scarce" / "reach"
    main(_ladder(out, "r3_imagined_sight", "r2_imagined_verdict", "r4_imagined") + ["--index", str(tmp_path / "ladder")])
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["sft", "r2_imagined_verdict", "r3_imagined_sight", "r4_imagined"]
    for name in ("r2_imagined_verdict", "r3_imagined_sight", "r4_imagined"):
        record = summary[name]
        assert RUNG_KEYS <= record.keys() and record["finished"]
        assert [point["step"] for point in record["curve"]] == [0, 2]
        assert record["curve"][0]["success"] == summary["sft"]["success"]  # the same policy on the same seeds
        # every step says how its reward agreed with the real outcome of the same rollouts
        assert [row["step"] for row in record["agreement_by_step"]] == [1, 2]
        assert all(row["truth_rollouts"] > 0 and "agreement" in row for row in record["agreement_by_step"])
    r2, r3, r4 = (summary[name] for name in ("r2_imagined_verdict", "r3_imagined_sight", "r4_imagined"))
    assert r2["real_interactions"] > 0 and r2["truth_real_interactions"] == 0  # acts for real: the truth is free
    assert r3["real_interactions"] > 0  # its reward replays the imagined actions for real
    assert all(row["agreement"] == 1.0 for row in r3["agreement_by_step"])  # its reward is the truth
    assert r4["real_interactions"] == 0 and r4["truth_real_interactions"] > 0  # the truth measured apart
    assert [row["step"] for row in r4["watch"]] == [1, 2]
    saved = json.loads((out / "r2_imagined_verdict" / "config.json").read_text())["run"]
    assert saved["env"] == "real" and saved["reward_sees"] == "imagined" and saved["reward"] == f"judge:{JUDGE}"
    assert (out / "ladder.md").is_file() and (out / "curves.png").is_file() and (out / "agreement.png").is_file()
    index = json.loads((tmp_path / "ladder" / "summary.json").read_text())
    assert index["scarce"]["reach"]["r4_imagined"] == r4
    assert "r4_imagined" in capsys.readouterr().out

    # A rerun finishes nothing twice; another rung joins the same ladder and its report.
    before = {name: len(read_metrics(out / name)) for name in ("r2_imagined_verdict", "r4_imagined")}
    main(_ladder(out, "r0_real", "r4_imagined", models=False))
    assert {name: len(read_metrics(out / name)) for name in before} == before
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["sft", "r0_real", "r2_imagined_verdict", "r3_imagined_sight", "r4_imagined"]
    assert summary["r0_real"]["real_interactions"] > 0
    assert write_ladder_index(tmp_path / "ladder")["scarce"]["reach"]["r0_real"] == summary["r0_real"]

    # The practice arm after the fix: any `gymnast rl` run with the ladder's recipe in OUT/fixed.
    main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--preset", "debug",
          "--reward", f"all:judge:{JUDGE}+sim", "--reward-sees", "real", "--fresh-scenes", "--truth-groups", "1",
          "--out", str(out / "fixed")])
    main(_ladder(out, "r0_real", models=False))
    fixed = json.loads((out / "summary.json").read_text())["fixed"]
    assert fixed["finished"] and fixed["reward"] == f"all:judge:{JUDGE}+sim" and "a fix" in fixed["what"]
    assert "| fixed |" in (out / "ladder.md").read_text()
    # A fix that imagines in a world model of its own says which.
    other = out / "fixed_refit"
    other.mkdir()
    saved = json.loads((out / "fixed" / "config.json").read_text())
    saved["run"]["wm"] = "elsewhere/world_model"
    (other / "config.json").write_text(json.dumps(saved))
    # ... and one that starts from another policy (say, one taught the imagined sight) says which.
    sight = out / "fixed_sight"
    sight.mkdir()
    saved = json.loads((out / "fixed" / "config.json").read_text())
    saved["run"]["policy"] = "elsewhere/policy"
    (sight / "config.json").write_text(json.dumps(saved))
    # ... and one whose lever is a GRPO setting the ladder's recipe does not have names it.
    anchored = out / "fixed_reanchor"
    anchored.mkdir()
    saved = json.loads((out / "fixed" / "config.json").read_text())
    saved["rl"] |= {"learn_on": "replays", "eval_episodes": 99}  # how it is evaluated is not its lever
    (anchored / "config.json").write_text(json.dumps(saved))
    # ... and one that starts from keyframes of another dataset names the dataset.
    segments = out / "fixed_segments"
    segments.mkdir()
    saved = json.loads((out / "fixed" / "config.json").read_text())
    saved["run"]["data"] = "elsewhere/rollouts"
    (segments / "config.json").write_text(json.dumps(saved))
    arms = {arm.name: arm.what for arm in fixed_arms(out)}
    assert "--data elsewhere/rollouts" in arms["fixed_segments"] and "--data" not in arms["fixed"]
    assert "imagined in elsewhere/world_model" in arms["fixed_refit"] and "imagined in" not in arms["fixed"]
    assert "--learn-on replays" in arms["fixed_reanchor"] and "eval" not in arms["fixed_reanchor"]
    assert "--learn-on" not in arms["fixed"]
    assert arms["fixed_sight"].endswith(", from elsewhere/policy") and "from" not in arms["fixed"]


def test_a_rung_whose_model_is_missing_is_refused_before_any_rung_trains(tmp_path, capsys):
    out = tmp_path / "ladder"
    with pytest.raises(SystemExit):
        main(["ladder", "--out", str(out), "--preset", "debug", "--policy", str(POLICY), "--rungs", "r0_real,r4_imagined"])
    assert "--wm RUN" in capsys.readouterr().err
    assert not (out / "r0_real").exists()
    with pytest.raises(ValueError, match="--state RUN"):
        LadderInputs(policy="p", wm="w").run_of(RUNGS["r4s_imagined_state"])


def test_rungs_are_named_and_run_in_the_order_given():
    assert [rung.name for rung in parse_rungs("r3_imagined_sight,r0_real")] == ["r3_imagined_sight", "r0_real"]
    assert parse_rungs("all") == tuple(RUNGS.values())
    with pytest.raises(ValueError, match="r1_judge_real"):
        parse_rungs("r9")


def test_a_rung_claimed_by_a_live_process_is_left_to_it_and_a_dead_ones_claim_is_taken_over(tmp_path):
    import socket
    import subprocess

    from gymnast.experiment.ladder import CLAIM, claimed

    where = tmp_path / "r0_real"
    with claimed(where) as mine:
        assert mine and (where / CLAIM).read_text().split()[1] == str(os.getpid())
        with claimed(where) as again:  # the same rung asked for twice: the second waits its turn elsewhere
            assert not again
    assert not (where / CLAIM).exists()  # released
    live = subprocess.Popen(["sleep", "30"])
    try:
        (where / CLAIM).write_text(f"{socket.gethostname()} {live.pid}")
        with claimed(where) as mine:
            assert not mine
    finally:
        live.kill()
        live.wait()
    with claimed(where) as mine:  # its process has ended: the claim is stale
        assert mine
    (where / CLAIM).write_text("another-machine 1")  # another machine's claim on a rung that went quiet
    with claimed(where) as mine:
        assert not mine  # just written: it may be at work
    os.utime(where / CLAIM, (0, 0))
    with claimed(where) as mine:
        assert mine



def _real_run(out, policy=POLICY, *extra):
    """A `gymnast rl` run in the real world with the simulator's success, on the debug ladder's recipe."""
    main(["rl", "--policy", str(policy), "--env", "real", "--reward", "sim", "--preset", "debug", "--fresh-scenes",
          "--out", str(out), *extra])
    return out


def _adopting(out, adoptions):
    """`gymnast ladder --adopt ...` with the committed models and no rung to train."""
    return ["ladder", "--out", str(out), "--preset", "debug", "--adopt", adoptions, "--policy", str(POLICY),
            "--wm", str(WORLD_MODEL), "--judge", str(JUDGE)]


def test_a_rung_run_elsewhere_is_adopted_only_when_it_is_the_same_experiment(tmp_path, capsys):
    real = _real_run(tmp_path / "elsewhere" / "real")
    ladder = tmp_path / "ladder"
    trained = len(read_metrics(real))
    main(_adopting(ladder, f"r0_real={real}"))
    link = ladder / "r0_real"
    assert link.is_symlink() and not Path(os.readlink(link)).is_absolute() and link.resolve() == real.resolve()
    assert len(read_metrics(real)) == trained  # linked, not trained again
    record = json.loads((ladder / "summary.json").read_text())["r0_real"]
    assert record["finished"] and record["adopted_from"] == os.readlink(link) and "adopted" in record["what"]
    main(_ladder(ladder, "r0_real", models=False))  # a rerun that names the rung trains nothing into the run
    assert len(read_metrics(real)) == trained

    # Another recipe, another reward or a rung that exists already: refused, naming what differs.
    other_lr = _real_run(tmp_path / "elsewhere" / "lr", POLICY, "--lr", "1e-3")
    with pytest.raises(SystemExit):
        main(_adopting(tmp_path / "ladder2", f"r0_real={other_lr}"))
    assert "lr was 0.001" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(_adopting(tmp_path / "ladder2", f"r1_judge_real={real}"))
    assert "its reward was sim" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(_adopting(ladder, f"r0_real={other_lr}"))
    assert "exists already" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(_adopting(tmp_path / "ladder2", "r0_real"))
    assert "RUNG=RUN" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(_adopting(tmp_path / "ladder2", f"r9_nowhere={real}"))
    assert "no rung 'r9_nowhere'" in capsys.readouterr().err


def test_an_adopted_runs_starting_policy_is_known_by_its_weights_or_else_by_its_step_0_evaluation(tmp_path):
    import shutil

    from gymnast.experiment.ladder_adopt import adopt_rung
    from gymnast.rl.config import RLRun
    from gymnast.experiment.ladder import LADDER_PRESETS
    from gymnast.envs.kinds import REAL
    from gymnast.reward.spec import RewardSpec

    copy = tmp_path / "copy_of_policy"
    shutil.copytree(POLICY, copy)
    real = _real_run(tmp_path / "elsewhere" / "real", copy)
    expected, recipe = RLRun(policy=str(POLICY), env=REAL, reward=RewardSpec("sim")), LADDER_PRESETS["debug"]
    assert adopt_rung(tmp_path / "by_weights", RUNGS["r0_real"], real, expected, recipe).is_symlink()

    # The copy gone: a ladder with no starting evaluation cannot tell; one whose start evaluated the
    # same on the same episodes can, and one whose start evaluated otherwise refuses.
    shutil.rmtree(copy)
    with pytest.raises(ValueError, match="starting policy"):
        adopt_rung(tmp_path / "empty", RUNGS["r0_real"], real, expected, recipe)
    ladder = tmp_path / "with_start"
    shutil.copytree(real, ladder / "fixed")  # any arm of the ladder gives its starting evaluation
    assert adopt_rung(ladder, RUNGS["r0_real"], real, expected, recipe).is_symlink()
    other = tmp_path / "other_start"
    shutil.copytree(real, other / "fixed")
    lines = (other / "fixed" / "metrics.jsonl").read_text().splitlines()
    first = json.loads(lines[0])
    assert first["step"] == 0 and "eval/own_success" in first
    first = {key: (1.0 - value if key.startswith("eval/own_success") else value) for key, value in first.items()}
    (other / "fixed" / "metrics.jsonl").write_text("\n".join([json.dumps(first), *lines[1:]]) + "\n")
    with pytest.raises(ValueError, match="step-0 evaluation differs"):
        adopt_rung(other, RUNGS["r0_real"], real, expected, recipe)
