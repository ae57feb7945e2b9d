"""`gymnast collect --policy`: record a learned policy's own real-world rollouts as a dataset.

A success judge and a world model learn best from the states RL visits, which are the policy's
own rather than an expert's. These episodes are collect's in every respect (the `Episode`
schema, the writer, staging and resume of `gymnast.data.collect.collect`), played by a
`PolicyActor` instead of a scripted behaviour: a chunk of K actions from the camera image,
executed open-loop as `gymnast eval` does. Greedy episodes and Gaussian action noise cycle
through ``--noise`` like the experts' (and a temperature samples the action tokens), so one
policy yields both successes and failures. They start from data seeds only: `CollectConfig`
refuses evaluation seeds, which must stay unseen by anything trained on the dataset.

With a world model (``--imagine-with``), the policy instead plans each episode closed loop in
imagination from the scene's first frame, and the real world executes the plan
(`ImaginedPlanActor`): each episode is then an imagined rollout of the policy labelled by what
its actions really do, at the cost of one real episode.

Each episode's behaviour is ``policy-<tag>`` (`gymnast.data.schema.policy_behaviour`), the tag a
digest of the checkpoint's weights and the temperature (and of the world model that planned), so
the rollouts of several policies, or of one policy at several temperatures, can share a dataset and
a rerun skips exactly its own.
"""

from __future__ import annotations

import hashlib
import logging
import zlib
from dataclasses import dataclass
from pathlib import Path

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, EpisodeJob, collect
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import policy_behaviour
from gymnast.eval.actors import ImaginedPlanActor, PolicyActor, load_run_policy, load_run_world_model
from gymnast.policy.load import is_lerobot, policy_env_config
from gymnast.utils.checkpoint import resolve_checkpoint
from gymnast.utils.plugins import is_plugin

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PolicyActors:
    """Builds each episode's `PolicyActor`, or `ImaginedPlanActor` with a world model (a
    `gymnast.data.collect.ActorFactory`).

    Plain settings, so it pickles to the worker processes, where the policy is loaded once.

    Attributes:
        run: the run (or checkpoint) directory of the policy, absolute.
        temperature: 0 for greedy decoding, above 0 to sample the action tokens.
        behaviour: the behaviour recorded with every episode, ``policy-<tag>``.
        world_model: a world-model run (absolute) the policy plans each episode in; None acts
            in the real world directly.
    """

    run: str
    temperature: float
    behaviour: str
    world_model: str | None = None

    def __call__(self, job: EpisodeJob) -> PolicyActor | ImaginedPlanActor:
        # Seeded by the recipe, so a recipe always yields the same episode, as a scripted one does.
        seed = zlib.crc32(f"{job.task}/{job.seed}".encode())
        actor = PolicyActor(load_run_policy(self.run), self.temperature, job.noise, seed)
        if self.world_model is None:
            return actor
        return ImaginedPlanActor(actor, load_run_world_model(self.world_model), job.env.horizon)


def _where(run: str | Path) -> str:
    """`run` as the workers load it: a run's absolute path, or the name of a LeRobot folder or of a
    factory of one's own (`load_policy` reads either)."""
    return str(run) if is_plugin(run) or is_lerobot(run) else str(Path(run).resolve())


def _named(run: str | Path) -> bytes:
    """What names the model `run` loads: its weights' digest, or its factory's name."""
    return str(run).encode() if is_plugin(run) or is_lerobot(run) else _weights_digest(Path(run))


def policy_tag(run: str | Path, temperature: float, world_model: str | Path | None = None) -> str:
    """Eight hex digits naming the newest checkpoint of `run`, the sampling temperature and the
    world model the policy plans in, if any.

    A checkpoint is named by the content of its weights, so a moved run keeps its tag and a run
    trained further gets a new one (an ensemble by its ``ensemble.json``); a policy or world model
    of one's own (`gymnast.utils.plugins`) by the string that names its factory and argument.

    Raises:
        FileNotFoundError: no checkpoint in `run` or `world_model`.
    """
    digest = hashlib.sha256(_named(run))
    digest.update(f"/temperature={temperature:g}".encode())
    if world_model is not None:
        digest.update(b"/world_model=" + _named(world_model))
    return digest.hexdigest()[:8]


