"""The grounded state model: it learns the recorded states and rewards, saves and loads exactly,
resumes, and its reward head scores rollouts from their start states and actions."""

from __future__ import annotations

import json

import pytest
import torch

from gymnast.data.lerobot import EpisodeDataset
from gymnast.policy.text import InstructionEncoder
from gymnast.reward.base import RewardContext
from gymnast.reward.state_reward import StateReward
from gymnast.world_model.state_model import (StateModel, StateModelConfig, load_state_model, load_state_models,
                                             write_state_ensemble)
from gymnast.world_model.train_state import StateTrainConfig, episode_tensors, state_loss, train_state_model


@pytest.fixture(scope="module")
def state_run(tiny_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("state")
    # 100 steps bring the loss below a twentieth of the untrained model's; one step leaves it above half.
    train_state_model(tiny_dataset, out, StateTrainConfig(steps=100, batch_size=32, unroll=8, heldout_fraction=0.0,
                                                          checkpoint_every=50), progress=False)
    return out


def test_training_lowers_the_loss_on_the_recorded_episodes(tiny_dataset, state_run):
    dataset = EpisodeDataset(tiny_dataset)
    episodes = episode_tensors(dataset, list(range(len(dataset))), InstructionEncoder())
    index = torch.arange(len(episodes.lengths)).repeat(8)
    times = torch.arange(len(index)) % 40
    batch = episodes.windows(index, times, 8)
    trained = load_state_model(state_run)
    untrained = StateModel(trained.config)
    untrained.load_state_dict({k: v for k, v in trained.state_dict().items() if "mean" in k or "std" in k}, strict=False)
    with torch.no_grad():
        before, _ = state_loss(untrained, batch, episodes.embedding[index])
        after, _ = state_loss(trained, batch, episodes.embedding[index])
    assert after < 0.5 * before


def test_a_saved_state_model_imagines_exactly_what_it_did_before(state_run):
    first, second = load_state_model(state_run), load_state_model(state_run)
    start, actions, text = torch.randn(3, first.config.state_dim), torch.rand(3, 5, 4) * 2 - 1, torch.randn(3, 384)
    a, b = first.imagine(start, actions, text), second.imagine(start, actions, text)
    assert torch.equal(a.states, b.states) and torch.equal(a.rewards, b.rewards)
    assert a.states.shape == (3, 5, first.config.state_dim) and a.success.shape == (3, 5)


def test_a_resumed_run_goes_on_from_its_last_checkpoint(tiny_dataset, state_run, tmp_path):
    saved = json.loads((state_run / "config.json").read_text())
    assert saved["train"]["steps"] == 100 and (state_run / "checkpoints" / "000050").is_dir()
    out = tmp_path / "again"
    config = StateTrainConfig(steps=50, batch_size=32, unroll=8, heldout_fraction=0.0, checkpoint_every=50)
    train_state_model(tiny_dataset, out, config, progress=False)
    longer = StateTrainConfig(steps=100, batch_size=32, unroll=8, heldout_fraction=0.0, checkpoint_every=50)
    train_state_model(tiny_dataset, out, longer, resume=True, progress=False)
    steps = [json.loads(line)["step"] for line in (out / "metrics.jsonl").read_text().splitlines()]
    # metrics every 50 steps: step 0 from the first run, step 50 from the resumed one, none twice
    assert steps == [0, 50] and (out / "checkpoints" / "000100").is_dir()


def test_the_reward_head_scores_rollouts_from_their_start_states_and_actions(state_run):
    reward = StateReward(load_state_model(state_run))
    states = torch.randn(4, reward.models[0].config.state_dim)
    actions = torch.zeros(4, 6, 4)
    context = RewardContext(start_state=states, actions=actions)
    frames = torch.zeros(4, 7, 8, 8, 3, dtype=torch.uint8)
    scores = reward.score(frames, ["reach the goal"] * 4, context)
    assert scores.shape == (4,) and ((0 <= scores) & (scores <= 1)).all()
    assert reward.verdict(["reach the goal"] * 4, context).shape == (4,)
    with pytest.raises(ValueError, match="start_state"):
        reward.score(frames, ["reach the goal"] * 4, RewardContext())
    with pytest.raises(ValueError, match="do not fit"):
        reward.score(frames, ["reach the goal"] * 4, RewardContext(start_state=states[:, :3], actions=actions))


def test_on_a_simulators_rollouts_the_reward_head_reads_the_real_states_held_after_the_end(state_run):
    reward = StateReward(load_state_model(state_run))
    model, words = reward.models[0], ["reach the goal"] * 2
    start = torch.randn(2, model.config.state_dim)
    real = torch.randn(2, 5, model.config.state_dim)
    real[1, 3:] = float("nan")  # the second rollout ended (a success) after 3 actions
    context = RewardContext(start_state=start, actions=torch.zeros(2, 5, 4), env_states=real)
    read = reward.imagine(words, context)[0]
    held = real.clone()
    held[1, 3:] = real[1, 2]  # the world stays where the episode ended
    expected = model.read(start, held, reward.encoder(words))
    assert torch.equal(read.states, held) and torch.allclose(read.rewards, expected.rewards)
    imagined = reward.imagine(words, RewardContext(start_state=start, actions=torch.zeros(2, 5, 4)))[0]
    assert not torch.allclose(imagined.states, held)  # without real states, the model's own dynamics
    with pytest.raises(ValueError, match="simulator's states"):
        reward.score(torch.zeros(2, 6, 8, 8, 3, dtype=torch.uint8), words,
                     RewardContext(start_state=start, actions=torch.zeros(2, 5, 4), env_states=real[..., :3]))


def test_sizes_that_cannot_build_a_model_are_refused():
    with pytest.raises(ValueError, match="hidden"):
        StateModelConfig(hidden=0)
    with pytest.raises(ValueError, match="unroll"):
        StateTrainConfig(unroll=0)


def test_extra_datasets_train_together_and_are_saved_with_the_run(tiny_dataset, tmp_path):
    config = StateTrainConfig(steps=2, batch_size=4, unroll=2, heldout_fraction=0.0, extra_data=(tiny_dataset,))
    train_state_model(tiny_dataset, tmp_path / "both", config, progress=False)
    saved = json.loads((tmp_path / "both" / "config.json").read_text())
    assert saved["train_episodes"] == 2 * len(EpisodeDataset(tiny_dataset))
    assert saved["train"]["extra_data"] == [str(tiny_dataset)]


def _saved(tmp_path, name, seed, **sizes):
    from gymnast.utils.checkpoint import save_checkpoint

    torch.manual_seed(seed)
    model = StateModel(StateModelConfig(**{"state_dim": 5, "hidden": 8, "layers": 1} | sizes))
    torch.nn.init.normal_(model.reward_head[-1].weight)  # a head that says something, differently per seed
    save_checkpoint(tmp_path / name, 1, model, {"model": model.spec()})
    return tmp_path / name


def test_an_ensemble_of_state_models_averages_rewards_and_counts_only_agreed_successes(tmp_path):
    members = [_saved(tmp_path, f"s{seed}", seed) for seed in range(3)]
    write_state_ensemble(tmp_path / "ensemble", members)
    models = load_state_models(tmp_path / "ensemble")
    assert len(models) == 3 and len(load_state_models(members[0])) == 1
    context = RewardContext(start_state=torch.randn(6, 5), actions=torch.rand(6, 4, 4) * 2 - 1)
    frames, sentences = torch.zeros(6, 5, 8, 8, 3, dtype=torch.uint8), ["reach the goal"] * 6
    ensemble, alone = StateReward(models), [StateReward(model) for model in models]
    rollouts = ensemble.imagine(sentences, context)
    agreed = torch.stack([r.success for r in rollouts]).amin(dim=0) > 0.5
    assert torch.equal(ensemble.verdict(sentences, context), agreed.any(dim=1).float())
    # a success counts only where every member sees it: never more verdicts than any one member's
    assert (ensemble.verdict(sentences, context) <= torch.stack([r.verdict(sentences, context) for r in alone]).amin(0)).all()
    scores = ensemble.score(frames, sentences, context)
    assert scores.shape == (6,) and ((0 <= scores) & (scores <= 1)).all()
    steps = ensemble.step_rewards(frames, sentences, context)  # what per-call credit shares out
    assert steps.shape == (6, 4) and torch.allclose(steps.mean(dim=1), scores)
    assert ensemble.metrics()["reward/state_disagreement"] > 0 and alone[0].metrics() == {}


def test_an_ensemble_refuses_members_that_do_not_fit_together(tmp_path):
    members = [_saved(tmp_path, "five", 0), _saved(tmp_path, "six", 1, state_dim=6)]
    with pytest.raises(ValueError, match="different"):
        write_state_ensemble(tmp_path / "ensemble", members)
    with pytest.raises(ValueError, match="two or more"):
        write_state_ensemble(tmp_path / "ensemble", members[:1])
    assert not (tmp_path / "ensemble" / "ensemble.json").exists()


def test_make_ensemble_over_state_runs_gives_a_state_reward(tmp_path, capsys):
    from gymnast.cli import main
    from gymnast.reward.select import make_reward
    from gymnast.reward.spec import RewardSpec

    members = [str(_saved(tmp_path, f"s{seed}", seed)) for seed in range(2)]
    main(["make-ensemble", "--members", *members, "--out", str(tmp_path / "ensemble")])
    assert "ensemble of 2 state models" in capsys.readouterr().out
    assert len(make_reward(RewardSpec.parse(f"state:{tmp_path / 'ensemble'}")).models) == 2
