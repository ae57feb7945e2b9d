"""The embedded policies that read the robot's state beside their images (`PolicyArchitecture.state_dim`)."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from gymnast.cli import main
from gymnast.policy.flow_vla import FlowVLA, FlowVLAConfig
from gymnast.policy.load import load_policy
from gymnast.policy.vla import EmbeddedVLA, VLAConfig
from gymnast.utils.metrics import read_metrics

TINY = dict(width=32, layers=1, heads=2, image_size=32, state_dim=4)


def _family(name: str):
    if name == "tokens":
        return EmbeddedVLA(VLAConfig(**TINY), pretrained_vision=False)
    return FlowVLA(FlowVLAConfig(**TINY), pretrained_vision=False)


@pytest.mark.parametrize("family", ["tokens", "flow"])
def test_a_state_reading_policy_acts_on_the_state_and_scores_its_samples_with_it(family):
    policy = _family(family).eval()
    generator = torch.Generator().manual_seed(0)
    images = torch.randint(0, 256, (2, 32, 32, 3), dtype=torch.uint8, generator=generator)
    texts = ["reach the goal"] * 2
    states = torch.tensor([[0.0, 0.6, 0.2, 1.0], [0.1, 0.7, 0.1, 0.0]])
    policy.standardise_states(torch.randn(50, 4, generator=generator) * 0.1)
    assert policy.memory(images, policy.embed_instructions(texts, 2), states=states).shape == (2, 2 + 4, 32)

    drawn = policy.sample(images, texts, temperature=1.0, generator=generator, states=states)
    torch.testing.assert_close(policy.log_prob(images, texts, drawn.tokens, states=states), drawn.logp)
    assert not torch.allclose(policy.log_prob(images, texts, drawn.tokens, states=states.flip(0)), drawn.logp)
    assert not torch.allclose(policy.act(images, texts, states), policy.act(images, texts, states.flip(0)))
    with pytest.raises(ValueError, match=r"reads the robot's state \(4 dimensions\) and was given none"):
        policy.act(images, texts)
    with pytest.raises(ValueError, match=r"states must be \(2, 4\), got \(2, 3\)"):
        policy.act(images, texts, states[:, :3])


def test_sft_with_the_robot_state_makes_a_policy_that_eval_and_real_rl_give_the_simulators_state(tiny_dataset, tmp_path):
    run, report = tmp_path / "run", tmp_path / "eval.json"
    main(["sft", "--data", str(tiny_dataset), "--out", str(run), "--preset", "debug", "--robot-state", "True"])
    policy = load_policy(run)
    assert policy.state_dim == 4 and policy.config.state_dim == 4  # hand xyz and gripper, as the dataset records them
    assert 0.3 < policy.state_mean[1] < 1.0  # standardised by the demonstrations' states (y: in front of the robot)
    main(["sft", "--out", str(run), "--resume"])  # the setting comes from the run
    main(["eval", "--policy", str(run), "--tasks", "reach-v3", "--episodes", "1", "--workers", "1",
          "--env.horizon", "10", "--out", str(report)])
    assert json.loads(report.read_text())["episodes"] == 1

    out = tmp_path / "rl"
    main(["rl", "--policy", str(run), "--data", str(tiny_dataset), "--preset", "debug", "--steps", "1",
          "--watch-every", "0", "--imitation-coef", "0.5", "--env", "real", "--reward", "sim-dense", "--horizon", "10",
          "--no-real-eval", "--out", str(out)])
    update = next(m for m in read_metrics(out) if "train/policy_calls" in m)
    # Each call is re-scored with the state it was sampled in, and the anchor reads the demonstrations' states.
    assert update["train/ratio"] == pytest.approx(1.0, abs=1e-4) and update["train/imitation_loss"] > 0


def test_robot_state_on_a_dataset_without_one_is_refused_by_name(tiny_dataset):
    from gymnast.data.lerobot import EpisodeDataset
    from gymnast.policy.sft import load_demos, state_dim_of

    demos = load_demos(EpisodeDataset(tiny_dataset), [0], chunk_size=5)
    assert state_dim_of(tiny_dataset, demos) == 4
    stateless = dataclasses.replace(demos, states=demos.states[:, :0])  # as a LeRobot dataset without observation.state
    with pytest.raises(ValueError, match=r"demos0 records no robot state \(observation.state\)"):
        state_dim_of(tiny_dataset, stateless)
