"""WorldGym: can the world model and its judge rank policies without the real world?

Each policy's success is estimated in imagination (greedy rollouts from the real first frames of
evaluation seeds, judged by the learned judge) and in the real world (greedy rollouts from the
same seeds), each with a 95% Wilson interval, over policies of different quality; WorldGym
(World-Gymnast's evaluation) reports the correlation between the two.

A correlation says little over policies of similar quality, so the policies include a ladder of
one trained policy with growing action noise (`gymnast.policy.noisy`), down to random actions:
together they span most of the range of real success. Both estimates run through the RL loop's
rollout engine (`gymnast.rl.evaluate.evaluate_in_env`), whose real-world protocol is
`gymnast eval`'s (greedy chunks executed open-loop, success at any step, the same horizon and
evaluation seeds), with the envs built once for all policies.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.envs.kinds import IMAGINED, REAL, EnvKind

if TYPE_CHECKING:  # torch stays unimported until a policy is loaded (the CLI reads DEFAULT_NOISE)
    from gymnast.policy.base import Policy

logger = logging.getLogger(__name__)

DEFAULT_NOISE = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, math.inf)
"""The noise ladder of `gymnast worldgym`: the policy itself, action noise (std, in action units)
in steps that each cost the MT10 SFT policy some real success, then random actions. On three
tasks it solves (4 seeds each) real success stayed 100% up to noise 0.2, then fell to 75% at 0.5,
58% at 0.75, 50% at 1.0, 17% at 1.5 and 0% for random actions."""


@dataclass(frozen=True)
class Candidate:
    """One policy whose imagined and real success WorldGym estimates.

    Attributes:
        name: the row's label (``noise_0.3``, ``random``, an arm's name, ...).
        policy: the loaded policy (acts greedily through ``act``).
        path: the run or checkpoint its weights came from.
        noise: the action-noise std added to it (``inf``: random actions), or None for a policy
            as trained.
    """

    name: str
    policy: Policy
    path: str
    noise: float | None = None


def noise_name(noise: float) -> str:
    """A noise level's row label: ``noise_0.3``, or ``random`` for infinite noise."""
    return "random" if math.isinf(noise) else f"noise_{noise:g}"


def json_noise(noise: float) -> float | str:
    """A noise level as JSON has it: the number, or ``"inf"`` for random actions (JSON has no
    infinity; ``float("inf")`` reads it back)."""
    return "inf" if math.isinf(noise) else float(noise)


def noise_ladder(policy_run: Path, noise: Sequence[float], seed: int = 0, prefix: str = "") -> list[Candidate]:
    """The policy of `policy_run` at each noise level (loaded once, shared by every level).

    Every level draws from the same seed, so the levels see the same standard-normal draws scaled
    by their std (common random numbers: the ladder's steps differ by the noise size alone).

    Args:
        policy_run: an SFT/RL run or checkpoint directory.
        noise: action-noise std per level; 0 is the policy itself, ``inf`` random actions.
        seed: seed of every level's noise generator.
        prefix: put before every name (e.g. ``sft_``).

    Raises:
        ValueError: no level, a repeated level, or a negative one.
    """
    from gymnast.policy.noisy import NoisyPolicy
    from gymnast.policy.load import load_policy

    if not noise:
        raise ValueError("the noise ladder needs at least one level")
    if len(set(noise)) != len(noise):
        raise ValueError(f"the noise ladder repeats a level: {list(noise)}")
    base = load_policy(policy_run)
    return [Candidate(prefix + noise_name(level), base if level == 0 else NoisyPolicy(base, level, seed),
                      str(policy_run), float(level)) for level in noise]


