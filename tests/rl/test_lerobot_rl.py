"""LeRobot's policies practise in gymnast's world model through the same GRPO loop, and the run
writes them back as a LeRobot folder that LeRobot loads and that acts as the trained policy does."""

import json

import pytest
import torch

from gymnast.cli import main
from gymnast.policy.load import load_policy
from gymnast.rl.train import LEROBOT_EXPORT
from gymnast.utils.metrics import read_metrics

from rl_helpers import JUDGE, RESULTS, WORLD_MODEL

STATE_ENSEMBLE = RESULTS / "world_model" / "state_v5"


@pytest.fixture
def folders(lerobot_act, lerobot_smolvla):
    """A tiny ACT (Gaussian head) and a tiny SmolVLA (flow SDE), randomly initialised (tests/conftest.py)."""
    return {"act": lerobot_act, "smolvla": lerobot_smolvla}


@pytest.mark.parametrize("kind", ["act", "smolvla"])
def test_a_grpo_step_in_imagination_trains_the_lerobot_policy_and_writes_it_back(kind, folders, rl_dataset, tmp_path,
                                                                                  capsys):
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    out = tmp_path / "run"
    main(["rl", "--policy", f"lerobot:{folders[kind]}", "--env", "imagined", "--wm", str(WORLD_MODEL),
          "--reward", f"judge:{JUDGE}", "--data", str(rl_dataset), "--out", str(out), "--preset", "debug",
          "--steps", "1", "--watch-every", "0", "--no-real-eval", "--imitation-coef", "0.5"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 1 and summary["real_interactions"] == 0
    update = next(m for m in read_metrics(out) if "train/policy_calls" in m)
    # The ratio is 1 on the policy's own samples; a random policy's rollouts may all score alike
    # (zero advantages), and the imitation anchor (LeRobot's own loss on the experts) still moves it.
    assert update["train/ratio"] == pytest.approx(1.0, abs=1e-4)
    assert update["train/imitation_loss"] > 0 and update["train/grad_norm"] > 0

    trained = load_policy(out)  # gymnast's checkpoint, exploration head included
    images = torch.randint(0, 256, (2, 96, 96, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    texts = ["reach the goal", "push the puck"]
    ours = trained.act(images, texts)
    exported = out / LEROBOT_EXPORT
    lerobot = get_policy_class(kind).from_pretrained(exported)
    preprocessor, postprocessor = make_pre_post_processors(lerobot.config, pretrained_path=str(exported))
    batch = preprocessor(trained.features.batch(images, texts))
    noise = {"noise": torch.zeros(2, 8, 8)} if kind == "smolvla" else {}
    theirs = postprocessor(lerobot.predict_action_chunk(batch, **noise))[:, :5]
    torch.testing.assert_close(theirs, ours, atol=1e-5, rtol=0)
    untrained = load_policy(f"lerobot:{folders[kind]}").act(images, texts)
    assert not torch.allclose(untrained, ours, atol=1e-6)  # the step changed what LeRobot now loads


@pytest.mark.slow
def test_a_lerobot_policy_reading_the_robot_state_practises_for_real_and_in_imagination_with_a_state_model(
        rl_dataset, tmp_path, capsys):
    from gymnast.policy.lerobot_init import new_act

    folder = new_act(tmp_path / "act", chunk=5, predicted=8, action_std=0.5, state_dim=4)  # hand xyz and gripper
    out = tmp_path / "run"
    common = ["rl", "--policy", f"lerobot:{folder}", "--data", str(rl_dataset), "--preset", "debug", "--steps", "1",
              "--watch-every", "0", "--imitation-coef", "0.5"]
    main([*common, "--env", "real", "--reward", "sim-dense", "--horizon", "10", "--no-real-eval", "--out", str(out)])
    update = next(m for m in read_metrics(out) if "train/policy_calls" in m)
    # The update recomputes each call's density with the state it was sampled in (ratio 1), and
    # the imitation anchor reads the demonstrations' own states.
    assert update["train/ratio"] == pytest.approx(1.0, abs=1e-4) and update["train/imitation_loss"] > 0

    trained = load_policy(out)
    images = torch.randint(0, 256, (2, 96, 96, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    texts, states = ["reach the goal"] * 2, torch.tensor([[0.0, 0.6, 0.2, 1.0], [0.1, 0.7, 0.1, 0.0]])
    ours = trained.act(images, texts, states)
    assert not torch.allclose(trained.act(images, texts, states.flip(0)), ours, atol=1e-4)  # the state counts
    exported = out / LEROBOT_EXPORT
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    lerobot = get_policy_class("act").from_pretrained(exported)
    preprocessor, postprocessor = make_pre_post_processors(lerobot.config, pretrained_path=str(exported))
    batch = preprocessor({"observation.image": images.permute(0, 3, 1, 2).float() / 255, "observation.state": states,
                          "task": texts})
    torch.testing.assert_close(postprocessor(lerobot.predict_action_chunk(batch))[:, :5], ours, atol=1e-5, rtol=0)

    # In imagination the robot's state comes from a state model stepped beside the world model.
    imagined = ["--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}", "--horizon", "10"]
    with pytest.raises(SystemExit):
        main([*common, *imagined, "--out", str(tmp_path / "refused")])
    assert "imagines images only; give a state model that imagines it with --robot-state RUN" in capsys.readouterr().err
    main([*common, *imagined, "--robot-state", str(STATE_ENSEMBLE), "--no-real-eval", "--out", str(tmp_path / "imagined")])
    update = next(m for m in read_metrics(tmp_path / "imagined") if "train/policy_calls" in m)
    assert update["train/ratio"] == pytest.approx(1.0, abs=1e-4)  # each call re-scored with its imagined state
