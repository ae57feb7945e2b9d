"""A world model of one imagined frame per action chunk (`actions_per_frame`): one latent step per
chunk of the policy's actions, the chunk's other frames repeating the last imagined one."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from gymnast.cli import main
from gymnast.envs.imagined import BatchedImaginedEnv
from gymnast.world_model.base import actions_per_frame, imagined_frame_mask, load_world_model, rollout
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig
from gymnast.world_model.ensemble import EnsembleWorldModel
from gymnast.world_model.train import WM_PRESETS, future_at, train_world_model
from gymnast.world_model.views import MultiViewWorldModel

TINY = dict(image_size=16, latent_channels=8, widths=(8, 8), blocks=1, action_width=8, bf16=False, reanchor_every=8)
CONTEXT = torch.randint(0, 256, (2, 2, 16, 16, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
ACTIONS = torch.rand(2, 12, 4, generator=torch.Generator().manual_seed(2)) * 2 - 1


def chunked(n: int = 5, trained_mixer: bool = True) -> EmbeddedWorldModel:
    torch.manual_seed(0)
    model = EmbeddedWorldModel(EmbeddedWorldModelConfig(**TINY, actions_per_frame=n)).eval()
    with torch.no_grad():  # trained blocks respond to their condition; fresh ones start as the identity
        for block in model.blocks:
            block.conv2.weight.normal_(0, 0.3)
        if trained_mixer and model.mix_chunk is not None:
            model.mix_chunk.weight.normal_(0, 0.3)
    return model


def test_one_frame_per_chunk_is_imagined_and_the_chunks_other_frames_repeat_the_last_one():
    model = chunked()
    frames = rollout(model, CONTEXT, ACTIONS).frames  # (2, 12, H, W, 3): chunks end after actions 5 and 10
    assert torch.equal(frames[:, 0], CONTEXT[:, -1]) and all(torch.equal(frames[:, t], frames[:, 0]) for t in range(4))
    assert not torch.equal(frames[:, 4], frames[:, 3]) and not torch.equal(frames[:, 9], frames[:, 8])
    assert all(torch.equal(frames[:, t], frames[:, 4]) for t in range(5, 9))
    assert torch.equal(frames[:, 10], frames[:, 9]) and torch.equal(frames[:, 11], frames[:, 9])  # a chunk not complete
    assert imagined_frame_mask(model, 12).nonzero().view(-1).tolist() == [4, 9]
    # Actions given a few at a time wait for their chunk: the same frames as all at once.
    state, pieces, done = model.init_state(CONTEXT), [], 0
    for count in (3, 4, 1, 4):
        state, piece = model.step(state, ACTIONS[:, done : done + count])
        pieces.append(piece)
        done += count
    assert torch.equal(torch.cat(pieces, dim=1), frames)
    assert state.pending.shape == (2, 2, 4) and state.select(slice(0, 1)).pending.shape == (1, 2, 4)
    # The order of a chunk's actions matters once the mixer is trained; a fresh one takes their mean.
    swapped = ACTIONS[:, [1, 0, 2, 3, 4]]
    assert not torch.equal(rollout(model, CONTEXT, swapped).frames[:, 4], frames[:, 4])
    fresh = chunked(trained_mixer=False)
    assert torch.equal(rollout(fresh, CONTEXT, swapped).frames[:, 4], rollout(fresh, CONTEXT, ACTIONS[:, :5]).frames[:, 4])


def test_one_frame_per_action_is_the_default_and_wrappers_and_errors_name_the_chunk():
    assert actions_per_frame(chunked(n=1)) == 1 and bool(imagined_frame_mask(chunked(n=1), 5).all())
    assert chunked(n=1).mix_chunk is None
    model = chunked()
    views = MultiViewWorldModel(model, ("front", "gripper"))
    assert views.actions_per_frame == 5
    frames = views.step(views.init_state(CONTEXT.repeat(1, 1, 1, 2, 1)), ACTIONS)[1]
    assert frames.shape == (2, 12, 16, 32, 3)
    assert EnsembleWorldModel([model, chunked()]).actions_per_frame == 5
    with pytest.raises(ValueError, match=r"the members' actions_per_frame differ: \[5, 1\]"):
        EnsembleWorldModel([model, chunked(n=1)])
    with pytest.raises(ValueError, match="grounded model .* actions_per_frame must be 1, got 5"):
        EmbeddedWorldModelConfig(**TINY, actions_per_frame=5, state_dim=3, state_mean=(0.0,) * 3, state_std=(1.0,) * 3)
    with pytest.raises(ValueError, match="actions_per_frame must be at least 1, got 0"):
        EmbeddedWorldModelConfig(**TINY, actions_per_frame=0)


def test_the_imagined_env_shows_the_policy_each_chunks_imagined_frame():
    model = chunked()
    env = BatchedImaginedEnv(model, 2, chunk_size=5, horizon=12)
    start = CONTEXT[:, -1].numpy()
    env.reset(seed=0, options={"frames": start, "instructions": ["reach the goal"] * 2})
    actions = ACTIONS.numpy()
    for first in (0, 5, 10):
        observation, *_ = env.step(np.ascontiguousarray(actions[:, first : first + 5]) if first < 10
                                   else np.pad(actions[:, 10:], ((0, 0), (0, 3), (0, 0))))
    expected = rollout(model, torch.from_numpy(start)[:, None], ACTIONS).frames.numpy()
    np.testing.assert_array_equal(env.video()[:, 1:], expected)
    with pytest.raises(ValueError, match="one frame per 5 actions; a policy chunk of 4 actions"):
        BatchedImaginedEnv(model, 2, chunk_size=4, horizon=12)


def test_train_wm_fine_tunes_a_model_of_one_frame_per_chunk_from_one_per_action_and_eval_wm_measures_its_frames(
        tiny_dataset, tmp_path):
    config = dataclasses.replace(WM_PRESETS["debug"], heldout_fraction=0.25)
    train_world_model(tiny_dataset, tmp_path / "plain", config, progress=False)
    model_config = dataclasses.replace(config.model, actions_per_frame=5)
    tuned = dataclasses.replace(config, init=tmp_path / "plain", model=model_config)
    assert [future_at(step, dataclasses.replace(tuned, future=12, steps=10)) for step in (0, 9)] == [5, 15]
    train_world_model(tiny_dataset, tmp_path / "tuned", tuned, progress=False)
    model = load_world_model(tmp_path / "tuned")
    assert model.actions_per_frame == 5
    plain = load_world_model(tmp_path / "plain")
    assert not torch.equal(model.encode_fine[0].weight, plain.encode_fine[0].weight)  # trained on from its weights
    logged = [json.loads(line) for line in (tmp_path / "tuned" / "metrics.jsonl").read_text().splitlines()]
    assert any("wm/val_psnr_h5" in row for row in logged)
    out = tmp_path / "eval.json"
    main(["eval-wm", "--wm", str(tmp_path / "tuned"), "--data", str(tiny_dataset), "--out", str(out), "--videos", "0",
          "--control-scenes", "1"])
    report = json.loads(out.read_text())
    # Measured on the frames it imagines (after actions 5, 10, ...), not on their repeats, each horizon
    # at the first imagined frame at or after it; a model of one frame per action on the same frames when asked.
    assert report["psnr_h1"] > 0 and report["psnr_full"] > 0 and report["copy_last_psnr_h1"] > 0
    main(["eval-wm", "--wm", str(tmp_path / "plain"), "--data", str(tiny_dataset), "--out", str(out), "--videos", "0",
          "--control-scenes", "0", "--measure-every", "5"])
    same_frames = json.loads(out.read_text())
    assert same_frames["copy_last_psnr_full"] == report["copy_last_psnr_full"]
    assert same_frames["copy_last_psnr_h1"] == report["copy_last_psnr_h1"]  # both at the 5th action's frame