class WorldGym:
    """Imagined and real success of policies on one set of evaluation starts.

    Args:
        wm_run: the world model the policies are imagined in.
        judge_run: the learned judge that scores the imagined rollouts.
        tasks: task names or sets, comma-separated.
        episodes: evaluation seeds per task (the same ones in both worlds).
        env: image size (the policies' and the world model's) and horizon of both worlds.
        workers: simulator processes for the real rollouts.
        batch: most rollouts stepped together.
        runner: where the simulator processes run: local, ray or ray:ADDRESS.
    """

    def __init__(self, wm_run: Path, judge_run: Path, tasks: str, episodes: int, env: EnvConfig, workers: int = 2,
                 batch: int = 32, runner: str = "local") -> None:
        from gymnast.envs.starts import evaluation_starts
        from gymnast.envs.tasks import resolve_tasks
        from gymnast.reward.select import make_reward
        from gymnast.reward.spec import RewardSpec
        from gymnast.world_model.base import load_world_model
        from gymnast.world_model.views import replay_cameras

        if episodes < 1:
            raise ValueError(f"WorldGym needs at least one episode per task, got {episodes}")
        self.world_model = load_world_model(wm_run)
        # The real and the imagined rollouts start from the views the world model imagines.
        env = dataclasses.replace(env, cameras=replay_cameras(self.world_model))
        self.tasks, self.env, self.workers, self.runner = resolve_tasks(tasks), env, workers, runner
        self.judge = make_reward(RewardSpec.judge(judge_run))
        self.starts = evaluation_starts(self.tasks, episodes, env)
        # Equal batches: 100 starts run as 4 x 25 rather than 32 + 32 + 32 + 4 padded to 32.
        self.batch = math.ceil(len(self.starts) / math.ceil(len(self.starts) / batch))
        self._factories: dict = {}  # chunk size -> EnvFactory, built at first use

    def imagined(self, policy: Policy) -> dict:
        """Judged success of `policy`'s greedy imagined rollouts (see `real` for the keys)."""
        return self._success(IMAGINED, policy)

    def real(self, policy: Policy) -> dict:
        """Real-world success of `policy`'s greedy rollouts: ``success``, ``ci_low``,
        ``ci_high`` (95% Wilson), ``episodes`` and ``per_task``."""
        return self._success(REAL, policy)

    def row(self, candidate: Candidate, real: Mapping | None = None) -> dict:
        """`candidate`'s WorldGym row; `real` (a `gymnast eval` report) replaces its real rollouts."""
        imagined = self.imagined(candidate.policy)
        real = real if real is not None else self.real(candidate.policy)
        noise = None if candidate.noise is None else json_noise(candidate.noise)
        row = {"policy": candidate.name, "path": candidate.path, "noise": noise,
               "imagined": imagined["success"], "real": real["success"],
               "imagined_ci": [imagined["ci_low"], imagined["ci_high"]], "real_ci": [real["ci_low"], real["ci_high"]],
               "imagined_episodes": imagined["episodes"], "real_episodes": real["episodes"]}
        logger.info("WorldGym %s: imagined %.2f [%.2f, %.2f], real %.2f [%.2f, %.2f]", candidate.name,
                    row["imagined"], *row["imagined_ci"], row["real"], *row["real_ci"])
        return row

    def rows(self, candidates: Sequence[Candidate], real: Mapping[str, Mapping] | None = None,
             progress: bool = True) -> list[dict]:
        """Every candidate's row, in order; `real` maps names to reports that replace real rollouts."""
        real = real or {}
        return [self.row(candidate, real.get(candidate.name))
                for candidate in tqdm(candidates, desc="worldgym", unit="policy", disable=not progress)]

    def _success(self, kind: EnvKind, policy: Policy) -> dict:
        from gymnast.envs.factory import EnvFactory
        from gymnast.rl.evaluate import evaluate_in_env

        if hasattr(policy, "reseed"):  # a noisy policy: each estimate draws its own noise from the start
            policy.reseed()
        if policy.chunk_size not in self._factories:
            self._factories[policy.chunk_size] = EnvFactory(IMAGINED, policy.chunk_size, self.env, "none", self.workers,
                                                            self.world_model, runner=self.runner, batch=self.batch)
        values = evaluate_in_env(self._factories[policy.chunk_size], kind, policy, self.judge, self.starts, prefix="wg")
        if "wg_success" not in values:
            raise RuntimeError(f"none of the {len(self.starts)} {kind} rollouts could be judged")
        return {"success": values["wg_success"], "ci_low": values["wg_ci_low"], "ci_high": values["wg_ci_high"],
                "episodes": int(values["wg_episodes"]),
                "per_task": {task: values[f"wg_success/{task}"] for task in self.tasks}}

    def close(self) -> None:
        """Stops the simulator processes."""
        for factory in self._factories.values():
            factory.close()
        self._factories.clear()

    def __enter__(self) -> WorldGym:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def correlation(imagined: list[float], real: list[float]) -> dict:
    """Pearson and Spearman correlation of imagined with real success over policies (None where
    undefined: fewer than three policies, or one side constant)."""
    from scipy import stats

    if len(imagined) != len(real):
        raise ValueError(f"{len(imagined)} imagined estimates but {len(real)} real ones")
    if len(imagined) < 3 or len(set(imagined)) < 2 or len(set(real)) < 2:
        return {"pearson": None, "spearman": None}
    pearson = float(stats.pearsonr(imagined, real).statistic)
    spearman = float(stats.spearmanr(imagined, real).statistic)
    return {"pearson": None if math.isnan(pearson) else pearson, "spearman": None if math.isnan(spearman) else spearman}


