"""`gymnast` subcommands that train and measure learned parts: the world model, the judge and RL.

Each is a thin call into the library; `gymnast.cli` gathers them with the others.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated, Literal

import tyro

from gymnast.cli_settings import flags_of, resolve, saved_inputs
from gymnast.config import CameraNames, CommaFloats
from gymnast.data.frames import Fit
from gymnast.data.lerobot_format import FeatureKeys
from gymnast.experiment.worldgym import DEFAULT_NOISE
from gymnast.envs.kinds import EnvName, env_kind
from gymnast.reward.chat_server import ChatLimits
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RL_PRESETS, RLConfig

Preset = Literal["debug", "demo", "full"]
GPUPreset = Literal["debug", "demo", "full", "gpu"]
"""The presets of the commands that also have one sized for a GPU (docs/gpu.md)."""
RLFlags = flags_of(RLConfig, RL_PRESETS)
KeyFlags = flags_of(FeatureKeys, {"LeRobot": FeatureKeys()})
"""--action-key and --state-key: which dataset features are the actions and the states."""


def key_overrides(keys: KeyFlags) -> dict[str, str | None]:
    """The feature-key flags as `resolve` overrides of a run's ``keys`` setting (None: not given)."""
    return {f"keys.{name}": value for name, value in dataclasses.asdict(keys).items()}


def feature_keys(keys: KeyFlags) -> FeatureKeys:
    """The feature keys the flags name, LeRobot's where a flag is left out."""
    return FeatureKeys(**{name: value for name, value in dataclasses.asdict(keys).items() if value is not None})


