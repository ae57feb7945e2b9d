"""The settings of an RL run: what it trains with (`RLRun`) and how (`RLConfig`, with presets).

They live apart from the loop so that the CLI, the experiment and the loop's helpers read them
without importing the loop itself.
"""

from __future__ import annotations

from dataclasses import dataclass

from gymnast.data.keyframes import KeyframeConfig
from pathlib import Path
from typing import Any

from gymnast.envs.kinds import EnvKind, env_kind
from gymnast.envs.tasks import parse_scenes
from gymnast.envs.workers import parse_runner
from gymnast.reward.spec import RewardSpec
from gymnast.utils.settings import saved_settings
from gymnast.utils.trackers import TrackerNames, check_trackers


CREDITS = ("rollout", "reward-to-go", "critic")
"""How a rollout's reward is shared among its policy calls (`RLConfig.credit`)."""

LEARN_ON = ("own", "replays", "both")
"""The frames the update reads the policy's actions on (`RLConfig.learn_on`)."""


@dataclass(frozen=True)
class RLConfig:
    """GRPO settings. Defaults follow World-Gymnast except where docs/rl.md says why not."""

    steps: int = 100
    """RL steps (one policy update each)."""
    tasks: str = "mt10"
    """Tasks whose start states are trained on (task names or sets, comma-separated). Left out of
    `gymnast rl`'s command line: the preset's tasks that the dataset has start states for, or else
    as many of the dataset's own."""
    fresh_scenes: bool = False
    """Start each group from a new scene (a random data seed) instead of the dataset's scenes. A
    simulator sets the scene up; a world model continues its first frame, rendered by a reset of
    the real world: no action is taken, and such frames are counted apart (``reset_frames``)."""
    scenes: str | None = None
    """Test-time practice: train and evaluate on these scenes only, ``task:seed`` comma-separated
    (say, the scene the policy is about to face: ``reach-v3:1000000``). Their first frames are
    rendered by a reset (counted in ``reset_frames``); each is evaluated once, greedily. Replaces
    --tasks."""
    instruction: str | None = None
    """Give the policy (and the judge) this sentence in every rollout and evaluation instead of the
    task's paraphrases: practise on your own wording. One task only."""
    keyframes: str = "first"
    """Where in the dataset's episodes practice starts: their first frames (first), or keyframes
    anywhere in them (uniform, near_success: the frames before the first success, failures: in
    episodes that failed; `gymnast.data.keyframes`), each imagined for `horizon` actions: short
    segments from real frames. Not with --fresh-scenes or --scenes."""
    keyframes_per_episode: int = 4
    """Keyframes drawn from each episode for the pool of starts (with --keyframes other than first)."""
    starts_per_step: int = 4
    """Start states B per step (groups)."""
    group_size: int = 8
    """Rollouts G per start state."""
    temperature: float = 1.0
    """Sampling temperature of the rollouts (the log-probabilities use the same). World-Gymnast's 1.6
    halves our policy's success (docs/rl.md), so we sample at 1.0."""
    horizon: int = 150
    """Actions per training rollout: the task's whole episode, or a segment from a keyframe (--keyframes)."""
    eval_horizon: int = 0
    """Actions per evaluation episode (evaluation starts at first frames); 0: `horizon`. With
    segments from keyframes, set the task's horizon (150, as `gymnast eval` runs episodes)."""
    clip_low: float = 0.2
    """PPO ratio clip below 1."""
    clip_high: float = 0.28
    """PPO ratio clip above 1 (clip-higher)."""
    kl_coef: float = 0.0
    """Weight of the k3 KL to the starting policy (0: no reference model is kept). In imagination it
    is the third lever against exploiting the world model: it anchors the policy to the SFT policy
    whose behaviour the world model was trained on."""
    disagreement_stop: float = 0.0
    """Imagined env with a world-model ensemble: end a rollout before its first frame whose
    ensemble disagreement exceeds this; it is judged on its video up to there (0: never stop)."""
    disagreement_penalty: float = 0.0
    """Imagined env with a world-model ensemble: subtract this times the rollout's mean ensemble
    disagreement from its reward before group normalisation, as MOPO does (0: no penalty)."""
    entropy_coef: float = 0.0
    """Weight of the entropy bonus."""
    imitation_coef: float = 0.0
    """Weight of an imitation loss on the dataset's expert demonstrations of the run's tasks, added
    to every update (VLA-RFT's auxiliary flow-matching loss for a flow policy, the token
    cross-entropy for the tokenized one); 0: none."""
    imitation_kl_gate: float = 0.0
    """Add the imitation loss only while the update's KL to the starting policy exceeds this
    (0: always). A starting policy is kept for it, as for --kl-coef."""
    imitation_batch: int = 64
    """Demonstration samples per imitation loss."""
    credit: str = "rollout"
    """How a rollout's reward is shared among its policy calls: rollout (GRPO: every call gets the
    rollout's advantage) or reward-to-go (each call gets the rewards of the actions from it on,
    against its group's at the same call; needs a reward that scores every action: sim-dense,
    state:RUN or a progress judge) or critic (the same rewards against a learned critic's values of
    what each call saw, with generalised advantage estimation: PPO's baseline; `gymnast.rl.critic`)."""
    critic_lr: float = 1e-4
    """Learning rate of the critic (--credit critic)."""
    critic_epochs: int = 2
    """Passes of the critic over each step's policy calls (--credit critic)."""
    gae_lambda: float = 0.95
    """GAE's lambda over policy calls (--credit critic): 1 the return minus the value, 0 one call's
    temporal difference."""
    learn_on: str = "own"
    """The frames the update holds the policy's actions to: own (the frames it acted on), replays
    (the frames of the same actions replayed where the reward saw them, --reward-sees) or both. With
    --env imagined --reward-sees real the policy acts on imagined frames and learns on the real frames
    its actions led to: what it learns is anchored on what reality shows it; with both, its proposals
    on the imagined frames move with it (`gymnast.rl.reanchor`)."""
    importance_cap: float = 0.0
    """With --learn-on replays or both: weight each token's advantage on the replay's frame by the
    probability the policy gives it there against the one it was sampled with, capped at this
    (truncated importance sampling: an action the policy would rarely take on the real frame teaches
    little there); 0: no weighting."""
    anchor_every: int = 0
    """With --env anchored: actions between the real frames the policy is shown (a multiple of its
    chunk); in between it sees the world model's frames, imagined from the last real one. The
    rollout is real; the sight is imagined, never more than this less one chunk past a real frame
    (`gymnast.envs.anchored`)."""
    normalize_std: bool = True
    """Divide group advantages by the group's standard deviation."""
    keep_low: float = 0.1
    """Dynamic sampling: keep groups whose success rate is at least this (binary rewards)."""
    keep_high: float = 0.9
    """... and at most this."""
    max_rounds: int = 3
    """Rollout rounds per step at most while refilling dropped groups."""
    freeze: tuple[str, ...] = ()
    """Parts of the policy the update leaves as they are, by parameter-name prefix (e.g. ``vision``:
    the embedded policies' image encoder, about half of their weights; VLA-RFT trains only its
    action head): RL then changes how the policy acts on what it sees, not how it sees. Empty: every
    parameter learns."""
    remember_vision: bool = True
    """With the image encoder frozen, encode each observation once per step (when the policy samples)
    and reuse its tokens in the update and the reference's KL (`gymnast.policy.frozen_vision`; the
    same tokens, so the same results). False: encode every time, as before."""
    lr: float = 1e-5
    """Peak learning rate (AdamW; linear warm-up, then constant)."""
    warmup_steps: int = 5
    """Linear warm-up steps."""
    max_grad_norm: float = 1.0
    """Gradient-norm clip."""
    minibatches: int = 1
    """Optimizer steps per RL step (1: on-policy, the ratio is 1 and clipping is inert)."""
    micro_batch: int = 256
    """Policy calls per forward/backward pass (gradients accumulate; results do not depend on it).
    Fewer keep fewer activations for the backward pass, for more time: with three cameras 64 took
    about 1 GiB less than 256 and twice the update's time (BENCHMARKS.md)."""
    gap: str = "mild"
    """Sim-to-real gap of the software simulator (``--env sim``)."""
    workers: int = 2
    """Simulator processes (sim/real rollouts, evaluation, the watch)."""
    device: str = "auto"
    """Where the policy, the world model and the judge run: auto (CUDA when torch sees a GPU), cpu,
    cuda or cuda:N. Environments and rollout records stay on the host."""
    runner: str = "local"
    """Where the worker processes run: local (spawned on this machine), ray (Ray actors on a Ray
    started here, or on the cluster in RAY_ADDRESS) or ray:ADDRESS (a Ray cluster, e.g. ray:auto or
    ray:ray://head:10001)."""
    eval_every: int = 25
    """Steps between evaluations (also at the start and the end); 0 evaluates only at both ends."""
    eval_episodes: int = 10
    """Evaluation episodes per task, from the evaluation seeds."""
    real_eval: bool = True
    """Also evaluate in the real world when training elsewhere (its interactions are counted)."""
    truth_groups: int = 0
    """Groups of each step's first round whose actions are replayed in the real world to log how
    often the reward agrees with the real outcome (``reward/agreement``, ``reward/truth_signal``),
    counted apart as ``truth_real_interactions``. Where the rollouts or the reward's replays are
    real, every rollout's outcome is known at no cost and logged whatever this is. 0: none."""
    watch_every: int = 10
    """Steps between reward-hacking checks (0: never): imagined actions replayed in the real world."""
    watch_rollouts: int = 16
    """Rollouts replayed per check."""
    video_every: int = 25
    """Steps between rollout videos (RUN/videos/): what the reward read, each chunk's last frame alone
    where it reads no others."""
    checkpoint_every: int = 10
    """Steps between checkpoints."""
    tracker: TrackerNames = ("tensorboard",)
    """Where the run logs besides RUN/metrics.jsonl: none, or any of tensorboard (RUN/tensorboard/)
    and wandb, comma-separated (gymnast.utils.trackers)."""
    seed: int = 0
    """Seed of start sampling, rollouts and environment resets."""

    @property
    def evaluation_horizon(self) -> int:
        """Actions per evaluation episode."""
        return self.eval_horizon or self.horizon

    @staticmethod
    def upgrade_saved(saved: dict[str, Any]) -> dict[str, Any]:
        """Settings saved by an earlier version under today's names: before `tracker`, a run said
        ``tensorboard: true`` (the default) or ``false``."""
        saved = dict(saved)
        if "tensorboard" in saved:
            saved["tracker"] = ["tensorboard"] if saved.pop("tensorboard") else []
        return saved

    def __post_init__(self) -> None:
        object.__setattr__(self, "tracker", check_trackers(self.tracker))  # a list when read back from JSON
        for name in ("steps", "starts_per_step", "group_size", "horizon", "max_rounds", "minibatches", "micro_batch",
                     "workers", "eval_episodes", "checkpoint_every", "video_every", "imitation_batch", "critic_epochs"):
            if getattr(self, name) < 1:
                raise ValueError(f"RLConfig.{name} must be at least 1, got {getattr(self, name)}")
        if self.group_size < 2:
            raise ValueError(f"RLConfig.group_size must be at least 2 (advantages compare a group), got {self.group_size}")
        if self.temperature <= 0:
            raise ValueError(f"RLConfig.temperature must be positive, got {self.temperature}")
        for name in ("kl_coef", "disagreement_stop", "disagreement_penalty", "imitation_coef", "imitation_kl_gate",
                     "anchor_every"):
            if getattr(self, name) < 0:
                raise ValueError(f"RLConfig.{name} must be at least 0, got {getattr(self, name)}")
        if self.scenes is not None:
            if self.fresh_scenes:
                raise ValueError("RLConfig: --scenes names the scenes to practise on; --fresh-scenes draws new ones; "
                                 "give one of them")
            parse_scenes(self.scenes)
        if self.eval_horizon < 0:
            raise ValueError(f"RLConfig.eval_horizon must be at least 0, got {self.eval_horizon}")
        KeyframeConfig(sampling=self.keyframes, horizon=self.horizon, per_episode=self.keyframes_per_episode)
        if self.keyframes != "first" and (self.fresh_scenes or self.scenes is not None):
            raise ValueError(f"RLConfig: --keyframes {self.keyframes} draws starts from the dataset's episodes; "
                             "--fresh-scenes and --scenes start from first frames; give one of them")
        if self.instruction is not None and not self.instruction.strip():
            raise ValueError("RLConfig.instruction is empty; give a sentence or leave it out")
        if self.credit not in CREDITS:
            raise ValueError(f"RLConfig.credit must be one of {', '.join(CREDITS)}, got {self.credit!r}")
        if self.importance_cap < 0:
            raise ValueError(f"RLConfig.importance_cap must be at least 0, got {self.importance_cap}")
        if self.importance_cap > 0 and self.learn_on == "own":
            raise ValueError("RLConfig.importance_cap weighs actions held to their replays' frames: give "
                             "--learn-on replays or both")
        if self.learn_on not in LEARN_ON:
            raise ValueError(f"RLConfig.learn_on must be one of {', '.join(LEARN_ON)}, got {self.learn_on!r}")
        if self.critic_lr <= 0 or not 0 <= self.gae_lambda <= 1:
            raise ValueError(f"RLConfig: need critic_lr > 0 and 0 <= gae_lambda <= 1, got {self.critic_lr} and "
                             f"{self.gae_lambda}")
        if not 0 <= self.keep_low <= self.keep_high <= 1:
            raise ValueError(f"need 0 <= keep_low <= keep_high <= 1, got {self.keep_low}, {self.keep_high}")
        parse_runner(self.runner)


