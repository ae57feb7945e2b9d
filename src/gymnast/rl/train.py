"""`gymnast rl`: GRPO fine-tuning of a VLA policy in the world model, the software simulator or
the real world, through one loop.

Each step (`rl_step`, top to bottom): draw B real start states, roll the policy out G times from
each at the rollout temperature, score every video with the reward, keep the groups with
something to learn from (dynamic sampling, refilling from fresh starts), normalise rewards within
each group and take one clipped policy-gradient step (`gymnast.rl.grpo`). The loop drives a vector
env and a `Reward`; it never asks where the frames come from. What it does around the step
depends only on what the env kind and the reward declare (`gymnast.envs.kinds.EnvKind`,
`gymnast.reward.base.RewardNeeds`). Its settings are `gymnast.rl.config`.

Around the loop: atomic checkpoints with every random state and the sampler position (``--resume``
continues exactly), metrics.jsonl and its trackers (`--tracker`), rollout videos with their rewards, a
reward-hacking watch that replays imagined actions in the real world, and evaluations on the
evaluation seeds in the run's own env and in the real world, whose real interactions are counted
apart from training's.

Legend: B start states per step, G rollouts per start, R = B * G rollouts, S policy calls,
N action tokens per call, T actions.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import time
import warnings
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path

import numpy as np
import torch
from gymnasium.vector import VectorEnv
from tqdm import tqdm

from gymnast.config import EnvConfig
from gymnast.envs.factory import EnvFactory
from gymnast.envs.kinds import ANCHORED, IMAGINED, REAL, EnvKind
from gymnast.envs.metaworld import CONTROL_FPS, STATE_DIM
from gymnast.data.keyframes import KeyframeConfig
from gymnast.envs.starts import Start, StartSampler, evaluation_starts, own_instruction, scene_starts
from gymnast.envs.tasks import parse_scenes, resolve_tasks
from gymnast.policy.frozen_vision import remembered_vision
from gymnast.policy.lerobot_policy import LeRobotPolicy
from gymnast.reward.base import Reward, StepReward, check_fits
from gymnast.rl import grpo, reanchor
from gymnast.rl.config import RLConfig, RLRun
from gymnast.rl.critic import CallCritic, ValueCritic
from gymnast.rl.evaluate import evaluate_in_env, verdicts, watch_hacking
from gymnast.rl.imitation import ImitationAnchor
from gymnast.rl.inputs import check_other_robot, policy_dataset, policy_frames, policy_keys
from gymnast.rl.rollout import (Rollouts, call_inputs, collect_rollouts, concat_rollouts, dataset_starts,
                                heldout_starts, own_tasks, recorded_elsewhere, score_groups)
from gymnast.rl.sight import RewardSight, reward_truth_metrics, reward_verdicts
from gymnast.rl.videos import write_group_video
from gymnast.utils.atomic import write_json
from gymnast.utils.checkpoint import (load_checkpoint, load_extra, resolve_checkpoint, save_checkpoint,
                                      write_run_config)
from gymnast.utils.device import resolve_device, to_device
from gymnast.utils.metrics import MetricsLog
from gymnast.utils.trackers import open_trackers
from gymnast.utils.optim import warmup_cosine
from gymnast.utils.plugins import is_plugin

logger = logging.getLogger(__name__)

LEROBOT_EXPORT = "lerobot/pretrained_model"
"""Where a run of a LeRobot policy writes it back as a LeRobot pretrained_model folder."""
CRITIC = "critic"
"""The name of the learned critic's weights and optimizer state in a checkpoint (``critic.pt``)."""


def robot_state_for(state_dim: int, env: EnvKind, run_spec: RLRun, world_model=None):
    """The imagined robot state for a policy of `state_dim` (D > 0) and/or a grounded `world_model`
    in imagination (`gymnast.world_model.robot_state.robot_state_in_imagination` of
    ``--robot-state``), or None where the env gives its own (a simulator's is Meta-World's hand xyz
    and gripper) or nothing reads one.

    Raises:
        ValueError: a state the env cannot give (the message says what to pass).
    """
    from gymnast.world_model.base import grounded_state_dim
    from gymnast.world_model.robot_state import robot_state_in_imagination

    if env.imagined:
        return robot_state_in_imagination(state_dim, run_spec.robot_state, run_spec.policy, run_spec.wm,
                                          grounded_state_dim(world_model))
    if run_spec.robot_state is not None:
        raise ValueError(f"--robot-state imagines the robot's state in imagination; --env {env} is a simulator, "
                         "which gives its own: leave --robot-state out")
    if state_dim and state_dim != STATE_DIM:
        raise ValueError(f"the policy {run_spec.policy} reads a {state_dim}-d robot state (observation.state), the "
                         f"simulator gives {STATE_DIM} (hand xyz and gripper opening)")
    return None


