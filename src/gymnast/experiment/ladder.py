"""`gymnast ladder`: where learning dies between reality and imagination.

GRPO in the real world with the simulator's success learns; GRPO in imagination with a learned
judge does not. Between the two, four parts change at once: what the policy sees, what steps the
rollout, who gives the reward and what the reward sees. The ladder runs the same recipe (the same
settings, seeds, scenes, steps and rollouts) once per rung, each rung swapping one part, from
reality to imagination:

| rung | policy sees / rollout steps | reward | the reward sees |
|---|---|---|---|
| r0_real | real | the simulator's success | the real rollout |
| r1_judge_real | real | the judge | the real video |
| r1s_state_real | real | the state model's reward head | the real states |
| r2_imagined_verdict | real | the judge | the world model's re-imagining of the real actions |
| r3_imagined_sight | imagined | the simulator's success | the imagined actions replayed in the real world |
| r4_imagined | imagined | the judge | the imagined video (World-Gymnast) |
| r4s_imagined_state | imagined | the state model | the real start state and the imagined actions |

Each rung is an ordinary `gymnast rl` run (`gymnast.rl.train.train_rl`) with its env kind, reward
and `RLRun.reward_sees`: a composition of the same engine's parts, not a loop of its own. Every
rung is evaluated in the real world on the same evaluation seeds (the step-0 evaluation, the SFT
policy's, runs once for all: `gymnast.rl.evaluate.shared_evaluations`), watched for reward hacking,
and logs at every step how often its reward agrees with the real outcome of the same rollouts
(`gymnast.rl.sight`). `gymnast.experiment.ladder_report` gathers the rungs into summary.json,
ladder.md and plots.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import socket
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from gymnast.experiment.ladder_report import write_ladder_report
from gymnast.experiment.rungs import RUNGS, Rung, rung_dir
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RL_PRESETS, RLConfig, RLRun
from gymnast.utils.atomic import read_json

logger = logging.getLogger(__name__)

@dataclass(frozen=True)
class LadderInputs:
    """The models a ladder swaps between (paths of runs or checkpoints).

    Attributes:
        policy: the policy every rung starts from (an SFT run).
        wm: the world model of the imagined rungs (r2, r3, r4, r4s).
        judge: the learned judge of the judged rungs (r1, r2, r4).
        state: the state model (or ensemble) of the state rungs (r1s, r4s).
    """

    policy: str
    wm: str | None = None
    judge: str | None = None
    state: str | None = None

    def run_of(self, rung: Rung) -> RLRun:
        """The `gymnast rl` run of `rung`.

        Raises:
            ValueError: the rung needs a model that was not given (the message names the flag).
        """
        if rung.needs_world_model and self.wm is None:
            raise ValueError(f"rung {rung.name} imagines with a world model: give it with --wm RUN")
        spec = {"sim": lambda: RewardSpec("sim"), "judge": lambda: self._model_spec("judge", self.judge, rung),
                "state": lambda: self._model_spec("state", self.state, rung)}[rung.reward]()
        return RLRun(policy=self.policy, env=rung.env, reward=spec, wm=self.wm if rung.needs_world_model else None,
                     reward_sees=rung.sees)

    @staticmethod
    def _model_spec(kind: str, run: str | None, rung: Rung) -> RewardSpec:
        if run is None:
            raise ValueError(f"rung {rung.name} is rewarded by the {kind}: give it with --{kind} RUN, or leave the "
                             f"rung out of --rungs")
        return RewardSpec(kind, run=Path(run))


def parse_rungs(text: str) -> tuple[Rung, ...]:
    """The rungs a comma-separated list names, in its order (the rungs that tell most can run
    first); ``all`` names every one, in the ladder's order.

    Raises:
        ValueError: an unknown rung (the message lists them).
    """
    names = [name.strip() for name in text.split(",") if name.strip()]
    if names == ["all"]:
        return tuple(RUNGS.values())
    unknown = [name for name in names if name not in RUNGS]
    if unknown or not names:
        raise ValueError(f"unknown rung(s) {', '.join(unknown) or '(none given)'}; the rungs are "
                         f"{', '.join(RUNGS)} (or all)")
    return tuple(RUNGS[name] for name in dict.fromkeys(names))


LADDER_PRESETS: dict[str, RLConfig] = {
    # Seconds: every rung at the debug size (tests, a first look at a new world model).
    "debug": dataclasses.replace(RL_PRESETS["debug"], fresh_scenes=True, truth_groups=1, watch_every=1),
    # The recipe that learns on MT10 in the real world (docs/rl.md), with 100 evaluation seeds per
    # task so that a 6-point gain can be told apart, the watch at every evaluation and the truth of
    # 4 groups (32 rollouts) a step where it is not known anyway.
    "full": RLConfig(steps=20, tasks="mt10", fresh_scenes=True, starts_per_step=20, group_size=8, max_rounds=2,
                     temperature=1.0, lr=3e-5, freeze=("vision",), kl_coef=0.1, eval_every=10, eval_episodes=100,
                     watch_every=10, video_every=10, checkpoint_every=5, truth_groups=4),
}


def run_rung(rung: Rung, inputs: LadderInputs, config: RLConfig, out: Path, progress: bool = True) -> dict | None:
    """Trains `rung` in OUT/<rung> (resuming it where it has a checkpoint; a finished one is read
    back) and returns its RL summary; None where another process is training it (`claimed`)."""
    from gymnast.rl.train import train_rl

    where = rung_dir(out, rung)
    if where.is_symlink():  # adopted (`gymnast.experiment.ladder_adopt`): never trained into another run
        logger.info("ladder: %s is the run %s, adopted; nothing to train", rung.name, os.readlink(where))
        return None
    if (where / "summary.json").is_file():
        summary = read_json(where / "summary.json")
        if summary.get("steps") == config.steps and summary["curve"] and summary["curve"][-1]["step"] == config.steps:
            logger.info("ladder: %s finished already", rung.name)
            return summary
    with claimed(where) as mine:
        if not mine:
            logger.info("ladder: %s is under way in another process; going on to the next rung", rung.name)
            return None
        resume = (where / "checkpoints").is_dir() and any((where / "checkpoints").iterdir())
        logger.info("ladder: %s (%s)%s", rung.name, rung.what, ", resumed" if resume else "")
        return train_rl(inputs.run_of(rung), where, config, resume=resume, progress=progress)


CLAIM = ".claim"
"""The file in a rung's directory that names the process training it (host and pid)."""


