"""Settings of the headline experiment, and its presets (debug / demo / full).

One frozen dataclass holds the whole pipeline: each stage's own settings (collection, SFT, world
model, judge, RL) and the experiment's protocol (which arms, how many evaluation episodes). Every
RL arm shares one `RLConfig`, so the arms differ only in where they practise and how they are
rewarded, never in their step budget.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

from gymnast.config import CameraNames, CommaFloats, EnvConfig
from gymnast.data.collect import CollectConfig
from gymnast.envs.instructions import read_sentences
from gymnast.envs.tasks import resolve_tasks
from gymnast.envs.workers import parse_runner
from gymnast.policy.sft import SFT_PRESETS, SFTConfig
from gymnast.reward.judges.train import JUDGE_PRESETS, JudgeTrainConfig
from gymnast.rl.config import RL_PRESETS, RLConfig
from gymnast.world_model.embedded import EmbeddedWorldModelConfig
from gymnast.world_model.train import WM_PRESETS, WorldModelTrainConfig
from gymnast.world_model.train_state import StateTrainConfig


@dataclass(frozen=True)
class IterSFTConfig:
    """Iter-SFT: SFT again on the SFT policy's judged-successful imagined rollouts."""

    group_size: int = 2
    """Imagined rollouts per dataset scene (at the RL rollout temperature)."""
    steps: int = 400
    """Fine-tuning steps from the SFT policy, half of every batch from the demonstrations."""
    lr: float = 1e-4
    """Peak learning rate of the fine-tuning."""