def _weights_digest(run: Path) -> bytes:
    from gymnast.world_model.base import ENSEMBLE_FILE

    path = run / ENSEMBLE_FILE if (run / ENSEMBLE_FILE).is_file() else resolve_checkpoint(run) / "model.safetensors"
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").digest()


def record_policy(
    run: str | Path, config: CollectConfig, out: str | Path, temperature: float = 0.0, progress: bool = True,
    imagine_with: str | Path | None = None,
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
        imagine_with: a world-model run: the policy plans each episode in it from the scene's first
            frame and the real world executes the plan (`ImaginedPlanActor`).

    Returns:
        `gymnast.data.collect.success_table` of the whole dataset.

    Raises:
        FileNotFoundError: no checkpoint in `run`.
        ValueError: the environment's image size is not the policy's, a negative temperature, or
            `out` holds a dataset recorded with other environment settings.
    """
    run_dir = _where(run)
    policy = load_run_policy(run_dir)
    # Fail here, before any worker starts: a policy Meta-World cannot execute, a bad temperature.
    PolicyActor(policy, temperature)
    size = policy.config.image_size
    if size != config.env.image_size:
        raise ValueError(
            f"the policy in {run} sees {size}x{size} images but env.image_size is {config.env.image_size}; "
            f"record with --env.image-size {size}"
        )
    world_model = None
    if imagine_with is not None:
        world_model = _where(imagine_with)
        imagined_size = load_run_world_model(world_model).image_size
        if imagined_size != size:
            raise ValueError(f"the world model in {imagine_with} imagines {imagined_size}x{imagined_size} frames, but "
                             f"the policy in {run} sees {size}x{size}")
    tag = policy_tag(run_dir, temperature, world_model)
    actors = PolicyActors(run_dir, temperature, policy_behaviour(tag), world_model)
    logger.info("recording %s as behaviour %s (temperature %g, noise %s%s)", run_dir, actors.behaviour, temperature,
                ", ".join(f"{n:g}" for n in config.noise), f", planned in {world_model}" if world_model else "")
    return collect(config, out, progress=progress, make_actor=actors)


def record_real_rollouts(run: str | Path, tasks: str, per_task: int, first_seed: int, temperature: float, horizon: int,
                         workers: int, runner: str, out: Path, progress: bool = True,
                         terminate_on_success: bool = True, imagine_with: str | Path | None = None) -> dict:
    """Records `per_task` real rollouts per task of `run`'s policy (sampled at `temperature`, data
    seeds from `first_seed`, no action noise) into `out`, and counts what they cost. Episodes end
    at success, or with `terminate_on_success` False play on to the horizon (a judge's data: the
    frames after a success show it too). With `imagine_with` a world model, each episode is the
    policy's plan made closed loop in it and executed for real (`record_policy`).

    Returns:
        ``episodes``, ``successes`` and ``real_interactions``: the actions taken, read back from
        the recorded dataset itself, so a resumed recording is counted whole.
    """
    # Recorded in every view the policy acts on, at its size: the views a world model and a judge
    # of the same cameras refit on (Dyna, equal budgets) or learn from (the experiment's judge).
    env = policy_env_config(EnvConfig(horizon=horizon, terminate_on_success=terminate_on_success), str(Path(run).resolve()))
    config = CollectConfig(tasks=tasks, episodes_per_task=per_task, noise=(0.0,), first_seed=first_seed,
                           workers=workers, runner=runner, env=env)
    record_policy(run, config, out, temperature=temperature, progress=progress, imagine_with=imagine_with)
    dataset = EpisodeDataset(out)
    return {"episodes": len(dataset), "successes": sum(info.success for info in dataset.episodes),
            "real_interactions": int(sum(dataset.lengths))}
