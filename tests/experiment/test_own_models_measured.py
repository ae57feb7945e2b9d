"""rl-signal and the imagination measurement run on a world model and a policy of one's own (the
example package examples/tiny_video_wm) with no change to gymnast, as every command that takes
--wm or --policy accepts them and says so in its help."""

import json
from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.experiment.dyna import DynaInputs, can_be_refit
from gymnast.experiment.stages import Stages

RESULTS = Path(__file__).resolve().parents[2] / "results"
POLICY, JUDGE = RESULTS / "sft" / "policy", RESULTS / "judge" / "one_camera" / "judge"
OWN_WM = "python:tiny_video_wm.gymnast_plugin:load_world_model"


def test_rl_signal_measures_practice_in_an_own_world_model(tmp_path):
    out = tmp_path / "signal"
    main(["rl-signal", "--policy", str(POLICY), "--wm", "plugin:tiny-video", "--reward", f"judge:{JUDGE}", "--out", str(out),
          "--tasks", "reach-v3", "--starts-per-task", "2", "--group-size", "2", "--horizons", "5", "--batch", "4",
          "--workers", "1"])
    report = json.loads((out / "signal.json").read_text())
    assert len(report["rollouts"]) == 4 and report["interactions"] == 4 * 5


def test_imagination_measures_an_own_policy_in_an_own_world_model(tmp_path):
    out = tmp_path / "imagination"
    main(["imagination", "--policy", "plugin:tiny-policy", "--wm", OWN_WM, "--reward", f"judge:{JUDGE}",
          "--tasks", "reach-v3", "--episodes", "1", "--horizon", "10", "--videos", "1", "--out", str(out)])
    report = json.loads((out / "imagination.json").read_text())
    assert report["settings"]["wm"] == OWN_WM and report["overall"]["episodes"] == 1


def test_dyna_and_the_experiment_take_an_own_world_model_as_given(tmp_path):
    assert not can_be_refit(OWN_WM) and can_be_refit("runs/wm")
    judge = tmp_path / "judge"
    judge.mkdir()
    (judge / "config.json").write_text(json.dumps({"data": "data/demos"}))
    DynaInputs(Path("plugin:tiny-policy"), Path(OWN_WM), judge=judge).check()  # no run directory asked for
    stages = Stages(tmp_path / "experiment", {"world_model": Path(OWN_WM)})
    assert stages.reuse["world_model"] == Path(OWN_WM)
    with pytest.raises(FileNotFoundError, match="no such directory"):
        Stages(tmp_path / "experiment", {"judge": Path("python:my_judge:load")})


@pytest.mark.parametrize("command", ["collect", "eval", "rl", "dyna", "imagination", "rl-signal", "worldgym",
                                     "check-policy", "eval-wm", "object-fidelity", "train-judge", "eval-judge",
                                     "check-wm", "ladder"])
def test_the_help_of_every_command_taking_a_policy_or_world_model_names_every_form(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.replace("│", " ").split())
    forms = ["python:MODULE:FACTORY[@ARG]", "plugin:NAME[@ARG]"]
    if "--policy" in text:
        forms.append("lerobot:PATH")
    assert all(form in text for form in forms), (command, forms)


def test_the_ladders_imagined_rungs_run_in_an_own_world_model_with_an_own_policy(tmp_path):
    out = tmp_path / "ladder"
    main(["ladder", "--policy", "plugin:tiny-policy", "--wm", OWN_WM, "--judge", str(JUDGE), "--out", str(out),
          "--preset", "debug", "--rungs", "r4_imagined,r3_imagined_sight"])
    summary = json.loads((out / "summary.json").read_text())
    for rung in ("r3_imagined_sight", "r4_imagined"):
        assert summary[rung]["finished"] and [row["step"] for row in summary[rung]["agreement_by_step"]] == [1, 2]
    assert json.loads((out / "r4_imagined" / "config.json").read_text())["run"]["wm"] == OWN_WM