@dataclass(frozen=True)
class DynaArmConfig:
    """The Dyna arm: the RL arms' step budget split into rounds; between rounds, a few real rollouts
    of the current policy, on which the world model and the judge are fine-tuned."""

    rounds: int = 2
    """Rounds of imagined RL; each takes ``rl.steps / rounds`` of the shared steps, and only the
    rounds before the last record real rollouts."""
    rollouts_per_task: int = 8
    """Real episodes of the current policy recorded per task after each round: the arm's only
    real interactions for training, counted."""
    wm_steps: int = 300
    """Fine-tuning steps of the world model per round."""
    judge_steps: int = 200
    """Fine-tuning steps of the judge per round."""

    def __post_init__(self) -> None:
        for name in ("rounds", "rollouts_per_task", "wm_steps", "judge_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"DynaArmConfig.{name} must be at least 1, got {getattr(self, name)}")


@dataclass(frozen=True)
class EqualBudgetConfig:
    """Equal real budgets (`gymnast.experiment.equal_budget`): the same few real rollouts per task
    spent on GRPO in the real world, on refitting the world model and the judge before practice in
    imagination, or on Iter-SFT of their real successes."""

    rollouts_per_task: int = 32
    """Real rollouts per task each arm may spend on training (0: the comparison is not run)."""
    first_seed: int = 200_000
    """Data seed of every task's first recorded rollout: scenes no other stage records."""
    wm_steps: int = 300
    """Fine-tuning steps of the world model on the recorded rollouts."""
    judge_steps: int = 200
    """Fine-tuning steps of the judge on them."""

    def __post_init__(self) -> None:
        for name in ("rollouts_per_task", "first_seed", "wm_steps", "judge_steps"):
            if getattr(self, name) < 0:
                raise ValueError(f"EqualBudgetConfig.{name} must be at least 0, got {getattr(self, name)}")
        if self.rollouts_per_task and min(self.wm_steps, self.judge_steps) < 1:
            raise ValueError("EqualBudgetConfig.wm_steps and judge_steps must be at least 1 when rollouts_per_task is set")


@dataclass(frozen=True)
class NewScenesConfig:
    """Test-time practice on new scenes (`gymnast.experiment.new_scenes`): the SFT policy practises
    in imagination from one new scene's first frame, rewarded by the judge, then acts on that scene
    in the real world; the shared `rl` recipe, on one scene at a time."""

    scenes_per_task: int = 2
    """New scenes (the first evaluation seeds) of each weak task, or of every task where the
    experiment has none of the weak ones (0: not run)."""
    steps: int = 8
    """RL steps on each scene."""
    starts_per_step: int = 4
    """GRPO groups a step, all from the one scene (each of ``rl.group_size`` rollouts)."""

    def __post_init__(self) -> None:
        if self.scenes_per_task < 0:
            raise ValueError(f"NewScenesConfig.scenes_per_task must be at least 0, got {self.scenes_per_task}")
        for name in ("steps", "starts_per_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"NewScenesConfig.{name} must be at least 1, got {getattr(self, name)}")


WEAK_TASKS = "reach-v3,push-v3,pick-place-v3,peg-insert-side-v3"
"""MT10's tasks where the SFT policy is weakest (10-24% real success, results/sft/)."""


@dataclass(frozen=True)
class ExperimentConfig:
    """The whole pipeline: data, models, the eight arms and how they are measured."""

    tasks: str = "mt10"
    """Tasks of every stage (names or sets, comma-separated)."""
    cameras: CameraNames = ("front", "gripper", "hand")
    """The views recorded, and seen side by side by the policy, the world model and the judges, the
    primary first. The fixed front camera, the one on the gripper and the front view zoomed on the
    hand: on the weak tasks (reach, push, pick-place, peg-insert-side) the same 10 demonstrations
    give SFT 34.0% [27.8, 40.8] against 31.0% with the first two and 16.0% with the front view alone,
    over MT10 69.4% against 69.6% and 60.8% (docs/policy.md, "Several cameras"); the three-camera
    headline's judge ranks the real replays of the weak tasks at +0.51 (results/headline_three). The
    third view costs about 1.5x the two's rendering and vision (`make demo`: 10.2 against 6.5 min on
    a 2-core AVX512-BF16 CPU)."""
    collect: CollectConfig = field(default_factory=lambda: CollectConfig(episodes_per_task=30))
    """Recording the dataset in the real world."""
    sft: SFTConfig = field(default_factory=lambda: SFT_PRESETS["full"])
    """The SFT policy every arm starts from."""
    world_model: WorldModelTrainConfig = field(default_factory=lambda: dataclasses.replace(
        WM_PRESETS["full"], future=35, model=EmbeddedWorldModelConfig(actions_per_frame=5)))
    """The world model the imagined arms practise in: one imagined frame per policy chunk of 5 actions,
    clips of 35 actions (7 imagined frames). On the two-camera dataset it trains in a third of the time
    of a frame per action (15.8 against 47.7 min) and imagines the signal stage's rollouts in a quarter
    (71 against 284 s), the judge scoring a fifth of the frames. With a judge trained on its own
    imagination, the two-camera headline's signal stage gave +0.36 [+0.17, +0.56] against the every-frame
    model's +0.23 [+0.00, +0.45] (results/world_model/chunks_cams), and a world-model RL step took about
    105 s, where the every-frame model's took 421 s, three times a software-simulator step."""
    judge: JudgeTrainConfig = field(default_factory=lambda: JUDGE_PRESETS["full"])
    """The learned judge (World-Gymnast's reward, and the WorldGym estimates)."""
    judge_rollouts: int = 40
    """Real rollouts per task of the SFT policy, sampled at `rl.temperature` on scenes no other stage
    records and played to the horizon past any success, that the judge learns from besides the
    dataset: the policy's own near misses, which scripted data does not show (0: none). Their real
    interactions are counted in summary.json (``judge_rollouts``). With 60 such rollouts per weak
    task, the judge's advantage correlation with real success on new rollouts of the weak tasks rose
    from +0.20 to +0.63 (results/judge/cameras/README.md)."""
    state_model: StateTrainConfig = field(default_factory=lambda: StateTrainConfig(steps=2000))
    """The grounded state model, whose reward head rewards the ``rl_wm_state`` arm (docs/world_model.md)."""
    rl: RLConfig = field(default_factory=lambda: RLConfig(
        steps=20, starts_per_step=20, group_size=8, max_rounds=2, lr=3e-5, kl_coef=0.1, freeze=("vision",),
        eval_every=10, eval_episodes=5, video_every=20, checkpoint_every=5))
    """Shared by every RL arm: step budget, batch, learning rate, anchors, learning-curve evaluations
    (``eval_episodes`` per task at each of them). The recipe under which RL in the real world beat
    SFT on MT10 with intervals apart (docs/rl.md, results/rl/scarce_mt10_real: 160 rollouts a step
    with dynamic sampling, the image encoder frozen, a KL anchor; 20 steps, as 10 were not enough);
    a video at the last step."""
    iter_sft: IterSFTConfig = field(default_factory=IterSFTConfig)
    """The Iter-SFT arm."""
    dyna: DynaArmConfig = field(default_factory=DynaArmConfig)
    """The Dyna arm (its RL settings are the shared `rl`)."""
    equal_budget: EqualBudgetConfig = field(default_factory=EqualBudgetConfig)
    """The equal-real-budget comparison (its RL settings are the shared `rl`)."""
    new_scenes: NewScenesConfig = field(default_factory=NewScenesConfig)
    """Test-time practice on new scenes of the weak tasks."""
    weak_tasks: str = WEAK_TASKS
    """Tasks whose pooled success summary.json reports per arm (``weak_tasks``), the ones RL should
    help most; those of them not in `tasks` are left out."""
    gap: str = "mild"
    """The software simulator's sim-to-real gap."""
    eval_episodes: int = 50
    """Real-world episodes per task for every arm's final evaluation (evaluation seeds)."""
    robustness_episodes: int = 10
    """Episodes per task under each perturbation (minor, major) and with held-out instructions."""
    sentences: Path | None = None
    """The language check's instructions: a file of ``task: sentence`` lines (your own wording,
    several per task allowed) in place of the held-out paraphrases. Every task needs one."""
    worldgym_episodes: int = 10
    """Imagined episodes per task for each policy's WorldGym estimate (and real ones for the
    policies that have no final evaluation)."""
    worldgym_noise: CommaFloats = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0)
    """WorldGym also rates the SFT policy with these action-noise stds (> 0; noise 0 is the SFT arm
    itself), so that the policies span most of the range of real success."""
    worldgym_random: bool = True
    """WorldGym also rates uniformly random actions (the floor of the noise ladder)."""
    signal_scenes: int = 4
    """Starts (GRPO groups) per task of the ``signal`` stage: the SFT policy sampled in imagination
    from the held-out episodes' keyframes as `rl.keyframes` draws them, for `rl.horizon` actions, and
    replayed in the real world (`gymnast rl-signal`)."""
    signal_weak_scenes: int = 12
    """Starts per weak task (`weak_tasks`) of the signal stages, in place of `signal_scenes`: there
    the policy's replayed actions mostly all fail or all succeed, so few groups rank anything (the
    two-camera headline's 4 starts a task gave 16 groups, half of them ranking nothing, and the judge's
    real-video figure +0.12 [0.00, +0.31]; 12 starts a task, 48 groups, measured the judges of
    results/fidelity/signal_cams to within +-0.08 to +-0.17)."""
    workers: int = 2
    """Simulator processes."""
    runner: str = "local"
    """Where the simulator processes of collection, RL and evaluation run: local, ray or
    ray:ADDRESS (see `gymnast eval --help`)."""
    seed: int = 0
    """Seed of every stage."""
    device: str = "auto"
    """Where the models train, imagine and judge (train-wm, sft, train-judge, eval-wm, rl): auto
    (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N. The real world's workers keep
    their policies on the CPU, where the simulator is the cost."""

    def __post_init__(self) -> None:
        for name in ("eval_episodes", "robustness_episodes", "worldgym_episodes", "signal_scenes", "signal_weak_scenes",
                     "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"ExperimentConfig.{name} must be at least 1, got {getattr(self, name)}")
        if self.judge_rollouts < 0:
            raise ValueError(f"ExperimentConfig.judge_rollouts must be at least 0, got {self.judge_rollouts}")
        if self.sentences is not None:  # checked now, not hours later at the language check
            missing = [task for task in resolve_tasks(self.tasks) if task not in read_sentences(self.sentences)]
            if missing:
                raise ValueError(f"{self.sentences} has no sentence for {', '.join(missing)}")
        if not all(0 < noise < math.inf for noise in self.worldgym_noise):
            raise ValueError(f"ExperimentConfig.worldgym_noise must be finite and positive (noise 0 is the SFT arm, "
                             f"random actions are worldgym_random), got {self.worldgym_noise}")
        if self.weak_tasks:
            resolve_tasks(self.weak_tasks)  # an unknown name is said now
        budget = self.equal_budget.rollouts_per_task * len(resolve_tasks(self.tasks))
        if self.equal_budget.rollouts_per_task and budget < self.rl.group_size:
            raise ValueError(f"ExperimentConfig.equal_budget.rollouts_per_task ({self.equal_budget.rollouts_per_task}) "
                             f"x {len(resolve_tasks(self.tasks))} tasks is {budget} real rollouts, fewer than one GRPO "
                             f"group of rl.group_size ({self.rl.group_size})")
        if self.rl.steps % self.dyna.rounds:
            raise ValueError(f"ExperimentConfig.dyna.rounds ({self.dyna.rounds}) must divide rl.steps "
                             f"({self.rl.steps}): Dyna spends the RL arms' step budget in equal rounds")
        parse_runner(self.runner)
        EnvConfig(cameras=self.cameras)  # an unknown or repeated name is said now

    @property
    def weak_task_list(self) -> list[str]:
        """The weak tasks this experiment has, in `tasks`' order."""
        weak = set(resolve_tasks(self.weak_tasks)) if self.weak_tasks else set()
        return [task for task in resolve_tasks(self.tasks) if task in weak]

    @property
    def new_scene_tasks(self) -> list[str]:
        """The tasks whose new scenes test-time practice visits: the weak ones, or every task where
        the experiment has none of them."""
        return self.weak_task_list or resolve_tasks(self.tasks)

    def resolved(self) -> ExperimentConfig:
        """Every stage told the experiment's tasks, cameras, workers, runner, device and seed (one place
        to set them)."""
        cameras = () if self.cameras == EnvConfig().cameras else self.cameras  # one view: as the stages read it alone
        return dataclasses.replace(
            self,
            collect=dataclasses.replace(self.collect, tasks=self.tasks, workers=self.workers, runner=self.runner,
                                        env=dataclasses.replace(self.collect.env, cameras=self.cameras)),
            sft=dataclasses.replace(self.sft, tasks="", seed=self.seed, device=self.device, cameras=cameras),
            world_model=dataclasses.replace(self.world_model, device=self.device, cameras=cameras),
            judge=dataclasses.replace(self.judge, device=self.device, cameras=cameras),
            state_model=dataclasses.replace(self.state_model, seed=self.seed),
            rl=dataclasses.replace(self.rl, tasks=self.tasks, gap=self.gap, workers=self.workers, runner=self.runner,
                                   seed=self.seed, device=self.device),
        )


def _debug() -> ExperimentConfig:
    rl = dataclasses.replace(RL_PRESETS["debug"], horizon=40, eval_every=1, eval_episodes=1, watch_every=2, kl_coef=0.1,
                             freeze=("vision",))
    return ExperimentConfig(
        tasks="reach-v3",
        # Two views: the tests' experiments run several cameras end to end at two thirds of three's cost.
        cameras=("front", "gripper"),
        collect=CollectConfig(episodes_per_task=4, failure_fraction=0.25),
        sft=dataclasses.replace(SFT_PRESETS["debug"], demos_per_task=2),
        # One frame per chunk of 5 actions, as the demo's: every stage is tested on the demo's kind of model.
        world_model=dataclasses.replace(WM_PRESETS["debug"], future=5, model=dataclasses.replace(
            WM_PRESETS["debug"].model, actions_per_frame=5)),
        judge=JUDGE_PRESETS["debug"],
        judge_rollouts=1,
        state_model=StateTrainConfig(steps=20, batch_size=16, unroll=4, checkpoint_every=20),
        rl=rl,
        iter_sft=IterSFTConfig(group_size=2, steps=2),
        dyna=DynaArmConfig(rounds=2, rollouts_per_task=1, wm_steps=2, judge_steps=2),
        equal_budget=EqualBudgetConfig(rollouts_per_task=2, wm_steps=2, judge_steps=2),
        new_scenes=NewScenesConfig(scenes_per_task=1, steps=1, starts_per_step=1),
        eval_episodes=2,
        robustness_episodes=1,
        worldgym_episodes=1,
        worldgym_noise=(0.5,),
        signal_scenes=1,
        signal_weak_scenes=1,
    )


def _demo() -> ExperimentConfig:
    # Sized to finish within 15 minutes on 2 CPU cores, set-up included: every stage runs, on two
    # tasks and the experiment's three cameras, with models far smaller than the full ones (the
    # numbers show the pipeline, not the method). Two cameras cost most stages 1.5-2x one camera's
    # time (10.3 -> about 16 min on an AVX2 CPU), won back by the trims marked "two cameras" below (the
    # values before them in brackets); the third view costs 1.6x again (6.5 -> 10.2 min on an
    # AVX512-BF16 CPU, docs/experiment.md "make demo's time"). Three views took 16.7 min on a 2-core
    # AVX2 CPU, won back by the trims marked "three cameras" (the values before them in brackets).
    return ExperimentConfig(
        tasks="drawer-open-v3,reach-v3",
        collect=CollectConfig(episodes_per_task=8),
        # Two cameras: 250 steps (300) of 32 samples (64), the demo's largest cost on a CPU without
        # native bfloat16: SFT took 153 s of its 16.8 min there at 64, 88 s of 15.6 at 32; Iter-SFT's too.
        # Not trimmed for three cameras: at 150 steps the policy failed every episode of both tasks (0 of 8
        # each), and so did every arm from it; at 250 it opens the drawer.
        sft=dataclasses.replace(SFT_PRESETS["demo"], demos_per_task=6, steps=250, batch_size=32, checkpoint_every=125),
        # One imagined frame per chunk of the policy's 5 actions (docs/world_model.md): a training
        # step 3.4x and imagination 2.1x cheaper, ranking as well as a frame per action from scratch;
        # clips of 20 future actions (4 imagined frames), not 32. Three cameras: 150 steps (250), and
        # the judge 100 (150).
        world_model=dataclasses.replace(WM_PRESETS["demo"], steps=150, future=20, video_every=150, validate_every=75,
                                        model=EmbeddedWorldModelConfig(actions_per_frame=5)),
        judge=dataclasses.replace(JUDGE_PRESETS["demo"], steps=100),
        judge_rollouts=1,
        state_model=StateTrainConfig(steps=200, batch_size=64, checkpoint_every=200),
        # Most of an arm's minutes here were its learning curve's two real evaluations, not its two
        # steps: one episode per task each (the arms' final evaluations below are the comparison).
        # Two cameras: 2 starts a step (3), 50 Iter-SFT steps (100), 10 refitting steps (20), one
        # episode per task for robustness, WorldGym and imagination (2), one signal scene (2).
        # The full preset's anchors, without refills of dropped groups (each would add a round of
        # rollouts to the 15 minutes).
        rl=RLConfig(steps=2, starts_per_step=2, group_size=4, max_rounds=1, lr=3e-5, kl_coef=0.1, freeze=("vision",),
                    eval_every=2, eval_episodes=1, watch_every=2, watch_rollouts=4, video_every=2, checkpoint_every=2),
        # Three cameras: 30 Iter-SFT steps (50), Dyna's 1 real rollout per task between rounds (2), 4
        # evaluation episodes per task (6).
        iter_sft=IterSFTConfig(group_size=2, steps=30),
        dyna=DynaArmConfig(rounds=2, rollouts_per_task=1, wm_steps=10, judge_steps=10),
        equal_budget=EqualBudgetConfig(rollouts_per_task=2, wm_steps=10, judge_steps=10),
        # Practice on new scenes is left out: about a minute a scene would overrun the 15 minutes.
        new_scenes=NewScenesConfig(scenes_per_task=0),
        eval_episodes=4,
        robustness_episodes=1,
        worldgym_episodes=1,
        signal_scenes=1,
        signal_weak_scenes=1,
        # Each rung of the noise ladder costs about a minute here: left out to keep the 15 minutes.
        worldgym_noise=(),
        worldgym_random=False,
    )


def _gpu() -> ExperimentConfig:
    # The full experiment at the papers' budget for one GPU: the gpu presets' world model, judge and
    # RL (400 steps of 256 rollouts). The imagined arms are GPU work; the real-world and simulator
    # arms, the evaluations and the data stay on the CPU's simulator processes (docs/gpu.md).
    return ExperimentConfig(
        collect=CollectConfig(episodes_per_task=50),
        world_model=WM_PRESETS["gpu"],
        judge=JUDGE_PRESETS["gpu"],
        judge_rollouts=128,
        # The full preset's recipe (success reward, dynamic sampling, frozen encoder, KL anchor) at that budget.
        rl=dataclasses.replace(RL_PRESETS["gpu"], eval_episodes=10, max_rounds=2, kl_coef=0.1, freeze=("vision",)),
        dyna=DynaArmConfig(rounds=4, rollouts_per_task=16, wm_steps=1000, judge_steps=500),
        # WMPO's budget: 128 real rollouts per task.
        equal_budget=EqualBudgetConfig(rollouts_per_task=128, wm_steps=1000, judge_steps=500),
        new_scenes=NewScenesConfig(scenes_per_task=5, steps=16, starts_per_step=8),
        workers=16,
    )


EXPERIMENT_PRESETS: dict[str, ExperimentConfig] = {"debug": _debug(), "demo": _demo(), "full": ExperimentConfig(),
                                                   "gpu": _gpu()}