def train_rl(run_spec: RLRun, out: Path, config: RLConfig, resume: bool = False, progress: bool = True) -> dict:
    """Trains (or resumes) an RL run in `out`; returns the summary (also RUN/summary.json)."""
    from gymnast.policy.load import load_policy, policy_env_config, policy_spec
    from gymnast.reward.judges.base import check_judge_sees
    from gymnast.reward.select import make_reward
    from gymnast.world_model.base import load_world_model, offloaded, placed
    from gymnast.world_model.ensemble import EnsembleWorldModel
    from gymnast.world_model.views import check_policy_views

    env = run_spec.env
    if env.imagined and run_spec.wm is None:
        raise ValueError(f"--env {env} practises in a world model: give it with --wm RUN")
    levers = ["--" + name.replace("_", "-") for name in ("disagreement_stop", "disagreement_penalty")
              if getattr(config, name) > 0]
    if levers and not env.imagined:
        raise ValueError(f"{levers[0]} acts on imagined rollouts; --env {env} imagines none")
    if levers and env.real_interactions:  # anchored: only the sight is imagined, the rollout goes on for real
        raise ValueError(f"{levers[0]} acts on imagined rollouts; --env {env}'s rollouts are real")
    if (env == ANCHORED) != (config.anchor_every > 0):
        raise ValueError("--anchor-every is how often --env anchored restarts the world model from the real frame: "
                         "give both or neither")
    if config.learn_on != "own" and run_spec.reward_sees is None:
        raise ValueError(f"--learn-on {config.learn_on} holds the actions to the frames of their replays where "
                         "the reward saw them: give --reward-sees real (or imagined)")
    device = resolve_device(config.device)
    policy = load_policy(run_spec.policy).to(device)
    cameras = getattr(policy.config, "cameras", ())
    world_model = placed(load_world_model(run_spec.wm), device) if run_spec.wm else None
    if env.imagined or (run_spec.reward_sees is not None and run_spec.reward_sees.imagined):
        check_policy_views(cameras, world_model, run_spec.policy, run_spec.wm)
    if env == ANCHORED and (run_spec.robot_state is not None or getattr(policy, "state_dim", 0)):
        raise ValueError(f"--env anchored shows the policy imagined frames alone, restarted from real ones; a robot "
                         f"state beside them ({run_spec.robot_state or f'the policy {run_spec.policy} reads one'}) "
                         "would go on from the imagined state")
    robot_state = robot_state_for(getattr(policy, "state_dim", 0), env, run_spec, world_model)
    # A user's own model may report disagreement too: the imagined env finds out at its first step.
    if levers and not isinstance(world_model, EnsembleWorldModel) and not is_plugin(run_spec.wm):
        raise ValueError(f"{levers[0]} needs a world-model ensemble to disagree (gymnast "
                         f"make-ensemble); {run_spec.wm} is a single world model")
    reward = make_reward(run_spec.reward, world_model)
    check_judge_sees(reward, cameras, policy.config.image_size, run_spec.reward.run, f"the policy {run_spec.policy}")
    if isinstance(reward, torch.nn.Module) or hasattr(reward, "members"):  # a learned judge, or a consensus of some
        reward.to(device)
    from_dataset = not config.fresh_scenes and config.scenes is None
    # The reward reads the rollouts, or their replays in the world it sees.
    check_fits(reward, str(run_spec.reward), run_spec.reward_sees or env, demonstrations=from_dataset)
    if config.credit != "rollout" and not isinstance(reward, StepReward):
        raise ValueError(f"--credit {config.credit} gives each policy call the rewards that followed it, but --reward "
                         f"{run_spec.reward} scores whole videos only; use a reward that scores every action "
                         "(sim-dense, state:RUN, or a progress judge) or --credit rollout")
    data = Path(run_spec.data or policy_dataset(run_spec.policy)) if from_dataset else None
    scenes = parse_scenes(config.scenes) if config.scenes is not None else None
    keys = policy_keys(run_spec.policy)  # the dataset read as the policy was trained on it
    elsewhere = data is not None and recorded_elsewhere(data, keys)
    if elsewhere:
        check_other_robot(data, env, config)
        tasks = own_tasks(data, config.tasks, keys)
    else:
        tasks = tuple(dict.fromkeys(task for task, _ in scenes)) if scenes else resolve_tasks(config.tasks)
    if config.instruction is not None and len(tasks) != 1:
        raise ValueError(f"--instruction is one sentence for one task, but --tasks {config.tasks} names {len(tasks)}; "
                         "practise one task at a time")
    env_config = policy_env_config(EnvConfig(image_size=policy.config.image_size, horizon=config.horizon), policy)
    practice = own_instruction(scene_starts(scenes, env_config), config.instruction) if scenes else None
    # Start frames as the policy saw its training frames: the same camera, fitted the same way.
    frames = policy_frames(run_spec.policy)
    keyframes = KeyframeConfig(sampling=config.keyframes, horizon=config.horizon, per_episode=config.keyframes_per_episode)
    pool = dataset_starts(data, tasks, policy.config.image_size, frames.get("fit", "resize"),
                          frames.get("camera"), keyframes, keys, cameras if len(cameras) > 1 else None) if data else None
    draw_starts = StartSampler(tasks, practice or pool, env_config, config.instruction)
    # Evaluations run in batches of the training batch, before the first step too (the evaluation
    # before training used to run one episode at a time), at most 32 episodes per simulator process:
    # each process keeps up to twice its episodes' scenes built, tens of MB each (`SimVectorEnv`).
    batch = min(config.starts_per_step * config.group_size, 32 * config.workers)
    envs = EnvFactory(env, policy.chunk_size, env_config, config.gap, config.workers, world_model,
                      stop_above=config.disagreement_stop or None, runner=config.runner, batch=batch,
                      robot_state=robot_state, anchor_every=config.anchor_every)
    # Segments from keyframes are shorter than the task's episodes, which evaluation runs whole.
    eval_envs = envs if config.evaluation_horizon == config.horizon else EnvFactory(
        env, policy.chunk_size, dataclasses.replace(env_config, horizon=config.evaluation_horizon), config.gap,
        config.workers, world_model, stop_above=config.disagreement_stop or None, runner=config.runner, batch=batch,
        robot_state=robot_state, anchor_every=config.anchor_every)
    replays = None  # the reward's own world model: its replays are not the loop the policy acted in
    if run_spec.reward_wm is not None:
        if run_spec.reward_sees is None or not run_spec.reward_sees.imagined:
            raise ValueError("--reward-wm is the world model the reward's replays are imagined in: give it with "
                             "--reward-sees imagined")
        reward_world_model = placed(load_world_model(run_spec.reward_wm), device)
        check_policy_views(cameras, reward_world_model, run_spec.policy, run_spec.reward_wm)
        replays = EnvFactory(IMAGINED, policy.chunk_size, env_config, config.gap, config.workers, reward_world_model,
                             runner=config.runner, batch=batch)
    sight = RewardSight(envs, env, run_spec.reward_sees, config.truth_groups, replays, video=reward.needs.video)
    resolved = {"rl": dataclasses.asdict(config), "run": run_spec.to_json(), "model": policy_spec(policy),
                "data": str(data) if data else None, "frames": frames}

    optimizer = torch.optim.AdamW(learning_parameters(policy, config.freeze), lr=config.lr, weight_decay=0.0)
    critic = None
    if config.credit == "critic":
        critic = CallCritic(ValueCritic.for_policy(policy), config.critic_lr, config.critic_epochs, config.gae_lambda,
                            config.micro_batch, config.max_grad_norm)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, warmup_cosine(config.warmup_steps, 10**12))
    sampler = torch.Generator().manual_seed(config.seed)  # start states and env seeds
    actions = torch.Generator().manual_seed(config.seed + 1)  # the policy's token draws
    reference = _frozen_copy(policy) if config.kl_coef > 0 or config.imitation_kl_gate > 0 else None
    anchor = None
    if config.imitation_coef > 0:
        demos = Path(run_spec.data or policy_dataset(run_spec.policy))  # the experts', whatever the starts
        anchor = ImitationAnchor.from_dataset(demos, tasks, policy.chunk_size, config.imitation_coef,
                                              config.imitation_kl_gate, config.imitation_batch, keys,
                                              cameras if len(cameras) > 1 else None)
    state = {"real_interactions": 0, "eval_real_interactions": 0, "watch_real_interactions": 0,
             "truth_real_interactions": 0, "reset_frames": len(practice or ()), "curve": [], "wall_s": 0.0}
    start_step = 0
    if resume:
        checkpoint_dir = resolve_checkpoint(out)
        trainer, rng = load_checkpoint(checkpoint_dir, policy, optimizer)
        if critic is not None:
            critic.load_state_dict(load_extra(checkpoint_dir, CRITIC))
        schedule.load_state_dict(trainer["schedule"])
        sampler.set_state(rng["sampler"])
        actions.set_state(rng["actions"])
        state = trainer["state"]
        start_step = trainer["step"]
        logger.info("resumed %s at step %d", out, start_step)
    write_run_config(out, resolved)
    resume_step = start_step if resume else None
    metrics = MetricsLog(out, resume_step, open_trackers(config.tracker, out, resume_step, "rl", resolved))
    if elsewhere:  # no simulator sets up new scenes of another robot: the models' held-out ones
        eval_starts = own_instruction(heldout_starts(pool, config.eval_episodes), config.instruction)
    else:
        eval_starts = practice or own_instruction(evaluation_starts(tasks, config.eval_episodes, env_config),
                                                  config.instruction)
    reset_frames_before = state.get("reset_frames", 0)  # runs saved before the count have none

    def log(step: int, values: dict[str, float]) -> None:
        values = {key: value for key, value in values.items() if np.isfinite(value)}  # NaN: nothing to report
        metrics.log(step, values)

    def evaluate(step: int) -> None:
        values: dict[str, float] = {}
        # An imagined evaluation is judged by the run's reward; one that reads another world's replays
        # (the real world's verdict on imagined actions) has its evaluation there, below.
        if env.reports_success or run_spec.reward_sees is None:
            values = evaluate_in_env(eval_envs, env, policy, reward, eval_starts, prefix="eval/own", progress=progress)
        if config.real_eval and not env.real_sight:  # else its own evaluation is the real one
            real = evaluate_in_env(eval_envs, REAL, policy, reward, eval_starts, prefix="eval/real",
                                   progress=progress)
            state["eval_real_interactions"] += int(real.pop("eval/real_interactions"))
            values |= real
        own = int(values.pop("eval/own_interactions", 0))
        if env.real_interactions:  # evaluating in the real world spends real interactions too
            state["eval_real_interactions"] += own
        values["eval/real_interactions"] = state["eval_real_interactions"]
        values = {key: value for key, value in values.items() if np.isfinite(value)}  # JSON has no NaN
        eval_envs.close_others()  # until the next evaluation, steps in the training env only
        state["curve"].append({"step": step, **values})
        log(step, values)

    def checkpoint(done: int) -> None:
        save_checkpoint(out, done, policy, resolved, optimizer,
                        {"sampler": sampler.get_state(), "actions": actions.get_state()},
                        {"schedule": schedule.state_dict(), "state": state},
                        extra={CRITIC: critic.state_dict()} if critic is not None else None)
        if isinstance(policy, LeRobotPolicy):  # back to LeRobot: the newest weights as its own folder
            policy.export(out / LEROBOT_EXPORT)

    def evaluation_due(done: int) -> bool:
        return (config.eval_every and done % config.eval_every == 0) or done == config.steps

    try:
        evaluated = {entry["step"] for entry in state["curve"]}
        if start_step == 0 or (evaluation_due(start_step) and start_step not in evaluated):
            # A new run's first evaluation, or one that a crash stopped after its step was saved.
            metrics.drop(start_step, "eval/")
            began = time.perf_counter()
            evaluate(start_step)
            state["wall_s"] += time.perf_counter() - began
            if start_step:
                checkpoint(start_step)
        bar = tqdm(range(start_step, config.steps), initial=start_step, total=config.steps, desc=f"rl {env}",
                   disable=not progress)
        for step in bar:
            done = step + 1
            started = time.perf_counter()
            video_due = done % config.video_every == 0 or done == config.steps
            # A video shows what was rendered: where only each chunk's last frame was (the reward reads
            # no others), it holds that frame for the chunk's actions, as a frame-per-chunk world model
            # imagines it. Rendering every frame of every rollout for one group's video made such a
            # step 2.9 times as long (410 s against 140 s in the two-camera headline's simulator arm).
            with remembered_vision(*([policy, reference] if config.remember_vision else [])) as memories:
                batch, scores, values = rl_step(envs.train(config.starts_per_step * config.group_size), policy,
                                                reward, draw_starts, config, sampler, actions, optimizer, schedule,
                                                reference, anchor, critic,
                                                every_frame=reward.needs.video and run_spec.reward_sees is None,
                                                sight=sight, released=lambda: offloaded(world_model))
            encoded = sum(memory.hits + memory.misses for memory in memories)
            if encoded:  # the share of the images a policy read whose tokens were already computed
                values["train/vision_reused"] = sum(memory.hits for memory in memories) / encoded
            interactions = int(values.pop("rollout/interactions"))
            replayed = int(values.pop("rollout/replay_interactions"))
            if env.real_interactions:
                state["real_interactions"] += interactions
            if sight.real_replays:  # the reward's verdict came from replaying the actions for real
                state["real_interactions"] += replayed
            state["truth_real_interactions"] = state.get("truth_real_interactions", 0) + int(
                values.pop("reward/truth_interactions"))
            values["reward/truth_real_interactions"] = state["truth_real_interactions"]
            values["time/step_s"] = time.perf_counter() - started
            values["train/lr"] = schedule.get_last_lr()[0]
            values["rollout/real_interactions"] = state["real_interactions"]
            state["reset_frames"] = reset_frames_before + draw_starts.rendered
            values["rollout/reset_frames"] = state["reset_frames"]
            values |= reward.metrics()  # a VLM judge's request, retry, cache and token counts
            # The watch replays actions in the real world: with real interactions there is nothing to check.
            if batch is not None and config.watch_every and done % config.watch_every == 0 and not env.real_interactions:
                watched = watch_hacking(envs, batch, scores, verdicts(batch, scores, reward), config.watch_rollouts)
                envs.close_others()  # the watch's real-world replays
                state["watch_real_interactions"] += int(watched.pop("eval/watch_interactions"))
                values |= watched | {"eval/watch_real_interactions": state["watch_real_interactions"]}
            if batch is not None and video_due:
                metrics.video("rollout/group_video", done, write_group_video(
                    out / "videos" / f"step_{done:06d}.mp4", batch, scores, config.group_size), CONTROL_FPS)
            del batch, scores  # not held through the evaluation and the next step's rollouts
            log(done, values)
            bar.set_postfix(reward=f"{values.get('reward/mean', float('nan')):.2f}", step_s=f"{values['time/step_s']:.1f}")
            state["wall_s"] += time.perf_counter() - started
            if done % config.checkpoint_every == 0 or evaluation_due(done):
                checkpoint(done)  # before the evaluation, which can run long: a crash there keeps the step
            if evaluation_due(done):
                began = time.perf_counter()
                evaluate(done)
                state["wall_s"] += time.perf_counter() - began
                checkpoint(done)  # again, with the evaluation in its state
    finally:  # worker processes and event files are released even when a step fails
        envs.close()
        eval_envs.close()
        if replays is not None:
            replays.close()
        metrics.close()
    return write_summary(out, run_spec, config, state)


