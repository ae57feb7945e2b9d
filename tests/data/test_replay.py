"""`gymnast collect --replay`: a recorded dataset's episodes again, in other cameras or at another size."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.data.collect import SETTINGS_FILE, CollectConfig, collect
from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.replay import check_replay, replay_dataset
from gymnast.data.schema import Episode, EpisodeColumns
from gymnast.envs.engine import ReplayActor, play_episode
from gymnast.envs.metaworld import MetaWorldEnv

SOURCE_ENV = EnvConfig(image_size=32, horizon=25, terminate_on_success=False)


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """Two scripted episodes (an expert and a random failure) of reach, front camera at 32 px,
    played to the horizon."""
    out = tmp_path_factory.mktemp("replay") / "source"
    collect(CollectConfig(tasks="reach-v3", episodes_per_task=1, failure_fraction=1.0, workers=1, env=SOURCE_ENV),
            out, progress=False)
    return out


def test_a_replay_in_two_cameras_at_another_size_is_the_same_episodes(source, tmp_path):
    out = tmp_path / "replayed"
    main(["collect", "--replay", str(source), "--out", str(out), "--cameras", "front,gripper",
          "--env.image-size", "48", "--workers", "1"])
    recorded, replayed = EpisodeDataset(source), EpisodeDataset(out, cameras=("front", "gripper"))
    assert sorted(info.key for info in replayed.episodes) == sorted(info.key for info in recorded.episodes)
    for i, info in enumerate(recorded.episodes):
        j = next(j for j, other in enumerate(replayed.episodes) if other.key == info.key)
        before, after = recorded.load(i), replayed.load(j)
        np.testing.assert_array_equal(after.actions, before.actions)
        np.testing.assert_array_equal(after.states, before.states)
        np.testing.assert_array_equal(after.successes, before.successes)
        assert after.info == before.info
        assert set(after.views) == {"front", "gripper"}
        assert after.views["front"].shape == (len(before.frames), 48, 48, 3)
    # The source's horizon and end at success are kept, whatever the command's defaults say.
    settings = out / SETTINGS_FILE
    assert '"terminate_on_success": false' in settings.read_text() and '"horizon": 25' in settings.read_text()


def test_a_rerun_resumes_and_other_cameras_are_refused(source, tmp_path):
    out = tmp_path / "replayed"
    config = CollectConfig(workers=1, env=EnvConfig(image_size=40))
    first = replay_dataset(source, out, config, progress=False)
    assert replay_dataset(source, out, config, progress=False) == first  # nothing left to record
    assert len(EpisodeDataset(out)) == len(EpisodeDataset(source))
    with pytest.raises(ValueError, match="cameras front"):
        replay_dataset(source, out, dataclasses.replace(config, env=EnvConfig(image_size=40, cameras=("front", "hand"))),
                       progress=False)


def test_a_replay_that_departs_from_its_recording_is_refused_by_name(source):
    recording = EpisodeDataset(source).columns(0)
    env = MetaWorldEnv(recording.info.task, dataclasses.replace(SOURCE_ENV, image_size=16))
    pushed = recording.actions.copy()
    pushed[5:] = np.clip(pushed[5:] + 0.5, -1, 1)  # another episode from step 5 on
    run = play_episode(env, ReplayActor(pushed), recording.info.seed, record=("states", "successes"))
    episode = dataclasses.replace(_as_episode(recording), states=np.stack(run.states))
    with pytest.raises(ValueError, match=r"episode 0 .*departs from its recording at step [6-9]"):
        check_replay(episode, recording, "episode 0 (reach)")
    shorter = _as_episode(recording, steps=len(recording.actions) - 1)
    with pytest.raises(ValueError, match="ended after 24 of its 25"):
        check_replay(shorter, recording, "episode 0 (reach)")


def test_only_a_dataset_gymnast_recorded_can_be_replayed(source, tmp_path, capsys):
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    with pytest.raises(FileNotFoundError, match="gymnast_collect.json is missing"):
        replay_dataset(foreign, tmp_path / "out", CollectConfig(workers=1), progress=False)
    with pytest.raises(ValueError, match="into itself"):
        replay_dataset(source, source, CollectConfig(workers=1), progress=False)
    with pytest.raises(SystemExit):
        main(["collect", "--replay", str(source), "--out", str(tmp_path / "x"), "--policy", str(source)])
    assert "takes no --policy" in capsys.readouterr().err


def _as_episode(columns: EpisodeColumns, steps: int | None = None) -> Episode:
    """The recording as an episode of blank frames, cut to its first `steps` actions."""
    steps = len(columns.actions) if steps is None else steps
    return Episode(frames=np.zeros((steps + 1, 16, 16, 3), np.uint8), states=columns.states[:steps + 1],
                   env_states=columns.env_states[:steps + 1], actions=columns.actions[:steps],
                   rewards=columns.rewards[:steps], successes=columns.successes[:steps], info=columns.info)