def train_wm(
    out: Path,
    data: Path | None = None,
    backend: Literal["embedded", "flow"] | None = None,
    preset: GPUPreset = "full",
    resume: bool = False,
    device: str | None = None,
    steps: int | None = None,
    seed: int | None = None,
    future: int | None = None,
    moving_weight: float | None = None,
    action_dropout: float | None = None,
    actions_per_frame: int | None = None,
    grounded: bool | None = None,
    state_noise: float | None = None,
    init: Path | None = None,
    extra_data: tuple[Path, ...] = (),
    camera: str | None = None,
    cameras: CameraNames = (),
    fit: Fit | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Train a world model on every episode of a dataset (held-out scenes excepted).

    Args:
        out: run directory: checkpoints, metrics.jsonl, config.json, videos/.
        data: dataset directory (from `gymnast collect`); with --resume, the run's own.
        backend: embedded (deterministic; the default) or flow (generative: latent flow matching, one sampled
            frame per action); with --resume, the run's own.
        preset: debug (seconds), demo (minutes), full (under an hour on 2 cores) or gpu (a larger model
            for one GPU; docs/gpu.md).
        resume: continue the run in OUT from its last checkpoint, with the settings and data saved there.
        device: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N.
        steps: override the preset's optimizer steps.
        seed: override the seed.
        future: actions per training clip, imagined open-loop and backpropagated through (the preset's: 32
            for the embedded backend; 1 trains on one-step predictions alone).
        moving_weight: extra loss weight of moving pixels, normalised (0 = plain mean squared error).
        action_dropout: share of training steps whose action is hidden, so that the model can be
            imagined with action guidance (`guidance` in its config.json; docs/world_model.md).
        actions_per_frame: imagine one frame per chunk of this many actions, one latent step each (the
            policy's action chunk, e.g. 5; embedded backend; 1 = a frame per action). Fine-tunes from a
            model of one frame per action.
        grounded: render every frame at the episode's recorded state (embedded backend): the model
            then imagines beside a state model that gives it the states (`gymnast rl --robot-state`).
        state_noise: with --grounded, noise on the recorded states in training, in units of their spread
            (a state model's imagined states are that far off).
        init: fine-tune: start from the weights of this world-model run or checkpoint (same model spec).
        extra_data: more dataset directories to train on (same image size), split by the same scene hash.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        cameras: several dataset cameras to imagine side by side, the primary first (e.g. front,gripper):
            one model learns every camera's view; saved with the model, so rl starts it from the views a
            policy of those cameras sees. Default: --camera alone.
        fit: how frames that are not the model's square size are fitted: resize (squash the whole
            frame) or crop (the central square); saved with the run.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.world_model.train import saved_train_config, train_world_model, wm_preset

    config, inputs = resolve(
        "train-wm", out, resume, wm_preset(preset, backend or "embedded"), inputs={"data": data}, required=("data",),
        overrides={"backend": backend, "device": device, "steps": steps, "seed": seed, "future": future,
                   "moving_weight": moving_weight,
                   f"{'flow' if backend == 'flow' else 'model'}.action_dropout": action_dropout,
                   "model.actions_per_frame": actions_per_frame,
                   "grounded": grounded, "state_noise": state_noise, "init": init, "extra_data": extra_data or None, "camera": camera, "cameras": cameras or None, "fit": fit,
                   **key_overrides(keys)},
        saved=lambda: (saved_train_config(out), saved_inputs(out, "data")))
    checkpoint = train_world_model(inputs["data"], out, config, resume=resume)
    print(f"world model: {checkpoint}")


def train_state(
    out: Path,
    data: Path | None = None,
    resume: bool = False,
    steps: int = 4000,
    unroll: int = 16,
    seed: int = 0,
    ridge: float = 1e-4,
    last_action: bool = True,
    extra_data: tuple[Path, ...] = (),
    init: Path | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Train the grounded state model on a dataset's recorded states, rewards and success flags: the
    state under the actions, and a reward head read off it (`--reward state:OUT`); writes
    OUT/eval.json, its open-loop errors on the held-out scenes.

    Args:
        out: run directory: checkpoints, metrics.jsonl, config.json, eval.json.
        data: dataset directory (from `gymnast collect`, or a LeRobot dataset with observation.state);
            with --resume, the run's own.
        resume: continue the run in OUT from its last checkpoint, with the settings and data saved there.
        steps: optimizer steps.
        unroll: steps imagined open loop per training window.
        seed: seed of the weights and of the windows drawn.
        ridge: start the dynamics' linear path at the least-squares fit of the recorded steps with this
            ridge penalty (0: at zero).
        last_action: condition each step on the action before it too.
        extra_data: more datasets to train on, e.g. the policy's own rollouts (`gymnast collect --policy`).
        init: fine-tune: start from the weights of this state-model run or checkpoint (its architecture
            and normalisation kept), e.g. on the policy's newest rollouts with --extra-data.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.utils.settings import from_json, saved_settings
    from gymnast.world_model.train_state import StateTrainConfig, train_state_model

    if resume:
        config, data = from_json(StateTrainConfig, saved_settings(out, "train")), Path(saved_settings(out)["data"])
    elif data is None:
        raise ValueError("train-state needs --data (or --resume to continue the run in --out)")
    else:
        config = StateTrainConfig(steps=steps, unroll=unroll, seed=seed, ridge=ridge, last_action=last_action,
                                  extra_data=extra_data, keys=feature_keys(keys), init=init)
    checkpoint = train_state_model(data, out, config, resume=resume)
    print(f"state model: {checkpoint}; held-out errors: {out / 'eval.json'}")


def practice_summary(
    out: Path,
    run: tuple[str, ...],
) -> None:
    """Gather RL runs into a practice summary (results/practice/summary.json): per task set, SFT (the
    first run's step-0 evaluation) and each RL arm's last real-world evaluation.

    Args:
        out: the JSON to write.
        run: TASKSET:ARM=RUN, one per run; ARM is imagined_rl or real_rl (e.g. weak:imagined_rl=runs/practice_weak).
    """
    from gymnast.experiment.practice_summary import practice_summary as summarize

    runs: dict[str, dict[str, Path]] = {}
    for item in run:
        named, _, path = item.partition("=")
        task_set, _, arm = named.partition(":")
        if not (task_set and arm and path):
            raise ValueError(f"--run {item!r}: expected TASKSET:ARM=RUN, e.g. weak:imagined_rl=runs/practice_weak")
        runs.setdefault(task_set, {})[arm] = Path(path)
    print(json.dumps(summarize(runs, out), indent=2))


def eval_wm(
    wm: Path,
    data: Path,
    out: Path,
    max_episodes: int = 0,
    videos: int = 6,
    gifs: int = 0,
    control_scenes: int = 10,
    reanchor_every: int | None = None,
    camera: str | None = None,
    device: str = "auto",
    robot_state: Path | None = None,
    measure_every: int | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Measure a world model's open-loop fidelity and controllability on held-out episodes.

    Args:
        wm: world-model run (or checkpoint) directory.
        data: dataset directory; its episodes from held-out scenes are used.
        out: report JSON; side-by-side videos go to <out stem>_videos/.
        max_episodes: evaluate at most this many held-out episodes (0 = all).
        videos: side-by-side videos (real | imagined | difference) to write.
        gifs: also write the first GIFS of them as small looping GIFs.
        control_scenes: held-out scenes for the controllability check (0 skips it).
        reanchor_every: override how often a long rollout re-encodes its own frames (0 = never).
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        device: where the world model imagines: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N.
        robot_state: for a grounded world model (train-wm --grounded), the state model (or ensemble) run whose
            imagined states it renders at, from each rollout's real start; default: the recorded states.
        measure_every: measure the frames after actions N, 2N, ... of each rollout (default: those the model
            imagines: every frame, or each chunk's last for a model of one frame per chunk); e.g. 5 to
            compare a model of one frame per action with one per 5-action chunk on the same frames.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state).
    """
    from gymnast.world_model.controllability import ControllabilityConfig
    from gymnast.world_model.evaluate import WorldModelEvalConfig, evaluate_world_model, format_report

    config = WorldModelEvalConfig(max_episodes=max_episodes, videos=videos, gifs=gifs,
                                  controllability=ControllabilityConfig(scenes=control_scenes), reanchor_every=reanchor_every,
                                  camera=camera, device=device, keys=feature_keys(keys), robot_state=robot_state,
                                  measure_every=measure_every)
    report = evaluate_world_model(wm, data, out, config)
    print(format_report(report))
    print(f"report: {out}")


def object_fidelity(
    wm: Path,
    data: Path,
    out: Path,
    extra_data: tuple[Path, ...] = (),
    tasks: str = "pick-place-v3,push-v3,peg-insert-side-v3",
    steps: int = 3000,
) -> None:
    """Object-level fidelity: train a position probe on real frames, then measure how far the object the
    world model imagines (open-loop, held-out episodes) is from the real one at steps 1, 8, 16, 32, 64, 128.

    Args:
        wm: world-model run (or checkpoint) directory; its held-out scenes are measured.
        data: dataset directory.
        out: report JSON (per task and step: centimetres, counts, probe floor, settings, seconds).
        extra_data: more datasets (same image size) to train the probe on and measure.
        tasks: tasks with a small object, comma-separated.
        steps: optimizer steps of the probe.
    """
    from gymnast.envs.tasks import resolve_tasks
    from gymnast.world_model.object_probe import ObjectProbeConfig, format_object_table, measure_object_fidelity

    config = ObjectProbeConfig(tasks=resolve_tasks(tasks), steps=steps)
    report = measure_object_fidelity(wm, data, out, extra_data, config)
    print(format_object_table(report))
    print(f"report: {out}")


def make_ensemble(members: tuple[Path, ...], out: Path) -> None:
    """Make an ensemble of world-model runs, or of state-model runs: OUT/ensemble.json lists them
    (relative to OUT). An ensemble of world models works wherever a world-model run does (--wm OUT;
    eval-wm also reports where the members disagree); one of state models wherever a state-model run
    does (--reward state:OUT: the members' mean reward, a success only where all predict it).

    Args:
        members: two or more world-model runs (the first one's frames are the ensemble's), or two or
            more `gymnast train-state` runs (or checkpoints).
        out: ensemble directory (created if missing).
    """
    from gymnast.world_model.ensemble import write_ensemble
    from gymnast.world_model.state_model import is_state_model, write_state_ensemble

    if any(is_state_model(member) for member in members):
        print(f"ensemble of {len(write_state_ensemble(out, members))} state models: {out}")
        return
    model = write_ensemble(out, members)
    print(f"ensemble of {len(model.members)} world models: {out}")


def train_judge(
    out: Path,
    data: Path | None = None,
    wm: Path | None = None,
    preset: GPUPreset = "full",
    resume: bool = False,
    steps: int | None = None,
    kind: Literal["frames", "video", "progress"] | None = None,
    extra_data: tuple[Path, ...] = (),
    init: Path | None = None,
    camera: str | None = None,
    cameras: CameraNames = (),
    fit: Fit | None = None,
    threshold_tpr: float | None = None,
    hard_negatives: float | None = None,
    device: str | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Train the embedded success judge on real episodes (and their re-imaginings with --wm), choose
    its threshold on validation scenes, then report its TPR and FPR on held-out real and imagined videos.

    Args:
        out: run directory: checkpoints, metrics.jsonl, metrics.json (the held-out figures).
        data: dataset directory (from `gymnast collect`); with --resume, the run's own.
        wm: world-model run: also train and measure on its re-imagining of every episode.
        preset: debug (seconds), demo (minutes), full or gpu (a wider judge for one GPU; docs/gpu.md).
        resume: continue the run in OUT from its last checkpoint, with the settings, data and world model
            saved there.
        steps: override the preset's optimizer steps.
        kind: frames (judge every frame; the default), video (four frames of the whole video) or progress
            (every frame's dense reward; a video scores its mean: a continuous reward, no threshold).
        extra_data: more datasets to train and measure on (e.g. a policy's recorded rollouts).
        init: a judge run (or checkpoint) to fine-tune instead of starting from random weights.
        camera: the dataset camera to read, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        cameras: several dataset cameras the per-frame judges see side by side, the primary first
            (e.g. front,gripper; with --wm, a world model of the same cameras). Default: --camera alone.
        fit: how frames that are not the model's square size are fitted: resize (squash the whole
            frame) or crop (the central square); saved with the run.
        threshold_tpr: choose the threshold for this TPR on the validation scenes (the highest that
            passes this share of their successes) instead of the most TPR - FPR; e.g. 0.95.
        hard_negatives: share of each batch's negative frames chosen as those the judge rates highest
            of four times as many random ones (its near misses); default 0, all random.
        device: auto (CUDA when torch sees a GPU, else the CPU), cpu, cuda or cuda:N; --resume may change it.
        keys: which dataset features are the actions and the states (default: LeRobot's action and
            observation.state); saved with the run.
    """
    from gymnast.reward.train_judge import JUDGE_PRESETS, saved_judge_config
    from gymnast.reward.train_judge import train_judge as train

    config, inputs = resolve(
        "train-judge", out, resume, JUDGE_PRESETS[preset], inputs={"data": data, "wm": wm}, required=("data",),
        overrides={"steps": steps, "kind": kind, "extra_data": extra_data or None, "init": init, "camera": camera,
                   "cameras": cameras or None, "fit": fit, "threshold_tpr": threshold_tpr,
                   "hard_negatives": hard_negatives, "device": device, **key_overrides(keys)},
        saved=lambda: (saved_judge_config(out), saved_inputs(out, "data", "wm")))
    report = train(inputs["data"], out, config, wm=inputs["wm"], resume=resume)
    print(json.dumps({k: v for k, v in report.items() if k.startswith(("real", "imagined"))}, indent=2))
    print(f"judge: {out}")


def serve_judge(
    judge: Path,
    port: int = 8000,
    host: str = "127.0.0.1",
    limits: Annotated[ChatLimits, tyro.conf.arg(name="")] = ChatLimits(),
) -> None:
    """Serve the learned judge over the OpenAI chat-completions protocol (POST /v1/chat/completions).

    A malformed request, one past the limits, or one that stalls past the read timeout gets a 4xx
    JSON error in the OpenAI shape naming the field at fault; the server logs it and serves on.

    Args:
        judge: judge run (or checkpoint) directory, from `gymnast train-judge`.
        port: TCP port to listen on.
        host: address to bind (127.0.0.1: this machine only).
        limits: the largest request body and `n`, and the read timeout.
    """
    import time

    from gymnast.reward.serve import judge_server

    with judge_server(judge, host, port, limits=limits) as server:
        print(f"judge: {judge} at {server.url} (model gymnast-judge); Ctrl-C stops", flush=True)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass


def eval_judge(
    reward: str,
    data: Path,
    out: Path,
    wm: Path | None = None,
    heldout_fraction: float = 0.1,
    device: str = "auto",
    camera: str | None = None,
    keys: Annotated[KeyFlags, tyro.conf.arg(name="")] = KeyFlags(),
) -> None:
    """Measure a 0/1 judge (judge:RUN or vlm:MODEL@BASE_URL) on held-out episodes: TPR and FPR on
    real videos and, with --wm, on the world model's re-imagining of the same episodes.

    Args:
        reward: the judge, e.g. judge:runs/judge or vlm:gpt-4o@https://api.openai.com/v1 (key from OPENAI_API_KEY).
        data: dataset directory; the episodes of its held-out scenes are judged.
        out: report JSON.
        wm: world-model run whose imagined videos are judged too.
        heldout_fraction: the held-out share of scenes (the world model's, so its videos are unseen).
        device: where a learned judge and the world model run: auto (CUDA when torch sees a GPU), cpu, cuda or cuda:N.
        camera: the dataset camera to judge, by name (front: observation.images.front) or by feature key
            (image, observation.images.top); default: its first video (else image) feature.
        keys: which dataset features are the actions (re-imagined with --wm) and the states (default:
            LeRobot's action and observation.state).
    """
    from gymnast.reward.select import measure_judge

    report = measure_judge(RewardSpec.parse(reward), data, out, wm, heldout_fraction, device, camera,
                           feature_keys(keys))
    print(json.dumps(report, indent=2))


def rl(
    out: Path,
    policy: Path | None = None,
    env: EnvName | None = None,
    reward: str | None = None,
    wm: Path | None = None,
    data: Path | None = None,
    robot_state: Path | None = None,
    preset: GPUPreset = "full",
    resume: bool = False,
    config: Annotated[RLFlags, tyro.conf.arg(name="")] = RLFlags(),
) -> None:
    """Fine-tune a policy with GRPO in the world model (imagined), the software simulator or the real world.

    Args:
        out: run directory: checkpoints, metrics.jsonl, tensorboard/, videos/, summary.json.
        policy: the SFT (or RL) run or checkpoint to start from (required unless --resume).
        env: where rollouts happen: imagined (in --wm), sim (the software simulator, --gap) or real.
        reward: judge:RUN | vlm:MODEL@BASE_URL | verified | sim | sim-dense.
        wm: the world model run (needed by --env imagined and --reward verified).
        data: dataset whose scenes are the start states (default: the one the policy was trained on).
        robot_state: with --env imagined, a state model (or ensemble) run stepped beside the world
            model, whose imagined robot state is given to a policy that reads one (observation.state).
        preset: debug (seconds), demo (minutes), full or gpu (400 steps of 256 rollouts; docs/gpu.md).
        resume: continue the run in OUT from its last checkpoint, with the settings, policy, env,
            reward, world model and data saved there.
        config: the GRPO settings; each one left out keeps the preset's value.
    """
    from gymnast.rl.config import RLRun, saved_rl_settings
    from gymnast.rl.inputs import with_tasks_from_data
    from gymnast.rl.train import train_rl

    def saved() -> tuple[RLConfig, dict]:
        run_spec, settings = saved_rl_settings(out)
        return settings, {field.name: getattr(run_spec, field.name) for field in dataclasses.fields(run_spec)}

    # Parsed here, once: the library takes the env kind and the reward spec, never their names.
    settings, inputs = resolve(
        "rl", out, resume, RL_PRESETS[preset], overrides=dataclasses.asdict(config), saved=saved,
        inputs={"policy": policy, "env": None if env is None else env_kind(env),
                "reward": None if reward is None else RewardSpec.parse(reward), "wm": wm, "data": data,
                "robot_state": robot_state},
        required=("policy", "env", "reward"))
    run_spec = RLRun(**{name: str(value) if isinstance(value, Path) else value for name, value in inputs.items()})
    if not resume and config.tasks is None:  # the preset's tasks may not be in the data
        settings = with_tasks_from_data(run_spec, settings)
    summary = train_rl(run_spec, out, settings, resume=resume)
    summary.pop("curve")
    print(json.dumps(summary, indent=2))


def worldgym(
    policy: Path,
    wm: Path,
    judge: Path,
    out: Path,
    noise: CommaFloats = DEFAULT_NOISE,
    tasks: str = "mt10",
    episodes: int = 10,
    horizon: int = 150,
    workers: int = 2,
    runner: str = "local",
    seed: int = 0,
) -> None:
    """WorldGym over a noise ladder: can the world model and judge rank policies like the real world?

    Each noise level of POLICY is rolled out greedily in imagination (judged) and in the real world
    from the same evaluation seeds; writes OUT/worldgym.json (rows with 95% intervals, Pearson and
    Spearman, settings, seconds) and OUT/worldgym.png, and prints the table.

    Args:
        policy: the SFT/RL run (or checkpoint) the ladder is made of.
        wm: world-model run the policies are imagined in.
        judge: learned-judge run that scores the imagined rollouts.
        out: output directory.
        noise: action-noise std per level (actions span [-1, 1]); 0 is the policy itself, inf random actions.
        tasks: task names or sets, comma-separated.
        episodes: evaluation seeds per task, in each world.
        horizon: actions per episode, in each world.
        workers: simulator processes for the real-world rollouts.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        seed: seed of the noise.
    """
    from gymnast.experiment.worldgym import format_rows, run_worldgym

    result = run_worldgym(policy, noise, wm, judge, tasks, episodes, out, horizon=horizon, workers=workers, seed=seed,
                          runner=runner)
    print(format_rows(result))
    print(f"report: {out / 'worldgym.json'}, plot: {out / 'worldgym.png'}")


def experiment(
    out: Path,
    preset: GPUPreset = "full",
    resume: bool = False,
    reuse: Annotated[list[str], tyro.conf.UseAppendAction] = [],  # noqa: B006 (read by tyro, never mutated)
    workers: int | None = None,
    sentences: Path | None = None,
    runner: str | None = None,
    device: str | None = None,
    cameras: CameraNames | None = None,
    judge_rollouts: int | None = None,
    demos_per_task: int | None = None,
    freeze: tuple[str, ...] | None = None,
) -> None:
    """The headline comparison: data, SFT, world model, judge, state model, eight arms, real-world
    evaluation and the WorldGym check, then OUT/report.md, OUT/summary.json and OUT/plots/.
    Rerunning the same command skips the stages that finished and continues an interrupted one.

    Args:
        out: experiment directory.
        preset: debug (a minute; tests), demo (a few tasks, what `make demo` runs), full (MT10) or gpu
            (MT10 at the papers' budget, for one GPU and its host's cores; docs/gpu.md).
        resume: continue the experiment in OUT with the settings saved there (whatever its preset).
        reuse: a stage to take from an earlier run instead of running it, as STAGE=DIR (collect=DATASET,
            sft=RUN, world_model=RUN, judge=RUN, state_model=RUN or an ensemble of them); repeat for
            several, e.g. --reuse collect=data/mt10 --reuse world_model=runs/wm_full.
        workers: simulator processes (default: the preset's, one per core on 2 cores).
        sentences: a file of `task: sentence` lines, your own wording of the tasks: the language
            check gives the policies these instead of the held-out paraphrases.
        runner: where they run: local, ray or ray:ADDRESS (default: the preset's, local).
        device: where the models train, imagine and judge: auto (CUDA when torch sees a GPU, else the
            CPU), cpu, cuda or cuda:N; --resume may change it.
        cameras: the views recorded and seen side by side by the policy, the world model and the
            judges, e.g. front or front,gripper,hand (default: the preset's, front,gripper).
        judge_rollouts: real rollouts per task of the SFT policy, played past any success, that the
            judge also learns from (its near misses; counted in summary.json); default: the preset's.
        demos_per_task: expert demonstrations per task the SFT policy learns from (default: the
            preset's, 10); the world model and the judge still learn from the whole dataset. 2 is
            the data-scarce regime (results/sft/scarce: SFT at 15-40% on MT10).
        freeze: parts of the policy the RL arms leave as SFT made them, by parameter-name prefix
            (default: the preset's, vision: the embedded policies' image encoder; a LeRobot
            policy's are its own, e.g. model.backbone; none: `--freeze` alone).
    """
    from gymnast.experiment.config import EXPERIMENT_PRESETS
    from gymnast.experiment.pipeline import run_experiment, saved_experiment_config
    from gymnast.experiment.report import format_table
    from gymnast.experiment.stages import parse_reuse

    config, _ = resolve("experiment", out, resume, EXPERIMENT_PRESETS[preset],
                        overrides={"workers": workers, "sentences": sentences, "runner": runner, "device": device,
                                   "cameras": cameras, "judge_rollouts": judge_rollouts,
                                   "sft.demos_per_task": demos_per_task, "rl.freeze": freeze},
                        inputs={}, saved=lambda: (saved_experiment_config(out), {}))
    summary = run_experiment(config, out, parse_reuse(reuse))
    print(format_table(summary))
    print(f"report: {out / 'report.md'}")


def imagination(
    policy: Path,
    wm: Path,
    reward: str,
    out: Path,
    tasks: str = "mt10",
    episodes: int = 10,
    horizon: int = 150,
    batch: int = 32,
    workers: int = 1,
    runner: str = "local",
    videos: int = 4,
    seed: int = 0,
    robot_state: Path | None = None,
) -> None:
    """Measure imagination under a policy: its greedy rollouts in the world model, judged, against
    the same actions replayed in the real world (agreement, false successes, PSNR per step) and
    against the policy run in the real world; writes OUT/imagination.json, imagination.md,
    psnr.png and side-by-side videos.

    Args:
        policy: SFT/RL run (or checkpoint) directory.
        wm: world-model run (or checkpoint) directory.
        reward: a 0/1 judge: judge:RUN or vlm:MODEL@BASE_URL (key from OPENAI_API_KEY).
        out: report directory.
        tasks: task names and/or sets, comma-separated.
        episodes: evaluation scenes per task.
        horizon: actions per rollout.
        batch: rollouts stepped together.
        workers: simulator processes for the real-world envs.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        videos: side-by-side videos (imagined | real replay | difference), disagreements first.
        seed: reset seed of the envs (what a stochastic world model draws from).
        robot_state: for a policy that reads the robot's state (observation.state), a state model
            (or ensemble) run that imagines it beside the world model (gymnast train-state).
    """
    from gymnast.experiment.imagination import ImaginationConfig, measure_imagination_runs
    from gymnast.experiment.imagination_report import format_imagination

    config = ImaginationConfig(tasks=tasks, episodes=episodes, horizon=horizon, batch=batch, workers=workers,
                               runner=runner, videos=videos, seed=seed)
    report = measure_imagination_runs(policy, wm, RewardSpec.parse(reward), config, out, robot_state=robot_state)
    print(format_imagination(report))
    print(f"report: {out / 'imagination.md'}")


def rl_signal(
    out: Path,
    policy: Path | None = None,
    wm: Path | None = None,
    reward: str | None = None,
    like: Path | None = None,
    tasks: str | None = None,
    starts_per_task: int = 8,
    group_size: int | None = None,
    temperature: float | None = None,
    horizons: tuple[int, ...] | None = None,
    batch: int | None = None,
    workers: int = 2,
    runner: str = "local",
    seed: int | None = None,
    data: Path | None = None,
    keyframes: Literal["first", "uniform", "near_success", "failures"] | None = None,
    heldout_fraction: float = 0.1,
    robot_state: Path | None = None,
) -> None:
    """Measure whether RL in imagination would push the policy where the real world would: GRPO
    groups sampled in the world model and judged, their actions replayed in the real world from the
    same starts, and the correlation of the imagined advantages with the real ones (real success,
    and the real dense return) by horizon; writes OUT/signal.json and OUT/signal.md.

    Args:
        out: report directory.
        policy: SFT/RL run (or checkpoint) directory (default: --like's).
        wm: world-model run (or checkpoint) directory (default: --like's).
        reward: a reward of the video alone: judge:RUN or vlm:MODEL@BASE_URL (key from OPENAI_API_KEY);
            or a grounded world model's reward head, state:RUN (from `gymnast train-state`) (default: --like's).
        like: an RL run in imagination whose practice is measured: its policy, world model, reward,
            tasks, starts (its dataset's keyframes), horizon, group size, temperature and seed, each
            unless given here.
        tasks: task names and/or sets, comma-separated (default: --like's, else the four weak tasks).
        starts_per_task: starts (GRPO groups) per task.
        group_size: rollouts per scene (default: --like's, else 8).
        temperature: the policy's sampling temperature (default: --like's, else 1).
        horizons: horizons read out, the largest the rollouts' length (default: --like's horizon, else 50 100 150).
        batch: rollouts stepped together, a multiple of the group size (default: 64 or the nearest multiple).
        workers: simulator processes for the real-world replays.
        runner: where they run: local, ray or ray:ADDRESS (see `gymnast eval --help`).
        seed: seed of the scenes and of the policy's samples (default: --like's, else 0).
        data: start from keyframes of this dataset's held-out episodes (segments as short as
            --horizons), restored in the real world by replaying the actions that led there;
            without it (and without --like), from fresh scenes' first frames.
        keyframes: how keyframes are drawn: first, uniform, near_success (the frames before the first
            success) or failures (episodes that failed) (default: --like's, else uniform).
        heldout_fraction: the share of --data's scenes the models held out, where keyframes come from;
            0 for a dataset they never trained on (e.g. the policy's own rollouts on new seeds).
        robot_state: for a policy that reads the robot's state (observation.state), a state model
            (or ensemble) run that imagines it beside the world model (default: --like's).
    """
    from gymnast.experiment.practice_signal import SignalConfig, batch_for, measure_signal_runs, practice_of

    inputs, settings = practice_of(like) if like is not None else ({}, {})
    given = {"policy": policy, "wm": wm, "reward": reward}
    inputs |= {name: str(value) for name, value in (given | {"robot_state": robot_state}).items() if value is not None}
    missing = [f"--{name}" for name in given if name not in inputs]
    if missing:
        raise ValueError(f"rl-signal needs {', '.join(missing)} (or --like RUN, an RL run in imagination)")
    chosen = {"tasks": tasks, "group_size": group_size, "temperature": temperature, "seed": seed,
              "horizons": None if horizons is None else tuple(horizons), "batch": batch,
              "data": None if data is None else str(data), "keyframes": keyframes}
    settings |= {name: value for name, value in chosen.items() if value is not None}
    if batch is None and "group_size" in settings:
        settings["batch"] = batch_for(settings["group_size"])
    config = SignalConfig(**settings, starts_per_task=starts_per_task, workers=workers, runner=runner,
                          heldout_fraction=heldout_fraction)
    measure_signal_runs(inputs["policy"], inputs["wm"], RewardSpec.parse(inputs["reward"]), config, out,
                        robot_state=inputs.get("robot_state"))
    print((out / "signal.md").read_text())
