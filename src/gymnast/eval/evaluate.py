"""`gymnast eval`: a policy's success rate in the real world, on held-out seeds, with Wilson CIs.

Legend: K action-chunk length, A action dimensions (4 in Meta-World), H/W image height/width.

Every episode starts from an evaluation seed (`gymnast.envs.tasks.eval_seed`), a range no
dataset ever records, so a policy is never scored on an initial state it was trained on. A
learned policy sees the current camera image every K steps and its chunk of K actions is
executed open-loop, as it would be on a robot; the scripted expert reads the simulator state
every step and serves as the reference ceiling. The first few episodes of each task are also
saved as browser-playable videos beside the JSON report. Episodes are played by the rollout
engine (`gymnast.envs.engine.play_episode`), whose stepping the RL loop's envs share.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.eval.actors import PolicyActor, load_run_policy
from gymnast.envs.engine import ScriptedActor, play_episode
from gymnast.envs.experts import ScriptedExpert
from gymnast.envs.gap import get_gap
from gymnast.envs.instructions import SPLITS, pick_sentence, read_sentences
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.envs.parallel import cached_env, parallel_map
from gymnast.envs.perturb import get_perturbation
from gymnast.envs.tasks import eval_seed, resolve_tasks
from gymnast.envs.workers import parse_runner
from gymnast.eval.stats import success_summary
from gymnast.policy.load import policy_env_config
from gymnast.utils.atomic import atomic_path, write_json
from gymnast.utils.device import resolve_device
from gymnast.utils.video import BROWSER_CODEC, encode_video

if TYPE_CHECKING:
    from gymnast.policy.base import Policy

logger = logging.getLogger(__name__)

EXPERT = "expert"
"""The `policy` argument that evaluates Meta-World's scripted expert instead of a run."""
VIDEO_DIR_SUFFIX = "_videos"
"""Videos go beside the JSON report, in ``<report name>_videos/``: one folder per report, so two
reports in one folder (say, with and without perturbation) never overwrite each other's videos."""


@dataclass(frozen=True)
class EvalConfig:
    """Where and how long to evaluate."""

    tasks: str = "mt10"
    """Task names and/or task sets (mt10, mt50), comma-separated."""
    episodes: int = 50
    """Episodes per task, each from its own evaluation seed."""
    perturb: str = "none"
    """Initial-state perturbation: none, minor (2.5 cm), major (5 cm), optionally ':object',
    ':goal', ':robot' or ':all' (the default target)."""
    gap: str = "none"
    """Evaluate in the real world (none) or a software simulator (mild, strong)."""
    instruction_split: str = "train"
    """Instruction paraphrases to give the policy: train or heldout."""
    instruction: str | None = None
    """Give the policy this sentence in every episode instead of the task's paraphrases (your own
    wording of the task); one task only."""
    sentences: Path | None = None
    """A file of ``task: sentence`` lines (your own wording; several per task allowed): each
    episode's instruction is one of its task's sentences, chosen by its seed, instead of the
    split's paraphrases. Every evaluated task needs one."""
    workers: int = 2
    """Processes that run episodes in parallel (one per core is best)."""
    device: str = "cpu"
    """Where the policy runs in each worker: cpu, cuda, cuda:N or auto (CUDA when torch sees a GPU).
    The CPU by default: one episode's forward passes are small, and the simulator is the cost."""
    runner: str = "local"
    """Where the worker processes run: local (spawned on this machine), ray (Ray actors on a Ray
    started here, or on the cluster in RAY_ADDRESS) or ray:ADDRESS (a Ray cluster, e.g. ray:auto or
    ray:ray://head:10001)."""
    videos_per_task: int = 1
    """Episodes of each task (the first ones) saved as mp4 videos; 0 saves none."""
    first_eval_index: int = 0
    """Index of the first evaluation seed; episode i uses eval_seed(first_eval_index + i)."""
    temperature: float = 0.0
    """0 acts greedily (the policy as deployed); above 0 samples every action token at this
    temperature, seeded by the episode's seed, as RL's rollouts do (`gymnast rl` samples at 1.0)."""
    env: EnvConfig = field(default_factory=EnvConfig)
    """Camera, image size and horizon."""

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"EvalConfig.episodes must be at least 1, got {self.episodes}")
        if self.workers < 1:
            raise ValueError(f"EvalConfig.workers must be at least 1, got {self.workers}")
        if self.videos_per_task < 0:
            raise ValueError(f"EvalConfig.videos_per_task must be >= 0, got {self.videos_per_task}")
        if not (self.temperature >= 0 and math.isfinite(self.temperature)):  # also refuses NaN
            raise ValueError(f"EvalConfig.temperature must be a finite number >= 0, got {self.temperature}")
        if self.instruction_split not in SPLITS:
            raise ValueError(f"EvalConfig.instruction_split must be one of {SPLITS}, got {self.instruction_split!r}")
        if self.videos_per_task and self.env.image_size % 2:
            raise ValueError(
                f"videos are H.264 4:2:0, which needs an even image size; got env.image_size="
                f"{self.env.image_size} (pick an even size or videos_per_task=0)"
            )
        # Fail here, in the calling process, rather than in every worker.
        if self.sentences is not None:
            if self.instruction is not None:
                raise ValueError("EvalConfig: give your wording as one instruction or as a sentences file, not both")
            missing = [task for task in resolve_tasks(self.tasks) if task not in self.own_sentences]
            if missing:
                raise ValueError(f"{self.sentences} has no sentence for {', '.join(missing)}")
        if self.instruction is not None:
            if not self.instruction.strip():
                raise ValueError("EvalConfig.instruction is empty; give a sentence or leave it out")
            if len(resolve_tasks(self.tasks)) != 1:
                raise ValueError(f"EvalConfig.instruction is one sentence for one task, but tasks={self.tasks!r} names "
                                 f"{len(resolve_tasks(self.tasks))}; evaluate one task at a time")
        resolve_tasks(self.tasks)
        get_perturbation(self.perturb)
        get_gap(self.gap)
        resolve_device(self.device)
        parse_runner(self.runner)
        eval_seed(self.first_eval_index)
        eval_seed(self.first_eval_index + self.episodes - 1)

    @property
    def own_sentences(self) -> dict[str, tuple[str, ...]]:
        """The sentences file's task -> sentences (empty without one)."""
        return read_sentences(self.sentences) if self.sentences is not None else {}

    @property
    def task_list(self) -> tuple[str, ...]:
        """The tasks, with task sets expanded, in order."""
        return resolve_tasks(self.tasks)

    @property
    def seeds(self) -> tuple[int, ...]:
        """The evaluation seeds every task is run from, in order."""
        return tuple(eval_seed(self.first_eval_index + i) for i in range(self.episodes))


