"""Task names, named task sets and the seed ranges that keep evaluation out of every dataset."""

from __future__ import annotations

import difflib
from typing import Iterable

from metaworld.env_dict import ALL_V3_ENVIRONMENTS

MT50: tuple[str, ...] = tuple(ALL_V3_ENVIRONMENTS)
MT10: tuple[str, ...] = (
    "reach-v3",
    "push-v3",
    "pick-place-v3",
    "door-open-v3",
    "drawer-open-v3",
    "drawer-close-v3",
    "button-press-topdown-v3",
    "peg-insert-side-v3",
    "window-open-v3",
    "window-close-v3",
)
TASK_SETS: dict[str, tuple[str, ...]] = {"mt10": MT10, "mt50": MT50}

# Initial states are drawn from a generator seeded by (task, seed), so two different seeds never
# share a state; disjoint ranges make "never evaluated on a state seen in training" checkable.
DATA_SEEDS = range(0, 1_000_000)
EVAL_SEEDS = range(1_000_000, 2_000_000)


def check_task(task: str) -> str:
    """Returns `task` if it is a Meta-World v3 task name, else raises a ValueError listing them."""
    if task in ALL_V3_ENVIRONMENTS:
        return task
    close = difflib.get_close_matches(task, MT50, n=1)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    raise ValueError(
        f"unknown task {task!r}.{hint} Task sets: {', '.join(TASK_SETS)}. "
        f"Tasks: {', '.join(MT50)}"
    )


def resolve_tasks(spec: str | Iterable[str]) -> tuple[str, ...]:
    """Expands task-set names and comma-separated task names into an ordered, unique tuple.

    Args:
        spec: e.g. ``"mt10"``, ``"drawer-open-v3,reach-v3"`` or ``["mt10", "sweep-v3"]``.
    """
    parts = spec.split(",") if isinstance(spec, str) else [p for item in spec for p in item.split(",")]
    tasks: list[str] = []
    for part in (p.strip() for p in parts):
        if not part:
            continue
        for task in TASK_SETS.get(part.lower(), (part,)):
            if check_task(task) not in tasks:
                tasks.append(task)
    if not tasks:
        raise ValueError(f"no tasks given in {spec!r}")
    return tuple(tasks)


def eval_seed(index: int) -> int:
    """The `index`-th evaluation seed (disjoint from every data seed)."""
    if not 0 <= index < len(EVAL_SEEDS):
        raise ValueError(f"evaluation seed index must be in [0, {len(EVAL_SEEDS)}), got {index}")
    return EVAL_SEEDS[index]


def parse_scenes(text: str) -> tuple[tuple[str, int], ...]:
    """Scenes named as ``task:seed``, comma-separated: ``"reach-v3:1000000,push-v3:1000001"``.

    Raises:
        ValueError: an entry is not ``task:seed`` with an integer seed, or its task is unknown.
    """
    scenes = []
    for entry in (part.strip() for part in text.split(",") if part.strip()):
        task, _, seed = entry.rpartition(":")
        if not task or not seed.isdigit():
            raise ValueError(f"scene {entry!r} is not task:seed (for example reach-v3:{EVAL_SEEDS.start})")
        scenes.append((check_task(task), int(seed)))
    if not scenes:
        raise ValueError(f"no scenes given in {text!r}")
    return tuple(scenes)