def run_worldgym(policy_run: Path, noise: Sequence[float], wm_run: Path, judge_run: Path, tasks: str, episodes: int,
                 out: Path, horizon: int = 150, workers: int = 2, seed: int = 0, progress: bool = True,
                 runner: str = "local") -> dict:
    """`gymnast worldgym`: the noise ladder of one policy, estimated in imagination and in the
    real world; writes ``out/worldgym.json`` and ``out/worldgym.png`` and returns the JSON's content.

    Returns:
        ``rows`` (one per level: ``policy``, ``path``, ``noise``, ``imagined``, ``imagined_ci``,
        ``imagined_episodes``, ``real``, ``real_ci``, ``real_episodes``), ``pearson`` and
        ``spearman`` over the rows, ``settings`` (the arguments) and ``seconds``.
    """
    from gymnast.experiment.plots import plot_worldgym_rows
    from gymnast.utils.atomic import write_json

    began = time.perf_counter()
    candidates = noise_ladder(policy_run, noise, seed)
    env = EnvConfig(image_size=candidates[0].policy.config.image_size, horizon=horizon)
    with WorldGym(wm_run, judge_run, tasks, episodes, env, workers, runner=runner) as gym:
        rows = gym.rows(candidates, progress=progress)
    result = {"rows": rows, **correlation([r["imagined"] for r in rows], [r["real"] for r in rows]),
              "settings": {"policy": str(policy_run), "noise": [json_noise(level) for level in noise],
                           "wm": str(wm_run), "judge": str(judge_run), "tasks": ",".join(gym.tasks),
                           "episodes": episodes, "horizon": horizon, "workers": workers, "seed": seed},
              "seconds": time.perf_counter() - began}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "worldgym.json", result)
    plot_worldgym_rows(rows, result["pearson"], result["spearman"], out / "worldgym.png")
    return result


def format_rows(result: dict) -> str:
    """The rows and correlations as aligned text (success in %, 95% intervals)."""
    width = max([len(row["policy"]) for row in result["rows"]] + [6])
    lines = [f"{'policy':<{width}}  imagined  95% CI        real    95% CI        episodes"]
    for row in result["rows"]:
        (il, ih), (rl, rh) = row["imagined_ci"], row["real_ci"]
        lines.append(f"{row['policy']:<{width}}  {row['imagined']:>7.0%}  [{il:>4.0%}, {ih:>4.0%}]  {row['real']:>6.0%}  "
                     f"[{rl:>4.0%}, {rh:>4.0%}]  {row['imagined_episodes']:>8}")
    fmt = lambda value: "undefined" if value is None else f"{value:.2f}"
    lines.append(f"Pearson r = {fmt(result['pearson'])}, Spearman = {fmt(result['spearman'])} "
                 f"over {len(result['rows'])} policies")
    return "\n".join(lines)