@contextlib.contextmanager
def claimed(where: Path) -> Iterator[bool]:
    """Claims a rung's directory for this process while the block runs: yields False where another
    live process holds it, so that several ladder processes (on one machine, or on several sharing
    the directory) can run the rungs of one ladder side by side, each taking the next free rung.
    A claim left by a process of this host that no longer runs is taken over, and one of another
    machine whose rung has written nothing for `CLAIM_QUIET_S`."""
    where.mkdir(parents=True, exist_ok=True)
    path, me = where / CLAIM, f"{socket.gethostname()} {os.getpid()}"
    for _ in range(2):
        try:
            descriptor = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            if not _stale(path):
                yield False
                return
            path.unlink(missing_ok=True)
            continue
        with os.fdopen(descriptor, "w") as file:
            file.write(me)
        try:
            yield True
        finally:
            path.unlink(missing_ok=True)
        return
    yield False


CLAIM_QUIET_S = 3600.0
"""A claim of another machine counts as abandoned when its rung has written nothing for this long
(a step writes its metrics within minutes)."""


def _stale(path: Path) -> bool:
    """Whether the claim at `path` was left by a process of this host that has ended, or by another
    machine's whose rung has been quiet for `CLAIM_QUIET_S` (its process cannot be checked from here)."""
    try:
        host, pid = path.read_text().split()
    except (OSError, ValueError):
        return True  # unreadable or half-written: nobody holds it
    if host != socket.gethostname():
        written = max(p.stat().st_mtime for p in (path, path.parent / "metrics.jsonl") if p.exists())
        return time.time() - written > CLAIM_QUIET_S
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def run_ladder(inputs: LadderInputs, config: RLConfig, rungs: tuple[Rung, ...], out: Path,
               progress: bool = True) -> dict:
    """Runs the rungs in order in OUT/<rung>/ and writes OUT/summary.json, OUT/ladder.md and plots
    after each one (of every rung OUT holds, those of earlier invocations included), so an
    interrupted ladder reports what finished; a rerun continues.

    Each rung's run is checked before any trains: a missing model is refused at once, not after
    hours of the rungs before it.
    """
    from gymnast.rl.evaluate import shared_evaluations

    for rung in rungs:
        inputs.run_of(rung)
    with shared_evaluations():  # the SFT policy's step-0 evaluation runs once for every rung
        for rung in rungs:
            run_rung(rung, inputs, config, out, progress)
            write_ladder_report(out, config)
    return write_ladder_report(out, config)
