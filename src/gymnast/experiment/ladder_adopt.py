"""A rung that already ran elsewhere: `gymnast ladder --adopt RUNG=RUN`.

A rung costs an hour or more on MT10, and the rung most users have run already is r0 (RL in the
real world with the simulator's success). Adopting such a run links it into the ladder as the rung
instead of training it again, once it is shown to be the same experiment: the same env, reward and
sight as the rung, the same models, the same GRPO recipe (settings that only say how a run is
evaluated, watched or computed may differ, and the report shows what they were: its own evaluation
episodes, say) and the same starting policy: the same path, the same weights, or, where the run's
policy is no longer on disk, the same step-0 real evaluation task by task on the same number of
episodes as the ladder's starting policy (greedy evaluation on the same seeds is deterministic).
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

from gymnast.experiment.ladder_records import recipe_changes, rung_record
from gymnast.experiment.ladder_report import ladder_summary
from gymnast.experiment.rungs import RUNGS, Rung, rung_dir
from gymnast.rl.config import RLConfig, RLRun
from gymnast.utils.settings import from_json, saved_settings

def parse_adoptions(text: str | None) -> dict[Rung, Path]:
    """``RUNG=RUN[,RUNG=RUN...]`` as {rung: run}.

    Raises:
        ValueError: an entry without ``=`` (the message shows the form) or an unknown rung.
    """
    adoptions = {}
    for entry in filter(None, (part.strip() for part in (text or "").split(","))):
        name, sep, run = (part.strip() for part in entry.partition("="))
        if not sep or not name or not run:
            raise ValueError(f"--adopt {entry!r}: give RUNG=RUN, e.g. r0_real=results/rl/scarce_mt10_real")
        if name not in RUNGS:
            raise ValueError(f"--adopt {entry!r}: no rung {name!r}; the rungs are {', '.join(RUNGS)}")
        adoptions[RUNGS[name]] = Path(run)
    return adoptions


def adopt_rung(out: Path, rung: Rung, run: Path, expected: RLRun, recipe: RLConfig) -> Path:
    """Links `run` into the ladder `out` as `rung` (a relative symlink OUT/<rung> -> RUN) after
    checking that it is the rung's experiment; returns the link. Adopting the same run again does
    nothing.

    Args:
        expected: the run the ladder would train for `rung` (`LadderInputs.run_of`).
        recipe: the ladder's GRPO settings.

    Raises:
        ValueError: `run` is not that experiment (the message names each setting that differs),
            or OUT/<rung> holds something else already.
        FileNotFoundError: `run` is not a `gymnast rl` run.
    """
    run, link = Path(run), rung_dir(out, rung)
    target = Path(os.path.relpath(run.resolve(), link.parent.resolve()))
    if link.is_symlink() and link.resolve() == run.resolve():
        return link
    if link.exists() or link.is_symlink():
        raise ValueError(f"{link} exists already: the ladder has its own {rung.name}; remove it to adopt {run}")
    saved = _rl_run_settings(run)
    problems = _run_differences(RLRun.from_json(saved["run"]), expected)
    problems += _recipe_differences(from_json(RLConfig, saved["rl"]), recipe)
    if not problems and not _same_policy(saved["run"]["policy"], expected.policy, rung, run, out, recipe):
        problems.append(f"its starting policy {saved['run']['policy']} is not the ladder's {expected.policy}: not "
                        "the same path or weights, and its step-0 evaluation differs from the ladder's (or the "
                        "ladder has none yet to compare with)")
    if problems:
        raise ValueError(f"{run} cannot be the ladder's {rung.name}: " + "; ".join(problems))
    out.mkdir(parents=True, exist_ok=True)
    os.symlink(target, link, target_is_directory=True)
    return link


def _rl_run_settings(run: Path) -> dict:
    if not (run / "config.json").is_file() or not (run / "metrics.jsonl").is_file():
        raise FileNotFoundError(f"{run} is not a gymnast rl run (it needs config.json and metrics.jsonl)")
    saved = saved_settings(run)
    if "run" not in saved or "rl" not in saved:
        raise FileNotFoundError(f"{run}/config.json holds no 'run' and 'rl' settings: not a gymnast rl run")
    return saved


def _run_differences(run: RLRun, expected: RLRun) -> list[str]:
    """What the run trained with that the rung would not (its env, reward, sight and models)."""
    problems = []
    if run.env != expected.env:
        problems.append(f"it acted in {run.env.name}, the rung in {expected.env.name}")
    if str(run.reward) != str(expected.reward):
        problems.append(f"its reward was {run.reward}, the rung's is {expected.reward}")
    if run.reward_sees != expected.reward_sees:
        problems.append(f"its reward saw {run.reward_sees.name if run.reward_sees else 'its own rollouts'}, the "
                        f"rung's sees {expected.reward_sees.name if expected.reward_sees else 'its own rollouts'}")
    if expected.wm is not None and run.wm != expected.wm:
        problems.append(f"it imagined in {run.wm}, the ladder in {expected.wm}")
    return problems


def _recipe_differences(run: RLConfig, recipe: RLConfig) -> list[str]:
    return [f"{name} was {getattr(run, name)!r}, the ladder's is {getattr(recipe, name)!r}"
            for name in recipe_changes(run, recipe)]


def _same_policy(policy: str, ladder_policy: str, rung: Rung, run: Path, out: Path, recipe: RLConfig) -> bool:
    """Whether the run started from the ladder's policy: by path, by weights, or else by its step-0
    real evaluation."""
    if os.path.normpath(policy) == os.path.normpath(ladder_policy):
        return True
    mine, theirs = _weights_digest(policy), _weights_digest(ladder_policy)
    if mine is not None and theirs is not None:
        return mine == theirs
    start = ladder_summary(out, recipe).get("sft") if out.is_dir() else None
    record = rung_record(rung, run, recipe.steps)
    if start is None or record is None or record["curve"][0]["step"] != 0:
        return False
    first, expected = record["curve"][0], start["curve"][0]
    return (first["episodes"] == expected["episodes"] and first["tasks"].keys() == expected["tasks"].keys()
            and all(math.isclose(value, expected["tasks"][task], abs_tol=1e-6) for task, value in first["tasks"].items()))


def _weights_digest(policy: str) -> str | None:
    """The SHA-256 of a policy's weights, or None where they cannot be read here (gone, or a policy
    that is not a gymnast checkpoint)."""
    from gymnast.utils.checkpoint import resolve_checkpoint

    try:
        weights = resolve_checkpoint(Path(policy)) / "model.safetensors"
    except (FileNotFoundError, OSError):
        return None
    digest = hashlib.sha256()
    with open(weights, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
