"""WorldGym over a noise ladder: the candidates, `gymnast worldgym` end to end, its table and plot."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from gymnast.cli import main
from gymnast.experiment.config import ExperimentConfig
from gymnast.experiment.plots import plot_worldgym_rows
from gymnast.experiment.worldgym import DEFAULT_NOISE, format_rows, json_noise, noise_ladder
from gymnast.policy.noisy import NoisyPolicy

RESULTS = Path(__file__).resolve().parents[2] / "results"
POLICY, WORLD_MODEL = RESULTS / "sft" / "policy", RESULTS / "world_model" / "wm"
JUDGE = RESULTS / "judge" / "one_camera" / "judge"
ROW_KEYS = {"policy", "path", "noise", "imagined", "real", "imagined_ci", "real_ci", "imagined_episodes", "real_episodes"}


def test_the_ladder_is_the_policy_at_each_noise_level_sharing_one_model():
    ladder = noise_ladder(POLICY, (0.0, 0.25, 1.0, math.inf), seed=3, prefix="sft_")
    assert [c.name for c in ladder] == ["sft_noise_0", "sft_noise_0.25", "sft_noise_1", "sft_random"]
    assert [c.noise for c in ladder] == [0.0, 0.25, 1.0, math.inf]
    assert all(c.path == str(POLICY) for c in ladder)
    base = ladder[0].policy
    assert not isinstance(base, NoisyPolicy)  # noise 0 is the policy itself
    for candidate in ladder[1:]:
        assert isinstance(candidate.policy, NoisyPolicy) and candidate.policy.base is base
        assert candidate.policy.noise == candidate.noise and candidate.policy.seed == 3
    assert ladder[-1].policy.random


def test_the_default_ladder_runs_from_the_policy_itself_to_random_actions():
    assert DEFAULT_NOISE[0] == 0 and math.isinf(DEFAULT_NOISE[-1]) and len(DEFAULT_NOISE) >= 8
    assert list(DEFAULT_NOISE) == sorted(DEFAULT_NOISE)


@pytest.mark.parametrize("noise, message", [((), "at least one level"), ((0.5, 0.5), "repeats a level"),
                                            ((-0.5,), "noise must be >= 0")])
def test_a_bad_ladder_is_refused(noise, message):
    with pytest.raises(ValueError, match=message):
        noise_ladder(POLICY, noise)


@pytest.mark.parametrize("noise", [(0.0,), (math.inf,), (0.5, -1.0)])
def test_the_experiment_ladder_takes_positive_finite_noise_only(noise):
    with pytest.raises(ValueError, match="worldgym_noise must be finite and positive"):
        ExperimentConfig(worldgym_noise=noise)


def test_noise_levels_are_valid_json():
    assert json.loads(json.dumps([json_noise(0.0), json_noise(0.3), json_noise(math.inf)])) == [0.0, 0.3, "inf"]
    assert float(json_noise(math.inf)) == math.inf


@pytest.fixture(scope="module")
def command(tmp_path_factory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("worldgym") / "wg"
    capture = pytest.MonkeyPatch()  # module-scoped: capsys is per test, so read stdout through a file
    printed = out.parent / "stdout.txt"
    with printed.open("w") as stream:
        capture.setattr("sys.stdout", stream)
        try:
            main(["worldgym", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--judge", str(JUDGE),
                  "--noise", "0,1.5,inf", "--tasks", "drawer-close-v3", "--episodes", "2", "--horizon", "15",
                  "--workers", "1", "--out", str(out)])
        finally:
            capture.undo()
    return out, printed.read_text()


@pytest.mark.slow
def test_the_command_writes_rows_with_both_intervals_and_the_correlation(command):
    out, _ = command
    result = json.loads((out / "worldgym.json").read_text())
    assert {"rows", "pearson", "spearman", "settings", "seconds"} <= set(result)
    assert [row["policy"] for row in result["rows"]] == ["noise_0", "noise_1.5", "random"]
    assert [row["noise"] for row in result["rows"]] == [0.0, 1.5, "inf"]
    for row in result["rows"]:
        assert set(row) == ROW_KEYS
        assert row["imagined_episodes"] == row["real_episodes"] == 2
        for side in ("imagined", "real"):
            low, high = row[f"{side}_ci"]
            assert 0 <= low <= row[side] <= high <= 1, (row["policy"], side)
            assert high - low > 0.3  # two episodes say little, and the interval says so
    assert result["settings"] == {"policy": str(POLICY), "noise": [0.0, 1.5, "inf"], "wm": str(WORLD_MODEL),
                                  "judge": str(JUDGE), "tasks": "drawer-close-v3", "episodes": 2, "horizon": 15,
                                  "workers": 1, "seed": 0}
    assert result["seconds"] > 0
    assert (out / "worldgym.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_the_command_prints_the_table(command):
    out, printed = command
    assert "noise_1.5" in printed and "random" in printed and "Pearson r =" in printed
    assert str(out / "worldgym.json") in printed


def test_the_table_and_plot_take_rows_of_both_kinds(tmp_path: Path):
    rows = [{"policy": name, "noise": noise, "imagined": i, "real": r, "imagined_ci": [i - 0.1, i + 0.1],
             "real_ci": [r - 0.1, r + 0.2], "imagined_episodes": 10, "real_episodes": 50}
            for name, noise, i, r in (("sft", None, 0.5, 0.6), ("sft_noise_1", 1.0, 0.3, 0.4), ("sft_random", "inf", 0.1, 0.1))]
    text = format_rows({"rows": rows, "pearson": 0.98, "spearman": 1.0})
    assert "sft_noise_1" in text and "50%" in text and "Pearson r = 0.98, Spearman = 1.00 over 3 policies" in text
    assert "undefined" in format_rows({"rows": rows, "pearson": None, "spearman": None})
    path = plot_worldgym_rows(rows, 0.98, 1.0, tmp_path / "wg.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
