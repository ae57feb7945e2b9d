"""Loading a LeRobot policy for gymnast: ``--policy lerobot:PATH`` and the checkpoints RL writes.

PATH is a LeRobot ``pretrained_model`` folder (config.json, model.safetensors and the pre- and
post-processors' files). Flow-matching policies (`gymnast.policy.lerobot_flow.FLOW_TYPES`) get
the flow SDE, every other policy the Gaussian head.
"""

from __future__ import annotations

from pathlib import Path

from gymnast.policy.lerobot_flow import FLOW_TYPES, LeRobotFlowPolicy
from gymnast.policy.lerobot_gaussian import LeRobotGaussianPolicy
from gymnast.policy.lerobot_policy import ExplorationConfig, LeRobotPolicy, load_parts, parts_from_files, read_folder

def load_lerobot(folder: str | Path, exploration: ExplorationConfig = ExplorationConfig()) -> LeRobotPolicy:
    """The adapter of the LeRobot policy in `folder`, its weights loaded, in eval mode.

    Raises:
        FileNotFoundError: `folder` is not a pretrained_model folder.
        ValueError: the policy declares a feature gymnast cannot give or take (named).
        ImportError: LeRobot is not installed (the message says how).
    """
    folder = Path(folder)
    if not (folder / "config.json").is_file():
        raise FileNotFoundError(f"--policy lerobot:{folder}: no config.json there; give a LeRobot pretrained_model "
                                "folder (config.json, model.safetensors, the processors' files)")
    files = read_folder(folder)
    return _adapter(files["config.json"]["type"])(*load_parts(folder, weights=True), files, str(folder), exploration)


class LeRobotFamily:
    """The `gymnast.policy.load` entry of LeRobot policies: rebuilds one from a saved spec."""

    @staticmethod
    def from_spec(spec: dict) -> LeRobotPolicy:
        saved = spec["lerobot"]
        files = saved["files"]
        return _adapter(files["config.json"]["type"])(*parts_from_files(files), files, saved["source"],
                                                      ExplorationConfig(**saved["exploration"]))


def _adapter(kind: str) -> type[LeRobotPolicy]:
    return LeRobotFlowPolicy if kind in FLOW_TYPES else LeRobotGaussianPolicy
