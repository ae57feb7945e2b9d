"""RL on a policy of several cameras: the real world renders its views, a world model of the same
cameras imagines them, and a world model or a judge of other cameras refuses it; LeRobot's
policies of several cameras (one ``observation.images.<camera>`` feature each) too."""

from __future__ import annotations

import json

import pytest
import torch

from gymnast.cli import main
from gymnast.config import EnvConfig
from gymnast.policy.load import load_policy, policy_env_config
from gymnast.rl.train import LEROBOT_EXPORT

from rl_helpers import POLICY, RESULTS, WORLD_MODEL


@pytest.mark.slow
def test_rl_practises_a_two_camera_policy_for_real_and_in_a_world_model_of_its_cameras(two_camera_demos, tmp_path, capsys):
    policy, wm = tmp_path / "policy", tmp_path / "wm"
    main(["sft", "--data", str(two_camera_demos), "--out", str(policy), "--preset", "debug", "--cameras", "front,gripper"])
    main(["train-wm", "--data", str(two_camera_demos), "--out", str(wm), "--preset", "debug", "--cameras", "front,gripper"])
    common = ["rl", "--policy", str(policy), "--data", str(two_camera_demos), "--preset", "debug", "--tasks", "reach-v3"]
    main([*common, "--env", "sim", "--reward", "sim-dense", "--out", str(tmp_path / "sim")])
    summary = json.loads((tmp_path / "sim" / "summary.json").read_text())
    assert summary["steps"] == 2 and summary["eval_real_interactions"] > 0
    main([*common, "--env", "imagined", "--wm", str(wm), "--reward", "verified", "--keyframes", "uniform",
          "--horizon", "10", "--eval-horizon", "10", "--out", str(tmp_path / "imagined")])
    summary = json.loads((tmp_path / "imagined" / "summary.json").read_text())
    assert summary["steps"] == 2 and summary["real_interactions"] == 0
    with pytest.raises(SystemExit):
        main([*common, "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", "verified", "--out", str(tmp_path / "one")])
    assert "sees front,gripper side by side, but the world model" in capsys.readouterr().err


def test_a_judge_of_other_views_is_refused_before_anything_runs(rl_dataset, tmp_path, capsys):
    # The committed one-camera policy at 96 px, and the default judge: three cameras at 128 px.
    judge = RESULTS / "judge" / "judge"
    commands = {
        "rl": ["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--preset", "debug",
               "--data", str(rl_dataset)],
        "imagination": ["imagination", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--tasks", "reach-v3"],
        "rl-signal": ["rl-signal", "--policy", str(POLICY), "--wm", str(WORLD_MODEL), "--tasks", "reach-v3",
                      "--data", str(rl_dataset)],
    }
    for name, command in commands.items():
        with pytest.raises(SystemExit):
            main([*command, "--reward", f"judge:{judge}", "--out", str(tmp_path / name)])
        error = capsys.readouterr().err
        assert f"the judge {judge} scores front,gripper,hand at 128 px, but the policy {POLICY} shows one camera at " \
               "96 px" in error, name
        assert not (tmp_path / name).exists() or not any((tmp_path / name).iterdir()), name


@pytest.mark.slow
def test_a_lerobot_policy_of_two_cameras_practises_in_their_world_model_and_acts_on_them_for_real(two_camera_demos,
                                                                                                  tmp_path):
    from gymnast.policy.lerobot_import import require_lerobot
    from gymnast.policy.lerobot_init import new_act

    require_lerobot()  # before LeRobot's own imports (beside gymnast's CPU torch)
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    folder = new_act(tmp_path / "act", image_size=32, cameras=("front", "gripper"), chunk=5, predicted=8)
    assert policy_env_config(EnvConfig(), f"lerobot:{folder}").cameras == ("front", "gripper")
    wm, run, report = tmp_path / "wm", tmp_path / "rl", tmp_path / "eval.json"
    main(["train-wm", "--data", str(two_camera_demos), "--out", str(wm), "--preset", "debug", "--cameras", "front,gripper",
          "--steps", "2"])
    main(["rl", "--policy", f"lerobot:{folder}", "--data", str(two_camera_demos), "--preset", "debug", "--steps", "1",
          "--env", "imagined", "--wm", str(wm), "--reward", "verified", "--keyframes", "uniform", "--horizon", "10",
          "--eval-horizon", "10", "--no-real-eval", "--watch-every", "0", "--out", str(run)])
    assert json.loads((run / "summary.json").read_text())["steps"] == 1
    # The trained policy, written back for LeRobot, acts on both views for real and in LeRobot alike.
    exported = run / LEROBOT_EXPORT
    main(["eval", "--policy", f"lerobot:{exported}", "--tasks", "reach-v3", "--episodes", "1", "--workers", "1",
          "--env.image-size", "32", "--env.horizon", "10", "--videos-per-task", "0", "--out", str(report)])
    assert json.loads(report.read_text())["config"]["env"]["cameras"] == ["front", "gripper"]
    trained = load_policy(run)
    front, gripper = (torch.randint(0, 256, (2, 32, 32, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))
                      for seed in (0, 1))
    texts = ["reach the goal", "reach the goal"]
    ours = trained.act(torch.cat([front, gripper], dim=2), texts)
    lerobot = ACTPolicy.from_pretrained(exported)
    preprocessor, postprocessor = make_pre_post_processors(lerobot.config, pretrained_path=str(exported))
    views = {f"observation.images.{name}": view.permute(0, 3, 1, 2).float() / 255
             for name, view in (("front", front), ("gripper", gripper))}
    batch = preprocessor(views | {"observation.state": torch.zeros(2, 0), "task": texts})
    torch.testing.assert_close(postprocessor(lerobot.predict_action_chunk(batch))[:, :5], ours, atol=1e-5, rtol=0)
    # The gripper's view counts: blanking it changes the actions.
    assert not torch.allclose(trained.act(torch.cat([front, torch.zeros_like(gripper)], dim=2), texts), ours, atol=1e-4)