@dataclass(frozen=True)
class EvalJob:
    """One evaluation episode: everything needed to run it, in any process.

    Attributes:
        policy: ``expert`` or a run directory (loaded once per process).
        video_path: where to save this episode's video, or None for no video.
    """

    task: str
    seed: int
    policy: str
    env: EnvConfig
    gap: str
    perturb: str
    instruction_split: str
    video_path: str | None = None
    instruction: str | None = None
    device: str = "cpu"
    temperature: float = 0.0


def plan_episodes(config: EvalConfig, policy: str, video_dir: Path) -> list[EvalJob]:
    """Every episode the configuration asks for, task by task, in seed order."""
    jobs, own = [], config.own_sentences
    for task in config.task_list:
        for i, seed in enumerate(config.seeds):
            video = str(video_dir / f"{task}_{seed}.mp4") if i < config.videos_per_task else None
            instruction = pick_sentence(own[task], task, seed) if own else config.instruction
            jobs.append(EvalJob(task, seed, policy, config.env, config.gap, config.perturb,
                                config.instruction_split, video, instruction, config.device, config.temperature))
    return jobs


def run_episode(job: EvalJob, policy: Policy | None = None) -> dict:
    """Runs one evaluation episode in this process's cached environment.

    Args:
        job: the episode.
        policy: an already-built policy to act with instead of `job.policy` (in-process use only).

    Returns:
        ``{"task", "seed", "instruction", "success", "steps"}``; success means the task was solved
        at some step. The video, if asked for, is written to `job.video_path`.
    """
    env = cached_env(job.task, job.env, gap=job.gap, perturbation=job.perturb,
                     instruction_split=job.instruction_split)
    if job.policy == EXPERT and policy is None:
        actor = ScriptedActor(ScriptedExpert(job.task))
    else:
        policy = policy if policy is not None else load_run_policy(job.policy, job.device)
        actor = PolicyActor(policy, temperature=job.temperature, seed=job.seed)
    run = play_episode(env, actor, job.seed, record=("frames",) if job.video_path else (), instruction=job.instruction)
    if job.video_path:
        with atomic_path(job.video_path) as tmp:
            encode_video(tmp, np.stack(run.frames), fps=MetaWorldEnv.metadata["render_fps"], codec=BROWSER_CODEC)
    return {"task": job.task, "seed": job.seed, "instruction": run.instruction, "success": run.success,
            "steps": run.steps}


