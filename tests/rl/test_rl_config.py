"""A run's settings travel typed (env kind, reward spec) and are saved as the command line names them."""

import json

from gymnast.envs.kinds import IMAGINED
from gymnast.reward.spec import RewardSpec
from gymnast.rl.config import RLConfig, RLRun, saved_rl_settings


def test_a_run_is_saved_by_name_and_read_back_typed(tmp_path):
    run = RLRun("runs/sft", IMAGINED, RewardSpec.judge("runs/judge"), wm="runs/wm", data="data/mt10")
    saved = run.to_json()
    assert saved == {"policy": "runs/sft", "env": "imagined", "reward": "judge:runs/judge", "wm": "runs/wm",
                     "data": "data/mt10", "robot_state": None, "reward_sees": "own", "reward_wm": None}
    (tmp_path / "config.json").write_text(json.dumps({"run": saved, "rl": {"steps": 3}}))
    assert saved_rl_settings(tmp_path) == (run, RLConfig(steps=3))
    # A run saved before --robot-state existed reads back without one.
    del saved["robot_state"]
    (tmp_path / "config.json").write_text(json.dumps({"run": saved, "rl": {"steps": 3}}))
    assert saved_rl_settings(tmp_path)[0] == run
