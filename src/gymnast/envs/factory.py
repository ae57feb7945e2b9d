"""The chunked vector envs a run rolls out in, built by kind (`gymnast.envs.kinds`): imagined, sim, real
or anchored (real rollouts the policy sees through the world model, `gymnast.envs.anchored`).

Legend: B rollouts stepped together, K actions per chunk, A action dimensions.

Both kinds follow one contract (see `gymnast.envs.sim_vector`): one step is a (B, K, A) action
chunk, its frames in ``infos["frames"]``, no autoreset. A run needs its own env at the training
batch size and, for evaluation and the reward-hacking watch, others (the real world among them).
The training env lives through the run; the others are closed after each use (`close_others`),
since a simulator's scenes take gigabytes, and their worker processes, costly to start, wait for
the next use inside a `gymnast.envs.sim_vector.shared_simulator_processes` block.
"""

from __future__ import annotations

from gymnasium.vector import VectorEnv

from gymnast.config import EnvConfig
from gymnast.envs.anchored import AnchoredImaginedEnv
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.envs.kinds import ANCHORED, IMAGINED, REAL, EnvKind
from gymnast.envs.sim_vector import SimVectorEnv


class EnvFactory:
    """Builds the vector envs a run needs, once each, by kind (imagined, sim, real, anchored) and size.

    Args:
        kind: the run's own env.
        chunk_size: K, the policy's chunk.
        config: image size and horizon of the simulators (the imagined env uses the same horizon).
        gap: the software simulator's gap (the real world has none).
        workers: simulator processes per env.
        runner: where they run: local, ray or ray:ADDRESS (`gymnast.envs.workers.parse_runner`).
        world_model: what the imagined env imagines with.
        stop_above: the imagined env stops a rollout before its first frame whose ensemble
            disagreement exceeds this (`BatchedImaginedEnv`); None never stops.
        batch: the most rollouts per evaluation batch (`gymnast.rl.evaluate.evaluate_in_env`) until
            `train` sets it to the training batch. One runs a single episode at a time, in this process.
        robot_state: the imagined env's robot state beside its frames (`BatchedImaginedEnv`), for
            a policy that reads one; None imagines none.
        anchor_every: the anchored env's actions between restarts from the real frame
            (`AnchoredImaginedEnv`); needed by that kind alone.
    """

    def __init__(self, kind: EnvKind, chunk_size: int, config: EnvConfig, gap: str, workers: int, world_model=None,
                 stop_above: float | None = None, runner: str = "local", batch: int = 1, robot_state=None,
                 anchor_every: int = 0) -> None:
        self.kind, self.chunk_size, self.config, self.gap, self.workers = kind, chunk_size, config, gap, workers
        self.world_model, self.stop_above, self.runner, self.robot_state = world_model, stop_above, runner, robot_state
        self.anchor_every = anchor_every
        self.batch = batch
        self._envs: dict[tuple[str, int], VectorEnv] = {}
        self._training: tuple[str, int] | None = None  # the key of `train`'s env

    def train(self, num_envs: int) -> VectorEnv:
        """The run's own env with `num_envs` rollouts (evaluations then run in batches of at most
        that size); every other env is closed first (`close_others`)."""
        self.batch, self._training = num_envs, (self.kind.name, num_envs)
        self.close_others()
        return self.get(self.kind, num_envs)

    def close_others(self) -> None:
        """Closes every env but the training one (every env before `train`).

        Evaluations and the reward-hacking watch use the others once in many steps, and a
        simulator's workers would hold their scenes in between: gigabytes with two cameras (an
        experiment ran out of 24 GB with the real world's evaluation env open through a simulator
        arm). Inside a `shared_simulator_processes` block the workers wait, without their scenes,
        for the next use."""
        for key in [key for key in self._envs if key != self._training]:
            self._envs.pop(key).close()

    def get(self, kind: EnvKind, num_envs: int) -> VectorEnv:
        key = (kind.name, num_envs)
        if key not in self._envs:
            self._envs[key] = self._build(kind, num_envs)
        return self._envs[key]

    def _build(self, kind: EnvKind, num_envs: int) -> VectorEnv:
        if kind == ANCHORED:
            return AnchoredImaginedEnv(self._build(IMAGINED, num_envs),
                                       self._build(REAL, num_envs), self.anchor_every)
        if kind.imagined:
            return BatchedImaginedEnv(self.world_model, num_envs, self.chunk_size, self.config.horizon,
                                      self.stop_above, self.robot_state)
        gap = "none" if kind.real_interactions else self.gap
        return SimVectorEnv(num_envs, self.chunk_size, self.config, gap=gap, workers=self.workers, runner=self.runner)

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
