"""Rewards are named by a spec parsed once, built from it, and declare what they need; clear errors
for malformed names and for an env that cannot give a reward what it needs."""

from pathlib import Path

import pytest

from gymnast.envs.kinds import ENV_KINDS, IMAGINED, REAL, SIM
from gymnast.reward.base import RewardNeeds, check_fits
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.video import LearnedJudge
from gymnast.reward.select import make_reward
from gymnast.reward.sim import SimDense, SimSuccess
from gymnast.reward.spec import RewardSpec
from gymnast.reward.verified import VerifiedReward
from gymnast.reward.chat.vlm import VLMJudge, VLMJudgeConfig
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig

SPECS = ["judge:runs/judge", "state:runs/state", "vlm:gpt-4o@http://127.0.0.1:9/v1", "verified", "sim", "sim-dense",
         "all:judge:runs/judge+state:runs/state"]


def _tiny_world_model() -> EmbeddedWorldModel:
    return EmbeddedWorldModel(EmbeddedWorldModelConfig(image_size=32, latent_channels=16, widths=(8, 16), blocks=1,
                                                       action_width=16))


def _every_reward() -> list:
    return [SimSuccess(), SimDense(), VerifiedReward(_tiny_world_model()), LearnedJudge(), FrameJudge(),
            VLMJudge(VLMJudgeConfig(model="m", base_url="http://127.0.0.1:9/v1"))]


def test_every_form_builds_its_reward(tmp_path, monkeypatch):
    model = _tiny_world_model()
    parse = RewardSpec.parse
    assert isinstance(make_reward(parse("sim")), SimSuccess) and isinstance(make_reward(parse("sim-dense")), SimDense)
    assert isinstance(make_reward(parse("verified"), model), VerifiedReward)
    judge = make_reward(parse("vlm:gpt-4o@http://127.0.0.1:9/v1"))
    assert isinstance(judge, VLMJudge) and judge.config.model == "gpt-4o" and judge.config.base_url == "http://127.0.0.1:9/v1"


def test_a_judge_reward_loads_its_run(tmp_path):
    from gymnast.utils.checkpoint import save_checkpoint

    judge = LearnedJudge()
    save_checkpoint(tmp_path, 1, judge, {"model": judge.spec()})
    assert isinstance(make_reward(RewardSpec.parse(f"judge:{tmp_path}")), LearnedJudge)
    with pytest.raises(FileNotFoundError):
        make_reward(RewardSpec.judge(tmp_path / "missing"))


def test_a_state_reward_loads_its_state_model_run(tmp_path):
    from gymnast.reward.state_reward import StateReward
    from gymnast.utils.checkpoint import save_checkpoint
    from gymnast.world_model.state_model import StateModel, StateModelConfig

    model = StateModel(StateModelConfig(state_dim=5, hidden=8, layers=1))
    save_checkpoint(tmp_path, 1, model, {"model": model.spec()})
    reward = make_reward(RewardSpec.parse(f"state:{tmp_path}"))
    assert isinstance(reward, StateReward) and [m.config.state_dim for m in reward.models] == [5]
    assert reward.needs.start_state and not reward.binary


@pytest.mark.parametrize("spec", ["judge", "judge:", "state:", "vlm:gpt-4o", "vlm:@http://x", "dense", "",
                                  "all:judge:a+dense"])
def test_malformed_names_list_the_valid_forms(spec):
    with pytest.raises(ValueError, match="vlm:MODEL@BASE_URL"):
        RewardSpec.parse(spec)


@pytest.mark.parametrize("text", SPECS)
def test_a_spec_reads_back_as_the_text_it_was_parsed_from(text):
    spec = RewardSpec.parse(text)
    assert str(spec) == text and RewardSpec.parse(str(spec)) == spec


def test_a_spec_holds_its_parts_typed():
    assert RewardSpec.parse("judge:runs/judge") == RewardSpec.judge("runs/judge") == RewardSpec("judge", run=Path("runs/judge"))
    assert RewardSpec.parse("vlm:gpt-4o@http://x/v1@y") == RewardSpec("vlm", model="gpt-4o", base_url="http://x/v1@y")
    with pytest.raises(ValueError, match="the forms are"):
        RewardSpec("judge")  # a judge without its run


def test_verified_without_a_world_model_says_what_is_missing():
    with pytest.raises(ValueError, match="needs a world model"):
        make_reward(RewardSpec.parse("verified"))


def test_every_reward_declares_whether_it_is_binary_what_it_needs_and_its_metrics():
    for reward in _every_reward():
        assert isinstance(reward.binary, bool) and isinstance(reward.needs, RewardNeeds), type(reward).__name__
        metrics = reward.metrics()
        assert all(key.startswith("reward/") and isinstance(value, float) for key, value in metrics.items())
    assert SimSuccess.needs.simulator_success and SimDense.needs.simulator_success
    assert VerifiedReward.needs.world_model and VerifiedReward.needs.reference_actions
    assert LearnedJudge.needs == FrameJudge.needs == VLMJudge.needs == RewardNeeds()
    # Only the simulator's own rewards leave the frames inside a chunk unread (RL need not render them).
    assert [type(reward).__name__ for reward in _every_reward() if not reward.needs.video] == ["SimSuccess", "SimDense"]


def test_each_reward_fits_exactly_the_envs_that_give_what_it_needs():
    fits = {}
    for reward in _every_reward():
        fits[type(reward).__name__] = []
        for env in ENV_KINDS.values():
            try:
                check_fits(reward, "r", env)
                fits[type(reward).__name__].append(env.name)
            except ValueError:
                pass
    # The anchored env is both: a real rollout (its success) seen through the world model (its frames).
    every = ["imagined", "sim", "real", "anchored"]
    assert fits == {"SimSuccess": ["sim", "real", "anchored"], "SimDense": ["sim", "real", "anchored"],
                    "VerifiedReward": ["imagined", "anchored"], "LearnedJudge": every, "FrameJudge": every,
                    "VLMJudge": every}


@pytest.mark.parametrize("spec, reward, env, why", [
    ("sim", SimSuccess(), IMAGINED, "simulator's own verdict, which --env imagined does not report"),
    ("sim-dense", SimDense(), IMAGINED, "simulator's own verdict"),
])
def test_an_env_that_cannot_give_what_a_reward_needs_is_refused_naming_both(spec, reward, env, why):
    with pytest.raises(ValueError, match=f"--reward {spec} cannot score rollouts of --env {env.name}") as error:
        check_fits(reward, spec, env)
    assert why in str(error.value) and "it fits --env sim or real" in str(error.value)


def test_the_verified_reward_is_refused_outside_imagination_and_without_demonstrations():
    verified = VerifiedReward(_tiny_world_model())
    for env in (SIM, REAL):
        with pytest.raises(ValueError, match=f"--reward verified cannot score rollouts of --env {env.name}.*"
                                             "does not imagine.*fits --env imagined"):
            check_fits(verified, "verified", env)
    check_fits(verified, "verified", IMAGINED)
    with pytest.raises(ValueError, match="fresh scenes have none"):
        check_fits(verified, "verified", IMAGINED, demonstrations=False)


def test_a_consensus_is_named_by_two_rewards_or_more_none_a_consensus():
    spec = RewardSpec.parse("all:judge:a+sim")
    assert spec.kind == "all" and spec.members == (RewardSpec.judge("a"), RewardSpec("sim"))
    with pytest.raises(ValueError, match="at least two"):
        RewardSpec.parse("all:judge:a")
    with pytest.raises(ValueError, match="consensus of consensuses"):
        RewardSpec("all", members=(spec, RewardSpec("sim")))
