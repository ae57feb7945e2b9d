"""Rewards are chosen by name, with clear errors for the malformed ones."""

import pytest

from gymnast.reward.judge import LearnedJudge
from gymnast.reward.select import make_reward
from gymnast.reward.sim import SimDense, SimSuccess
from gymnast.reward.verified import VerifiedReward
from gymnast.reward.vlm import VLMJudge
from gymnast.world_model.embedded import EmbeddedWorldModel, EmbeddedWorldModelConfig


def test_every_form_builds_its_reward(tmp_path, monkeypatch):
    model = EmbeddedWorldModel(EmbeddedWorldModelConfig(image_size=32, latent_channels=16, widths=(8, 16), blocks=1, action_width=16))
    assert isinstance(make_reward("sim"), SimSuccess) and isinstance(make_reward("sim-dense"), SimDense)
    assert isinstance(make_reward("verified", model), VerifiedReward)
    judge = make_reward("vlm:gpt-4o@http://127.0.0.1:9/v1")
    assert isinstance(judge, VLMJudge) and judge.config.model == "gpt-4o" and judge.config.base_url == "http://127.0.0.1:9/v1"


def test_a_judge_reward_loads_its_run(tmp_path):
    from gymnast.utils.checkpoint import save_checkpoint

    judge = LearnedJudge()
    save_checkpoint(tmp_path, 1, judge, {"model": judge.spec()})
    assert isinstance(make_reward(f"judge:{tmp_path}"), LearnedJudge)
    with pytest.raises(FileNotFoundError):
        make_reward(f"judge:{tmp_path / 'missing'}")


@pytest.mark.parametrize("spec", ["judge", "judge:", "vlm:gpt-4o", "vlm:@http://x", "dense", ""])
def test_malformed_names_list_the_valid_forms(spec):
    with pytest.raises(ValueError, match="vlm:MODEL@BASE_URL"):
        make_reward(spec)


def test_verified_without_a_world_model_says_what_is_missing():
    with pytest.raises(ValueError, match="needs a world model"):
        make_reward("verified")
