"""Stage bookkeeping: a finished stage is never run twice; reuse is checked before anything runs."""

import json
import sys

import numpy as np
import pytest
from process_memory import resident_bytes

from gymnast.experiment.stages import Stages, parse_reuse


def test_a_finished_stage_is_read_back_instead_of_run_again(tmp_path):
    calls = []
    stages = Stages(tmp_path)
    first = stages.run("sft", lambda: calls.append(1) or {"checkpoint": "x"}, tmp_path / "sft")
    again = Stages(tmp_path).run("sft", lambda: calls.append(2) or {"checkpoint": "y"}, tmp_path / "sft")
    assert calls == [1] and again == first and first["checkpoint"] == "x" and first["wall_s"] >= 0
    assert json.loads((tmp_path / "stages" / "sft.json").read_text()) == first


def test_an_interrupted_stage_leaves_no_record_and_runs_again(tmp_path):
    stages = Stages(tmp_path)

    def crash():
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        stages.run("world_model", crash)
    assert not stages.done("world_model")
    assert stages.run("world_model", lambda: {"ok": True})["ok"] is True


def test_a_reused_stage_points_at_the_given_directory_without_running(tmp_path):
    elsewhere = tmp_path / "wm_run"
    elsewhere.mkdir()
    stages = Stages(tmp_path / "exp", {"world_model": elsewhere})
    record = stages.run("world_model", lambda: pytest.fail("a reused stage must not run"), tmp_path / "exp" / "wm")
    assert record["reused"] is True and stages.path("world_model") == elsewhere


def test_a_stage_reused_from_another_experiment_carries_what_that_experiment_measured(tmp_path):
    rollouts = {"episodes": 400, "successes": 274, "real_interactions": 60000}
    (tmp_path / "first" / "judge").mkdir(parents=True)
    Stages(tmp_path / "first").run("judge", lambda: {"rollouts": rollouts}, tmp_path / "first" / "judge")
    record = Stages(tmp_path / "second", {"judge": tmp_path / "first" / "judge"}).run(
        "judge", lambda: pytest.fail("a reused stage must not run"))
    # The real rollouts the judge learned from count in the experiment that reuses it.
    assert record["reused"] is True and record["rollouts"] == rollouts
    assert record["measured_in"] == str(tmp_path / "first") and record["measured_wall_s"] >= 0
    # Another directory of that experiment's is not its judge stage's output: nothing is borrowed.
    (tmp_path / "first" / "judge_copy").mkdir()
    record = Stages(tmp_path / "third", {"judge": tmp_path / "first" / "judge_copy"}).run("judge", dict)
    assert "rollouts" not in record and "measured_in" not in record


def test_reuse_errors_name_the_stage_or_directory(tmp_path):
    with pytest.raises(ValueError, match="unknown stages \\['arm_rl_sim'\\]"):
        Stages(tmp_path, {"arm_rl_sim": tmp_path})
    with pytest.raises(FileNotFoundError, match="--reuse judge=.*missing"):
        Stages(tmp_path, {"judge": tmp_path / "missing"})
    with pytest.raises(ValueError, match="expects STAGE=DIR"):
        parse_reuse(["world_model"])
    assert parse_reuse(["sft = runs/sft"]) == {"sft": tmp_path.__class__("runs/sft")}


def test_a_stage_finished_here_cannot_later_be_swapped_for_a_reused_one(tmp_path):
    Stages(tmp_path).run("sft", dict, tmp_path / "sft")
    other = tmp_path / "other"
    other.mkdir()
    with pytest.raises(ValueError, match="already finished"):
        Stages(tmp_path, {"sft": other}).run("sft", dict, tmp_path / "sft")


def test_a_recording_is_made_whole_only_while_a_stage_still_to_run_reads_it(tmp_path, caplog):
    dataset, calls = tmp_path / "rollouts", []

    def restore(stages: Stages, readers=("refit",)) -> None:
        stages.restore_dataset("judge", dataset, lambda: calls.append(stages.out.name) or {}, stages.pending(readers),
                               "the rollouts")

    restore(Stages(tmp_path / "new"))  # not recorded yet: the stage itself will
    here = Stages(tmp_path / "here")
    here.run("judge", dict, dataset)  # the stage that recorded them
    restore(here)  # gone (a copy without its datasets): recorded again, with a warning
    assert calls == ["here"] and "the rollouts again" in caplog.text
    (dataset / "meta").mkdir(parents=True)
    (dataset / "meta" / "info.json").write_text("{}")
    caplog.clear()
    restore(here)  # there, perhaps cut short: the recording finishes it (it skips what is there), quietly
    assert calls == ["here", "here"] and "again" not in caplog.text
    here.run("refit", dict)
    restore(here)  # every reader done
    restore(here, readers=())
    elsewhere = Stages(tmp_path / "reusing", {"judge": tmp_path})
    elsewhere.run("judge", pytest.fail)
    restore(elsewhere)  # another run's recording is not this one's to make
    assert calls == ["here", "here"]


def test_a_recording_made_again_that_differs_from_the_first_is_said(tmp_path, caplog):
    dataset, stages = tmp_path / "rollouts", Stages(tmp_path)
    stages.run("judge", lambda: {"rollouts": {"episodes": 400, "successes": 274, "real_interactions": 60000}}, dataset)

    def restore(now: dict) -> None:
        caplog.clear()
        stages.restore_dataset("judge", dataset, lambda: now, True, "the rollouts", lambda record: record["rollouts"])

    restore({"episodes": 400, "successes": 274, "real_interactions": 60000})
    assert "differ" not in caplog.text
    restore({"episodes": 400, "successes": 270, "real_interactions": 60000})
    assert "successes 270 (the stage's recording: 274)" in caplog.text and "episodes 400" not in caplog.text
    restore({"episodes": 399, "successes": 274})
    assert "episodes 399 (the stage's recording: 400)" in caplog.text and str(dataset) in caplog.text


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="malloc_trim is glibc's")
def test_what_a_stage_freed_leaves_the_process_when_it_ends(tmp_path):
    pinned = []

    def decode_and_drop() -> dict:
        frames = [np.ones(8000) for _ in range(3000)]  # 192 MB in 64 KB blocks: the heap, not mmap
        pinned.append(np.ones(8000))  # allocated last, it keeps the heap's top in use, as a live model would
        held.append(resident_bytes())
        del frames
        return {}

    held: list[int] = []
    Stages(tmp_path).run("judge", decode_and_drop)
    assert resident_bytes() < held[0] - 150e6
