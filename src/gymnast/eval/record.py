"""`gymnast collect --policy`: record a learned policy's own real-world rollouts as a dataset.

A success judge and a world model learn best from the states RL visits, which are the policy's
own rather than an expert's. These episodes are collect's in every respect (the `Episode`
schema, the writer, staging and resume of `gymnast.data.collect.collect`), played by a
`PolicyActor` instead of a scripted behaviour: a chunk of K actions from the camera image,
executed open-loop as `gymnast eval` does. Greedy episodes and Gaussian action noise cycle
through ``--noise`` like the experts' (and a temperature samples the action tokens), so one
policy yields both successes and failures. They start from data seeds only: `CollectConfig`
refuses evaluation seeds, which must stay unseen by anything trained on the dataset.

Each episode's behaviour is ``policy-<tag>`` (`gymnast.data.schema.policy_behaviour`), the tag a
digest of the checkpoint's weights and the temperature, so the rollouts of several policies, or
of one policy at several temperatures, can share a dataset and a rerun skips exactly its own.
"""

from __future__ import annotations

import hashlib
import logging
import zlib
from dataclasses import dataclass
from pathlib import Path

from gymnast.data.collect import CollectConfig, EpisodeJob, collect
from gymnast.data.schema import policy_behaviour
from gymnast.eval.actors import PolicyActor, load_run_policy
from gymnast.utils.checkpoint import resolve_checkpoint

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PolicyActors:
    """Builds each episode's `PolicyActor` (a `gymnast.data.collect.ActorFactory`).

    Plain settings, so it pickles to the worker processes, where the policy is loaded once.

    Attributes:
        run: the run (or checkpoint) directory of the policy, absolute.
        temperature: 0 for greedy decoding, above 0 to sample the action tokens.
        behaviour: the behaviour recorded with every episode, ``policy-<tag>``.
    """

    run: str
    temperature: float
    behaviour: str

    def __call__(self, job: EpisodeJob) -> PolicyActor:
        # Seeded by the recipe, so a recipe always yields the same episode, as a scripted one does.
        seed = zlib.crc32(f"{job.task}/{job.seed}".encode())
        return PolicyActor(load_run_policy(self.run), self.temperature, job.noise, seed)


def policy_tag(run: str | Path, temperature: float) -> str:
    """Eight hex digits naming the newest checkpoint of `run` and the sampling temperature.

    The checkpoint is named by the content of its weights, so a moved run keeps its tag and a
    run trained further gets a new one.

    Raises:
        FileNotFoundError: no checkpoint in `run`.
    """
    with open(resolve_checkpoint(Path(run)) / "model.safetensors", "rb") as f:
        digest = hashlib.file_digest(f, "sha256")
    digest.update(f"/temperature={temperature:g}".encode())
    return digest.hexdigest()[:8]


def record_policy(
    run: str | Path, config: CollectConfig, out: str | Path, temperature: float = 0.0, progress: bool = True
) -> dict:
    """Records the rollouts of `run`'s newest checkpoint into the dataset `out`.

    Args:
        run: an SFT/RL run directory (or a checkpoint directory).
        config: tasks, episodes per task, noise levels, seeds, workers and environment, as for
            scripted collection; `failure_fraction` is not used (the policy's own failures are
            recorded).
        out: dataset directory (created if missing); episodes already there are skipped.
        temperature: 0 decodes greedily; above 0 samples every action token at this temperature.
        progress: show a progress bar with the running success rate.

    Returns:
        `gymnast.data.collect.success_table` of the whole dataset.

    Raises:
        FileNotFoundError: no checkpoint in `run`.
        ValueError: the environment's image size is not the policy's, a negative temperature, or
            `out` holds a dataset recorded with other environment settings.
    """
    run_dir = str(Path(run).resolve())
    policy = load_run_policy(run_dir)
    # Fail here, before any worker starts: a policy Meta-World cannot execute, a bad temperature.
    PolicyActor(policy, temperature)
    size = policy.config.image_size
    if size != config.env.image_size:
        raise ValueError(
            f"the policy in {run} sees {size}x{size} images but env.image_size is {config.env.image_size}; "
            f"record with --env.image-size {size}"
        )
    actors = PolicyActors(run_dir, temperature, policy_behaviour(policy_tag(run_dir, temperature)))
    logger.info("recording %s as behaviour %s (temperature %g, noise %s)",
                run_dir, actors.behaviour, temperature, ", ".join(f"{n:g}" for n in config.noise))
    return collect(config, out, progress=progress, make_actor=actors)
