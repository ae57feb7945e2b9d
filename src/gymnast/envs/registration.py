"""Gymnasium ids for gymnast's environments, so tools that build envs by id can use them.

    import gymnast.envs                      # registers the ids below
    env = gymnasium.make("gymnast/drawer-open-v3", config=EnvConfig(image_size=96))
    env = gymnasium.make("gymnast/imagined", model=load_world_model("runs/wm"), starts=starts)

``gymnast/<task>`` is the Meta-World "real world" of every task (`MetaWorldEnv`; keyword
arguments such as ``config``, ``gap`` and ``perturbation`` pass through, so a software simulator
is ``gap="mild"``); ``gymnast/imagined`` is the imagined env over a world model (`ImaginedEnv`),
which needs the model and real start frames. No ``max_episode_steps``: the envs end episodes at
their own horizon (``truncated``), and a second time limit would disagree with it.
"""

from __future__ import annotations

import gymnasium

from gymnast.envs.tasks import MT50

NAMESPACE = "gymnast"
IMAGINED_ID = f"{NAMESPACE}/imagined"


def task_id(task: str) -> str:
    """The Gymnasium id of a Meta-World task: ``gymnast/<task>``."""
    return f"{NAMESPACE}/{task}"


def register_envs() -> None:
    """Registers every task's id and the imagined env's; a second call changes nothing."""
    registered = gymnasium.envs.registration.registry
    for task in MT50:
        if task_id(task) not in registered:
            gymnasium.register(task_id(task), entry_point="gymnast.envs.metaworld:MetaWorldEnv", kwargs={"task": task})
    if IMAGINED_ID not in registered:
        gymnasium.register(IMAGINED_ID, entry_point="gymnast.envs.imagined:ImaginedEnv")