def evaluate(policy: str | Policy, config: EvalConfig, out: str | Path, progress: bool = True) -> dict:
    """Evaluates a policy on every task and evaluation seed; writes and returns the report.

    Args:
        policy: ``expert`` (Meta-World's scripted expert, the reference), an SFT/RL run directory
            (its newest checkpoint is loaded once in each worker), or a `Policy` object, which
            runs in this process and therefore needs ``config.workers == 1``.
        config: tasks, episodes, perturbation, gap and workers.
        out: JSON report to write (atomically); videos go to ``<out's folder>/<out's name>_videos/<task>_<seed>.mp4``.
        progress: show a progress bar with the running success rate.

    Returns:
        The report: ``success``, ``ci_low``, ``ci_high`` (95% Wilson), ``episodes``, ``successes``,
        ``per_task`` (task -> the same five), ``records`` (one per episode, sorted by task then
        seed), ``policy``, ``config`` (resolved), ``wall_s``, ``real_interactions`` (environment
        steps taken) and ``videos`` (paths relative to the report's folder).

    Raises:
        FileNotFoundError: `policy` is neither ``expert`` nor an existing directory.
        ValueError: a `Policy` object with more than one worker, or the expert with a temperature.
    """
    out = Path(out)
    label, in_process = _resolve_policy(policy, config)
    config = dataclasses.replace(config, env=policy_env_config(config.env, in_process or label))  # the policy's cameras
    if label == EXPERT and config.temperature > 0:
        raise ValueError(f"the scripted expert has no action tokens to sample; temperature={config.temperature} "
                         f"is for learned policies (leave it at 0 with --policy expert)")
    video_dir = out.parent / f"{out.stem}{VIDEO_DIR_SUFFIX}"
    jobs = plan_episodes(config, label, video_dir)
    run = run_episode if in_process is None else functools.partial(run_episode, policy=in_process)
    logger.info("evaluating %s: %d tasks x %d seeds, perturb=%s, gap=%s, %d workers (%s)", label,
                len(config.task_list), config.episodes, config.perturb, config.gap, config.workers, config.runner)
    start = time.perf_counter()
    records: list[dict] = []
    bar = tqdm(total=len(jobs), desc="eval", unit="ep", disable=not progress)
    try:
        for record in parallel_map(run, jobs, config.workers, config.runner):
            records.append(record)
            bar.update()
            bar.set_postfix(success=f"{sum(r['success'] for r in records) / len(records):.0%}")
    finally:
        bar.close()
    wall_s = time.perf_counter() - start
    order = {task: i for i, task in enumerate(config.task_list)}
    records.sort(key=lambda r: (order[r["task"]], r["seed"]))
    report = {
        **success_summary(records),
        "per_task": {task: success_summary(r for r in records if r["task"] == task) for task in config.task_list},
        "records": records,
        "policy": label,
        "config": _json_ready({**dataclasses.asdict(config), "tasks": ",".join(config.task_list),
                               "seeds": list(config.seeds)}),
        "wall_s": wall_s,
        "real_interactions": sum(r["steps"] for r in records),
        "videos": [f"{video_dir.name}/{Path(job.video_path).name}" for job in jobs if job.video_path],
    }
    write_json(out, report)
    logger.info("success %.1f%% [%.1f, %.1f] over %d episodes in %.0f s; report %s",
                100 * report["success"], 100 * report["ci_low"], 100 * report["ci_high"],
                report["episodes"], wall_s, out)
    return report


def format_summary(report: dict) -> str:
    """Success (%) and 95% CI per task and overall, as aligned text."""
    rows = [*report["per_task"].items(), ("overall", report)]
    width = max(len(name) for name, _ in rows)
    lines = [f"{'task':<{width}}  success  95% CI            episodes"]
    for name, summary in rows:
        lines.append(f"{name:<{width}}  {summary['success']:>7.1%}  [{summary['ci_low']:>6.1%}, "
                     f"{summary['ci_high']:>6.1%}]  {summary['episodes']:>8}")
    return "\n".join(lines)


def _json_ready(value: dict) -> dict:
    # Tuples become lists and paths strings, so the returned report equals the one read back from the file.
    return json.loads(json.dumps(value, default=str))


def _resolve_policy(policy: str | Policy, config: EvalConfig) -> tuple[str, Policy | None]:
    """(label for the report, the policy object when it runs in this process)."""
    if not isinstance(policy, str):
        if config.workers != 1:
            raise ValueError(
                f"a Policy object runs in this process only, so it needs workers=1 (got {config.workers}); "
                "pass its run directory to evaluate with several workers"
            )
        return f"{type(policy).__module__}.{type(policy).__qualname__} (in-process)", policy
    if policy == EXPERT:
        return EXPERT, None
    run_dir = Path(policy)
    if not run_dir.is_dir():
        raise FileNotFoundError(f"policy run directory not found: {run_dir} (pass '{EXPERT}' or an SFT/RL run directory)")
    return str(run_dir.resolve()), None
