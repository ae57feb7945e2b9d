"""The eight arms of the headline comparison: what each one trains, where and with which reward.

Every arm starts from the same SFT policy; the RL arms share one step budget and one `RLConfig`.
The simulators (software and real) start each group from a fresh scene, which only a simulator
can set up; the world-model arms start from the dataset's real frames (its first frames, or
keyframes as `rl.keyframes` draws them), as a world model only continues real frames (and the
verified reward needs the dataset's expert actions). Their rewards: the judge (World-Gymnast's),
the verified comparison (VLA-RFT's) and the state model's reward head (grounded). Dyna
splits the same steps into rounds, between which it records a few counted real rollouts and
fine-tunes the world model and the judge on them (`gymnast.experiment.dyna`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from gymnast.envs.kinds import IMAGINED, REAL, SIM, EnvKind
from gymnast.experiment.config import ExperimentConfig
from gymnast.experiment.dyna import DynaConfig, DynaInputs
from gymnast.reward.spec import RewardKind, RewardSpec
from gymnast.rl.config import RLConfig, RLRun


@dataclass(frozen=True)
class Arm:
    """One row of the table.

    Attributes:
        name: key in summary.json and the stage names.
        title: what the report calls it.
        env: where it practises (None: no practice, or imitation only).
        reward: its reward's kind (``judge``, ``state`` and ``verified`` are bound to the experiment's own models).
        dyna: practises in rounds with real rollouts and fine-tuning between them (`dyna_setup`).
    """

    name: str
    title: str
    env: EnvKind | None = None
    reward: RewardKind | None = None
    dyna: bool = False

    @property
    def is_rl(self) -> bool:
        return self.env is not None


# The simulators' arms are rewarded by success (binary), as the recipe that learns in the real world
# is (docs/rl.md): GRPO on the dense reward lost ground on MT10 (60.8% -> 56.2%, results/headline_one_camera).
ARMS = (
    Arm("sft", "SFT"),
    Arm("iter_sft", "Iter-SFT (judged imagined successes + demos)"),
    Arm("rl_sim", "RL in the software simulator (success reward)", SIM, "sim"),
    Arm("rl_wm_judge", "RL in the world model, judge (World-Gymnast)", IMAGINED, "judge"),
    Arm("rl_wm_verified", "RL in the world model, verified (VLA-RFT)", IMAGINED, "verified"),
    Arm("rl_wm_state", "RL in the world model, state model's reward (grounded)", IMAGINED, "state"),
    Arm("rl_real", "RL in the real world (success reward; upper bound)", REAL, "sim"),
    Arm("dyna", "Dyna: world-model RL (judge) with a few real rollouts (World-Gymnast)", IMAGINED, "judge", dyna=True),
)
ARM_NAMES = tuple(arm.name for arm in ARMS)
WM_ARMS = ("rl_wm_judge", "rl_wm_verified", "rl_wm_state", "dyna")
"""The arms that practise in the world model; `rl_wm_judge` is World-Gymnast's without real
interactions, the one the goals over SFT and the software simulator are about."""
ROBUSTNESS_ARMS = ("sft", "rl_wm_judge", "rl_wm_verified")
"""Policies measured under perturbations and with held-out instructions."""
PERTURBATIONS = ("minor", "major")
"""VLA-RFT's robustness levels (2.5 cm and 5 cm; `gymnast.envs.perturb`)."""


def arm(name: str) -> Arm:
    for candidate in ARMS:
        if candidate.name == name:
            return candidate
    raise KeyError(f"no arm {name!r}; arms are {list(ARM_NAMES)}")


def rl_setup(spec: Arm, config: ExperimentConfig, sft: Path, wm: Path, judge: Path, data: Path,
             state: Path | None = None) -> tuple[RLRun, RLConfig]:
    """The `gymnast rl` run an RL arm is: its env and reward on the experiment's models (`state`:
    the state-model run, for the arm its reward head rewards)."""
    models = {"judge": judge, "state": state}
    reward = RewardSpec(spec.reward, run=models[spec.reward]) if spec.reward in models else RewardSpec(spec.reward)
    imagined = spec.env.imagined
    run = RLRun(str(sft), spec.env, reward, wm=str(wm) if imagined else None, data=str(data))
    rl = dataclasses.replace(config.rl, fresh_scenes=not imagined,
                             # the watch replays imagined actions in the real world; elsewhere it has nothing to check
                             watch_every=config.rl.watch_every if imagined else 0)
    return run, rl


def dyna_setup(config: ExperimentConfig, sft: Path, wm: Path, judge: Path, data: Path) -> tuple[DynaConfig, DynaInputs]:
    """The `gymnast dyna` run the Dyna arm is: the RL arms' settings and step budget, split into
    `config.dyna.rounds` rounds, each measured in the real world like the other arms' learning
    curves (``rl.eval_episodes`` per task); the reward-hacking watch, if on, ends every round."""
    rounds = config.dyna.rounds
    steps = config.rl.steps // rounds
    rl = dataclasses.replace(config.rl, steps=steps, real_eval=False, eval_every=0,
                             watch_every=steps if config.rl.watch_every else 0)
    settings = DynaConfig(rounds=rounds, real_rl=False, rollouts_per_task=config.dyna.rollouts_per_task,
                          wm_steps=config.dyna.wm_steps, judge_steps=config.dyna.judge_steps,
                          eval_episodes=config.rl.eval_episodes, workers=config.workers, runner=config.runner, rl=rl)
    return settings, DynaInputs(policy=sft, wm=wm, judge=judge, data=data)