RL_PRESETS: dict[str, RLConfig] = {
    "debug": RLConfig(steps=2, tasks="reach-v3", starts_per_step=2, group_size=2, horizon=10, max_rounds=1,
                      warmup_steps=1, micro_batch=3, workers=1, eval_episodes=1, watch_every=1, watch_rollouts=2,
                      video_every=1, checkpoint_every=1, keep_low=0.0, keep_high=1.0),
    "demo": RLConfig(steps=30, tasks="reach-v3,push-v3", eval_every=10, video_every=10),
    "full": RLConfig(),
    # Paper scale for one GPU: 400 steps of 256 rollouts (VLA-RFT's step count, World-Gymnast's
    # batch), a larger micro-batch to fill the device. In imagination a step is estimated at 0.5-2 s
    # on an H100 (docs/gpu.md); the real world and the simulator stay CPU-bound.
    "gpu": RLConfig(steps=400, starts_per_step=32, group_size=8, lr=3e-5, micro_batch=2048, eval_every=100,
                    video_every=100, watch_every=50, checkpoint_every=50),
}


@dataclass(frozen=True)
class RLRun:
    """What one run trains with: the policy's run, the env and the reward (parsed), and the world
    model's and dataset's runs (and the state model that imagines the robot's state beside the
    world model, for a policy that reads one)."""

    policy: str
    env: EnvKind
    reward: RewardSpec
    wm: str | None = None
    data: str | None = None
    robot_state: str | None = None
    reward_sees: EnvKind | None = None
    """The world the reward's video comes from: None for the rollouts' own; else the same actions
    from the same starts are replayed there (`gymnast.rl.sight.RewardSight`): ``real`` gives a
    simulator's verdict on imagined actions, ``imagined`` the world model's re-imagining of real ones."""

    reward_wm: str | None = None
    """With ``reward_sees`` imagined: the world model the reward's replays are imagined in, when not
    ``wm`` (a model that did not show the policy the frames it acted on)."""

    def to_json(self) -> dict[str, Any]:
        """The run as RUN/config.json keeps it: the env and the reward as the command line names them."""
        return {"policy": self.policy, "env": self.env.name, "reward": str(self.reward), "wm": self.wm,
                "data": self.data, "robot_state": self.robot_state,
                "reward_sees": self.reward_sees.name if self.reward_sees else OWN_SIGHT, "reward_wm": self.reward_wm}

    @classmethod
    def from_json(cls, saved: dict[str, Any]) -> RLRun:
        sees = saved.get("reward_sees", OWN_SIGHT)  # runs saved before the choice existed saw their own
        return cls(**saved | {"env": env_kind(saved["env"]), "reward": RewardSpec.parse(saved["reward"]),
                              "reward_sees": reward_sight(sees)})


OWN_SIGHT = "own"
"""`--reward-sees own`: the reward reads the rollouts' own video."""


def reward_sight(name: str) -> EnvKind | None:
    """The world `--reward-sees NAME` replays actions in: None for ``own``, else the env kind."""
    return None if name == OWN_SIGHT else env_kind(name)


def saved_rl_settings(run: Path) -> tuple[RLRun, RLConfig]:
    """The run and settings an RL run was started with (RUN/config.json), for ``--resume``."""
    return RLRun.from_json(saved_settings(run, "run")), RLConfig(**RLConfig.upgrade_saved(saved_settings(run, "rl")))
