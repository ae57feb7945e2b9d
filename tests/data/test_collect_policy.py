"""`gymnast collect --policy`: a learned policy's own rollouts recorded as collect's episodes."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, EpisodeJob, plan_episodes, record_episode
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import POLICY, EpisodeInfo, behaviour_kind, policy_behaviour
from gymnast.envs.engine import run_batch
from gymnast.envs.experts import make_behaviour
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.envs.metaworld import MetaWorldEnv
from gymnast.eval.actors import ImaginedPlanActor, PolicyActor
from gymnast.eval.record import PolicyActors, policy_tag, record_policy
from gymnast.policy.load import load_policy
from gymnast.world_model.base import load_world_model

RUN = Path(__file__).resolve().parents[2] / "results" / "sft" / "policy"
ENV = EnvConfig(image_size=96, horizon=20)  # the committed policy sees 96x96 images
CONFIG = CollectConfig(tasks="reach-v3", episodes_per_task=2, noise=(0.0, 0.3), workers=1, env=ENV)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Path, dict]:
    """A greedy episode (seed 0) and a noisy one (seed 1, noise 0.3) of the committed policy."""
    out = tmp_path_factory.mktemp("policy_data")
    return out, record_policy(RUN, CONFIG, out, progress=False)


def _greedy_chunk(policy, frame: np.ndarray, instruction: str) -> np.ndarray:
    with torch.inference_mode():
        return policy.act(torch.from_numpy(frame)[None], [instruction])[0].numpy()  # (K, A)


def test_policy_rollouts_are_episodes_with_every_step_and_behaviour_policy(recorded):
    out, table = recorded
    dataset = EpisodeDataset(out)
    behaviour = policy_behaviour(policy_tag(RUN, 0.0))
    assert [(info.behaviour, info.noise, info.seed) for info in dataset.episodes] == [
        (behaviour, 0.0, 0), (behaviour, 0.3, 1)]
    assert all(behaviour_kind(info.behaviour) == POLICY for info in dataset.episodes)
    assert table == {"reach-v3": {behaviour: [sum(info.success for info in dataset.episodes), 2]}}
    for i, info in enumerate(dataset.episodes):
        episode = dataset.load(i)
        assert episode.frames.shape == (episode.length + 1, 96, 96, 3)
        assert episode.env_states.shape == (episode.length + 1, 39) and episode.rewards.shape == (episode.length,)
        assert episode.successes.dtype == bool and episode.successes.shape == (episode.length,)
        assert info.success == episode.successes.any()
        # Success ends an episode (terminate_on_success is on), otherwise the horizon does.
        assert episode.length == (int(np.argmax(episode.successes)) + 1 if info.success else ENV.horizon)


def test_greedy_episodes_hold_the_policys_chunks_and_noisy_ones_depart_from_them(recorded):
    out, _ = recorded
    dataset = EpisodeDataset(out)
    policy = load_policy(RUN)
    k = policy.chunk_size
    actors = PolicyActors(str(RUN.resolve()), 0.0, policy_behaviour(policy_tag(RUN, 0.0)))
    jobs = {job.key: job for job in plan_episodes(CONFIG, actors.behaviour)}
    for i, info in enumerate(dataset.episodes):
        stored = dataset.load(i)
        fresh = record_episode(jobs[info.key], actors)  # the same recipe replays exactly
        np.testing.assert_array_equal(stored.actions, fresh.actions)
        np.testing.assert_array_equal(stored.states, fresh.states)
        assert np.abs(fresh.actions).max() <= 1.0
        departed = False
        for t in range(0, fresh.length, k):  # the policy is asked at every chunk start only
            chunk = fresh.actions[t:t + k]
            greedy = _greedy_chunk(policy, fresh.frames[t], info.instruction)[:len(chunk)]
            if info.noise == 0:
                np.testing.assert_array_equal(chunk, greedy)
                # The decoded video frames are within the codec's error of the raw ones, so they
                # lead to the same chunk, give or take one action bin.
                decoded = _greedy_chunk(policy, stored.frames[t], info.instruction)[:len(chunk)]
                np.testing.assert_allclose(decoded, chunk, rtol=0, atol=2 / (policy.tokenizer.bins - 1) + 1e-6)
            departed |= not np.array_equal(chunk, greedy)
        assert departed == (info.noise > 0)


def test_a_rerun_records_nothing_new_and_another_temperature_is_another_behaviour(recorded, tmp_path: Path):
    out, _ = recorded
    copy = tmp_path / "data"
    shutil.copytree(out, copy)
    before = EpisodeDataset(copy)
    record_policy(RUN, CONFIG, copy, progress=False)
    after = EpisodeDataset(copy)
    assert after.info["total_frames"] == before.info["total_frames"]
    assert [info.key for info in after.episodes] == [info.key for info in before.episodes]
    sampled = CollectConfig(tasks="reach-v3", episodes_per_task=1, noise=(0.0,), workers=1, env=ENV)
    table = record_policy(RUN, sampled, copy, temperature=1.0, progress=False)
    hot = policy_behaviour(policy_tag(RUN, 1.0))
    assert hot != policy_behaviour(policy_tag(RUN, 0.0)) and table["reach-v3"][hot][1] == 1
    assert len(EpisodeDataset(copy)) == 3


WM = RUN.parents[1] / "world_model" / "wm"


def test_a_plan_made_in_imagination_is_the_policys_closed_loop_imagined_rollout_executed_for_real(tmp_path: Path):
    config = CollectConfig(tasks="reach-v3", episodes_per_task=1, noise=(0.0,), workers=1, env=ENV)
    table = record_policy(RUN, config, tmp_path / "data", progress=False, imagine_with=WM)
    planned = policy_behaviour(policy_tag(RUN, 0.0, WM))
    assert planned != policy_behaviour(policy_tag(RUN, 0.0)) and table["reach-v3"][planned][1] == 1
    episode = EpisodeDataset(tmp_path / "data").load(0)
    # The recorded actions are what the greedy policy chose looking at imagined frames only.
    policy, world_model = load_policy(RUN), load_world_model(WM)
    env = MetaWorldEnv("reach-v3", ENV)
    obs, _ = env.reset(seed=0)
    imagination = BatchedImaginedEnv(world_model, 1, policy.chunk_size, ENV.horizon)
    start = {"frames": obs["image"][None], "instructions": [env.instruction]}
    with torch.inference_mode():
        chunks = [result.actions[0, : result.frames.shape[1]] for result in run_batch(
            imagination, lambda images, instructions, states: _greedy_chunk(policy, images[0], env.instruction)[None], start)]
    np.testing.assert_array_equal(episode.actions, np.concatenate(chunks)[:episode.length])
    # ... and the real world executed them from the same scene (every step, open-loop).
    for action, state in zip(episode.actions, episode.states[1:]):
        obs, *_ = env.step(action)
        np.testing.assert_allclose(obs["state"], state, rtol=0, atol=1e-6)
    env.close()


def test_a_plan_that_runs_out_before_the_episode_ends_is_an_error():
    env = MetaWorldEnv("reach-v3", ENV)
    obs, _ = env.reset(seed=0)
    actor = ImaginedPlanActor(PolicyActor(load_policy(RUN)), load_world_model(WM), horizon=5)
    assert actor(env, obs).shape == (5, 4)
    with pytest.raises(ValueError, match="imagined plan of 5 actions ran out"):
        actor(env, obs)
    with pytest.raises(ValueError, match="horizon >= 1"):
        ImaginedPlanActor(PolicyActor(load_policy(RUN)), load_world_model(WM), horizon=0)
    env.close()


def test_the_env_image_size_must_be_the_policys_and_the_temperature_non_negative(tmp_path: Path):
    small = CollectConfig(tasks="reach-v3", episodes_per_task=1, workers=1, env=EnvConfig(image_size=32, horizon=20))
    with pytest.raises(ValueError, match=r"96x96 images but env.image_size is 32"):
        record_policy(RUN, small, tmp_path / "data", progress=False)
    with pytest.raises(ValueError, match="temperature must be"):
        record_policy(RUN, CONFIG, tmp_path / "data", temperature=-1.0, progress=False)
    assert not (tmp_path / "data").exists()  # refused before anything was written


def test_cli_refuses_evaluation_seeds_and_a_temperature_without_a_policy(tmp_path: Path, capsys):
    args = ["collect", "--out", str(tmp_path / "data"), "--tasks", "reach-v3", "--env.horizon", "20"]
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--policy", str(RUN), "--first-seed", "1000000"])
    assert exit_info.value.code == 2 and "evaluation seeds are never recorded" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--temperature", "0.5"])
    assert exit_info.value.code == 2 and "--policy" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--imagine-with", str(WM)])
    assert exit_info.value.code == 2 and "--policy" in capsys.readouterr().err
    assert not (tmp_path / "data").exists()


@pytest.mark.slow
def test_cli_records_a_policy_in_worker_processes(tmp_path: Path, capsys):
    out = tmp_path / "data"
    main(["collect", "--policy", str(RUN), "--out", str(out), "--tasks", "reach-v3", "--episodes-per-task", "2",
          "--noise", "0", "--workers", "2", "--env.horizon", "10"])
    assert policy_behaviour(policy_tag(RUN, 0.0)) in capsys.readouterr().out
    dataset = EpisodeDataset(out)
    assert sorted(info.seed for info in dataset.episodes) == [0, 1]
    assert all(behaviour_kind(info.behaviour) == POLICY for info in dataset.episodes)


def test_scripted_episodes_still_take_one_action_per_step_from_the_simulator_state():
    job = EpisodeJob("reach-v3", "noisy_expert", 0.3, 3, "none", EnvConfig(image_size=32, horizon=30))
    episode = record_episode(job)
    # The loop collect ran before actors existed: one behaviour call per step.
    env = MetaWorldEnv(job.task, job.env)
    act = make_behaviour(job.behaviour, job.task, job.noise, job.seed)
    obs, _ = env.reset(seed=job.seed)
    frames, actions, done = [obs["image"]], [], False
    while not done:
        actions.append(act(env.env_state))
        obs, _, terminated, truncated, _ = env.step(actions[-1])
        frames.append(obs["image"])
        done = terminated or truncated
    env.close()
    np.testing.assert_array_equal(episode.actions, np.stack(actions))
    np.testing.assert_array_equal(episode.frames, np.stack(frames))


def test_a_policy_plan_cycles_noise_levels_without_failures_and_scripted_plans_keep_theirs():
    config = CollectConfig(tasks="reach-v3,push-v3", episodes_per_task=3, noise=(0.0, 0.3), failure_fraction=0.5)
    jobs = plan_episodes(config, "policy-9ed3de35")
    assert [(j.task, j.behaviour, j.noise, j.seed) for j in jobs[:3]] == [
        ("reach-v3", "policy-9ed3de35", 0.0, 0), ("reach-v3", "policy-9ed3de35", 0.3, 1),
        ("reach-v3", "policy-9ed3de35", 0.0, 2)]
    assert len(jobs) == 6 and {j.behaviour for j in jobs} == {"policy-9ed3de35"}
    scripted = plan_episodes(config)
    assert [j.behaviour for j in scripted if j.task == "push-v3"] == [
        "expert", "noisy_expert", "expert", "random", "wrong_task_expert"]


def test_policy_behaviours_carry_a_tag_and_others_are_refused():
    assert policy_behaviour("9ed3de35") == "policy-9ed3de35"
    kinds = [behaviour_kind(b) for b in ("policy", "policy-9ed3de35", "noisy_expert")]
    assert kinds == [POLICY, POLICY, "noisy_expert"]
    info = dict(task="reach-v3", instruction="reach", success=False, noise=0.0, seed=0)
    assert EpisodeInfo(behaviour="policy-9ed3de35", **info).key == "real/reach-v3/policy-9ed3de35/0/0"
    for bad in ("policy-", "policy-A/B", "robot"):
        with pytest.raises(ValueError, match="behaviour"):
            EpisodeInfo(behaviour=bad, **info)
    with pytest.raises(ValueError, match="tag"):
        policy_behaviour("x/y")
