"""LeRobot's policies practise in gymnast's world model through the same GRPO loop, and the run
writes them back as a LeRobot folder that LeRobot loads and that acts as the trained policy does."""

import json

import pytest
import torch

from gymnast.cli import main
from gymnast.policy.load import load_policy
from gymnast.rl.train import LEROBOT_EXPORT
from gymnast.utils.metrics import read_metrics

from rl_helpers import JUDGE, WORLD_MODEL


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