def rl_step(env: VectorEnv, policy, reward: Reward, draw_starts: Callable[[int, torch.Generator], list[Start]],
            config: RLConfig, sampler: torch.Generator, actions: torch.Generator, optimizer: torch.optim.Optimizer,
            schedule: torch.optim.lr_scheduler.LRScheduler, reference=None, anchor: ImitationAnchor | None = None,
            critic: CallCritic | None = None, every_frame: bool = True, sight: RewardSight | None = None,
            released: Callable[[], AbstractContextManager] = nullcontext
            ) -> tuple[Rollouts | None, torch.Tensor | None, dict[str, float]]:
    """One RL step, from start states to the policy update.

    1. Draw B start states and roll the policy out G times from each, at the rollout temperature.
    2. Score every rollout with the reward, one group (one start state) at a time, on the video
       the reward sees (`sight`: the rollouts' own, or their actions replayed in another world).
       In the first round, measure the reward against the real outcome where it is known
       (``reward/agreement``...; `gymnast.rl.sight`).
    3. Dynamic sampling: keep the groups with something to learn from, refilling from fresh starts
       for at most `max_rounds` rounds. A binary reward keeps a group when its success rate lies in
       [keep_low, keep_high]; a continuous one (dense, verified) when its rewards differ at all.
    4. Group-normalised advantages (per rollout, or per policy call with ``credit`` reward-to-go;
       with ``credit`` critic, GAE against the critic, which is then fitted on the batch)
       and `minibatches` clipped policy-gradient steps; the learning
       rate schedule advances even when no group was kept, so steps and the schedule stay aligned.
       With ``learn_on`` replays or both, the update holds the actions to the frames their replays
       showed at each call (`gymnast.rl.reanchor`); the batch returned stays the rollouts' own.

    Args:
        env: the run's vector env with R = B * G rollouts.
        draw_starts: `draw(count, generator)` start states (`gymnast.envs.starts.StartSampler`).
        sampler: draws the start states and the env's reset seeds.
        actions: draws the policy's tokens.
        reference: the frozen starting policy of the KL penalty, or None.
        anchor: the imitation loss added to the update (`gymnast.rl.imitation`), or None; its
            demonstrations are drawn with `actions`.
        critic: the learned critic of ``credit`` critic (`gymnast.rl.critic`), else None; its fitting
            shuffles with `actions`.
        every_frame: False when neither the reward nor a video reads the frames inside a chunk: a
            simulator then renders only the frames the policy reads (`collect_rollouts`).
        sight: what the reward sees and where the truth it is held to comes from; None: the
            rollouts' own video, no truth measured.
        released: a context the policy's update runs in: a world model on a GPU releases its
            memory there (`gymnast.world_model.base.offloaded`).

    Returns:
        (the kept rollouts or None, their (R,) scores or None, metrics), the metrics including
        ``rollout/interactions``: the actions taken in every round, the replays that restored its
        keyframes included; ``rollout/replay_interactions``: those the reward's replays took;
        ``reward/truth_interactions``: the real actions spent measuring the truth.
    """
    groups, size = config.starts_per_step, config.group_size
    per_call = config.credit != "rollout"
    kept: list[Rollouts] = []
    kept_scores: list[torch.Tensor] = []
    kept_steps: list[torch.Tensor] = []  # (G, T) each, with per-call credit
    kept_replayed: list[torch.Tensor] = []  # (G, S, H, W, 3) each, with --learn-on replays or both
    values: dict[str, float] = {"rollout/interactions": 0, "rollout/replay_interactions": 0,
                                "reward/truth_interactions": 0, "time/rollout_s": 0.0, "time/policy_s": 0.0,
                                "time/reward_s": 0.0}
    for round_ in range(config.max_rounds):
        starts = draw_starts(groups, sampler)
        seed = int(torch.randint(2**31 - 1, (1,), generator=sampler))
        timer: dict[str, float] = {}
        began = time.perf_counter()
        rollouts = collect_rollouts(env, policy, [start for start in starts for _ in range(size)], config.temperature,
                                    actions, seed, calls=-(-config.horizon // policy.chunk_size), timer=timer,
                                    every_frame=every_frame)
        values["time/rollout_s"] += time.perf_counter() - began
        values["time/policy_s"] += timer.get("policy_s", 0.0)
        began = time.perf_counter()
        seen, replayed = sight.seen(rollouts) if sight is not None else (rollouts, 0)
        values["rollout/replay_interactions"] += replayed
        if config.learn_on != "own":  # the frames the replays showed at each call, for the update to read
            replayed_calls = reanchor.replay_observations(rollouts, seen, policy.chunk_size)
        if per_call:
            steps = score_groups(reward, seen, size, per_step=True)  # (R, T)
            scores = torch.nanmean(steps, dim=1)  # what score() gives
        else:
            scores = score_groups(reward, seen, size)  # (R,)
        values["time/reward_s"] += time.perf_counter() - began
        # A keyframe is restored by replaying its prefix in the env the rollout runs in.
        values["rollout/interactions"] += int(rollouts.lengths.sum()) + size * sum(len(s.prefix) for s in starts)
        if round_ == 0:  # the first round is an unbiased sample of the current policy
            finite = scores[torch.isfinite(scores)]
            values |= {"reward/mean": finite.mean().item() if len(finite) else float("nan"),
                       "reward/std": finite.std().item() if len(finite) > 1 else float("nan"),
                       "rollout/success": torch.nanmean(verdicts(seen, scores, reward)).item(),
                       "rollout/length": rollouts.lengths.float().mean().item()}
            if sight is not None:
                began = time.perf_counter()
                truth, spent = sight.truth(rollouts, seen, size)
                values["reward/truth_interactions"] += spent
                if torch.isfinite(truth).any():  # a reward's verdict is read only where there is a truth to hold it to
                    values |= reward_truth_metrics(reward_verdicts(reward, seen, scores, size), truth, scores, size)
                values["time/truth_s"] = time.perf_counter() - began
            if rollouts.disagreement is not None:
                values |= disagreement_metrics(rollouts, config)
        grouped = scores.view(groups, size)  # (B, G)
        if reward.binary:
            keep = grpo.keep_groups(grouped, config.keep_low, config.keep_high)
        else:
            keep = grpo.keep_varied_groups(grouped)
        for g in keep.nonzero().flatten().tolist()[: groups - len(kept)]:
            index = torch.arange(g * size, (g + 1) * size)
            kept.append(rollouts.select(index))
            if config.learn_on != "own":
                kept_replayed.append(replayed_calls[index])
            kept_scores.append(scores[index])
            if per_call:
                kept_steps.append(steps[index])
        # The kept groups are copies: the round's frames (gigabytes with several cameras) go now,
        # not when the next round's are already collected beside them.
        del rollouts, seen
        if len(kept) == groups:
            break
    values |= {"rollout/kept_groups": len(kept), "rollout/rounds": round_ + 1}

    batch, scores = (concat_rollouts(kept), torch.cat(kept_scores)) if kept else (None, None)
    kept.clear()  # the batch is a copy of them: one set of frames through the update
    updated = time.perf_counter()
    if batch is not None:
        rewards = scores  # the verdicts above (dynamic sampling, the watch) stay the reward's own
        if config.disagreement_penalty > 0 and batch.disagreement is None:
            raise ValueError("disagreement_penalty needs rollouts from a world-model ensemble, which report disagreement")
        if config.disagreement_penalty > 0:
            rewards = grpo.penalise_disagreement(scores, batch.disagreement, config.disagreement_penalty)
        advantages, advantage_metrics = grpo.group_advantages(rewards.view(-1, size), config.normalize_std)
        advantages = advantages.reshape(-1)  # (R,)
        with released():  # a world model on a GPU may give the update its memory
            if per_call:
                step_rewards = torch.cat(kept_steps)  # (R, T)
                if config.disagreement_penalty > 0:  # MOPO's own form: each imagined step's reward minus its uncertainty
                    step_rewards = step_rewards - config.disagreement_penalty * batch.disagreement
                returns = grpo.reward_to_go(step_rewards, policy.chunk_size, batch.tokens.shape[1])  # (R, S)
                if critic is not None:
                    advantages, critic_metrics = critic.advantages_and_fit(batch, returns, config.normalize_std, actions)
                    values |= critic_metrics
                else:
                    advantages = grpo.call_advantages(returns, batch.token_mask.any(-1), size, config.normalize_std)
            learned = batch  # what the update reads; the batch itself stays the rollouts' own (videos, the watch)
            if config.learn_on != "own":
                learned, advantages = reanchor.learning_batch(policy, batch, torch.cat(kept_replayed), advantages,
                                                              config.learn_on, config.temperature, config.micro_batch,
                                                              config.importance_cap)
            values |= advantage_metrics | update_policy(policy, optimizer, learned, advantages, config, reference,
                                                        anchor, actions)
    with warnings.catch_warnings():
        # The schedule counts RL steps, those whose rollouts left nothing to learn from included;
        # torch warns when it steps before any optimizer step, as the first such step does.
        warnings.filterwarnings("ignore", message="Detected call of `lr_scheduler.step\\(\\)` before")
        schedule.step()
    values["time/update_s"] = time.perf_counter() - updated
    return batch, scores, values


def disagreement_metrics(rollouts: Rollouts, config: RLConfig) -> dict[str, float]:
    """How far the world-model ensemble's members disagreed on the frames the rollouts showed.

    ``rollout/disagreement_mean`` over all shown frames, ``rollout/disagreement_max`` the mean over
    rollouts of each one's worst frame, ``rollout/stopped`` the share of rollouts the
    disagreement stop ended (an imagined rollout otherwise always reaches the horizon) and
    ``rollout/disagreement_penalty`` the mean penalty subtracted from the rewards.
    """
    shown = rollouts.disagreement.isfinite()  # (R, T)
    values = {"rollout/disagreement_mean": rollouts.disagreement[shown].mean().item() if shown.any() else float("nan")}
    worst = torch.where(shown, rollouts.disagreement, float("-inf")).amax(dim=1)[shown.any(dim=1)]  # (R',)
    values["rollout/disagreement_max"] = worst.mean().item() if len(worst) else float("nan")
    if config.disagreement_stop > 0:
        values["rollout/stopped"] = (rollouts.lengths < config.horizon).float().mean().item()
    if config.disagreement_penalty > 0:
        zeros = torch.zeros(len(rollouts.starts))
        penalty = -grpo.penalise_disagreement(zeros, rollouts.disagreement, config.disagreement_penalty)
        values["rollout/disagreement_penalty"] = penalty.mean().item()
    return values


def update_policy(policy, optimizer: torch.optim.Optimizer, batch: Rollouts, advantages: torch.Tensor,
                  config: RLConfig, reference=None, anchor: ImitationAnchor | None = None,
                  generator: torch.Generator | None = None) -> dict[str, float]:
    """`minibatches` clipped policy-gradient steps on the batch's policy calls; returns metrics.

    `advantages` is (R,), one per rollout, (R, S), one per policy call (per-call credit), or
    (R, S, N), one per token (re-anchoring weighted by importance, `gymnast.rl.reanchor`).
    Every policy call (r, s) that executed at least one action is a row; rows are processed in
    micro-batches whose gradients accumulate, normalised by the token count of the whole
    minibatch, so the step does not depend on `micro_batch`.
    """
    rows_r, rows_s = batch.token_mask.any(-1).nonzero(as_tuple=True)  # (M,) each
    totals: dict[str, float] = {}
    parts = torch.tensor_split(torch.arange(len(rows_r)), config.minibatches)
    for part in parts:
        total = int(batch.token_mask[rows_r[part], rows_s[part]].sum())
        if total == 0:
            continue
        optimizer.zero_grad(set_to_none=True)
        part_values: dict[str, float] = {}
        for micro in part.split(config.micro_batch):
            r, s = rows_r[micro], rows_s[micro]
            obs, texts, tokens, states = call_inputs(policy, batch, r, s)
            entropy = None
            if config.entropy_coef > 0:
                logp, entropy = policy.log_prob_and_entropy(obs, texts, tokens, config.temperature, **states)
            else:
                logp = policy.log_prob(obs, texts, tokens, config.temperature, **states)
            ref_logp = None
            if reference is not None:
                with torch.no_grad():
                    ref_logp = reference.log_prob(obs, texts, tokens, config.temperature, **states)
            advantage = advantages[r, s] if advantages.ndim >= 2 else advantages[r]  # (m,) or, per token, (m, N)
            old, advantage, mask = (to_device(x, logp.device) for x in (batch.logp[r, s], advantage,
                                                                          batch.token_mask[r, s]))
            loss, values = grpo.policy_loss(logp, old, advantage, mask,
                                            config.clip_low, config.clip_high, total, ref_logp, config.kl_coef,
                                            entropy, config.entropy_coef)
            loss.backward()
            for key, value in values.items():
                part_values[key] = part_values.get(key, 0.0) + value
        if anchor is not None:
            active = anchor.active(part_values.get("train/kl"))
            if active:
                imitation, values = anchor.loss(policy, generator)
                imitation.backward()
                part_values |= values
            part_values["train/imitation_active"] = float(active)
        for key, value in part_values.items():
            totals[key] = totals.get(key, 0.0) + value / len(parts)
        norm = torch.nn.utils.clip_grad_norm_(policy.parameters(), config.max_grad_norm).item()
        totals["train/grad_norm"] = totals.get("train/grad_norm", 0.0) + norm / len(parts)
        optimizer.step()
    totals["train/policy_calls"] = float(len(rows_r))
    return totals


def write_summary(out: Path, run_spec: RLRun, config: RLConfig, state: dict) -> dict:
    """RUN/summary.json: the run's env, reward, steps, success before and after, and the curve.

    Success is measured on the evaluation seeds in the run's own env (``start_success``,
    ``end_success``; None where the reward cannot tell success, as the verified reward on imagined
    video) and, when the run trained elsewhere, in the real world (``start_real_success``...).
    """
    first, last = state["curve"][0], state["curve"][-1]
    where = {"": "own", "_real": "own" if run_spec.env.real_sight else "real"}
    summary = {"env": run_spec.env.name, "reward": str(run_spec.reward), "reward_sees": run_spec.to_json()["reward_sees"],
               "steps": config.steps, "policy": run_spec.policy, "wm": run_spec.wm}
    for suffix, env in where.items():
        for moment, point in (("start", first), ("end", last)):
            summary[f"{moment}{suffix}_success"] = point.get(f"eval/{env}_success")
            summary[f"{moment}{suffix}_ci"] = [point.get(f"eval/{env}_ci_low"), point.get(f"eval/{env}_ci_high")]
    summary |= {
        "eval_episodes": first.get("eval/own_episodes"),
        "real_interactions": state["real_interactions"],
        "eval_real_interactions": state["eval_real_interactions"],
        "watch_real_interactions": state["watch_real_interactions"],
        "truth_real_interactions": state.get("truth_real_interactions", 0),
        "reset_frames": state.get("reset_frames", 0),
        "wall_s": state["wall_s"],
        "curve": state["curve"],
    }
    write_json(out / "summary.json", summary)
    return summary


def learning_parameters(policy: torch.nn.Module, freeze: tuple[str, ...]) -> list[torch.nn.Parameter]:
    """The parameters RL updates: all but those named by a `freeze` prefix, which stop taking
    gradients (so the backward pass skips them).

    Raises:
        ValueError: a prefix names no parameter, or nothing is left to learn.
    """
    named = dict(policy.named_parameters())

    def under(name: str, prefix: str) -> bool:
        return name == prefix or name.startswith(prefix.rstrip(".") + ".")

    for prefix in freeze:
        if not any(under(name, prefix) for name in named):
            parts = sorted({name.split(".")[0] for name in named})
            raise ValueError(f"RLConfig.freeze: the policy has no parameter named {prefix!r} or under it; "
                             f"its parts are {', '.join(parts)}")
    frozen = {name for name in named if any(under(name, prefix) for prefix in freeze)}
    if len(frozen) == len(named):
        raise ValueError(f"RLConfig.freeze ({', '.join(freeze)}) leaves the policy nothing to learn")
    for name, parameter in named.items():
        parameter.requires_grad_(name not in frozen)
    return [parameter for name, parameter in named.items() if name not in frozen]


def _frozen_copy(policy):
    reference = copy.deepcopy(policy).eval()
    reference.requires_grad_(False)
    return reference

