"""A flow-matching policy goes through the same RL loop and evaluation as the tokenized one:
its denoising paths stand where tokens stood, and GRPO's ratio is exactly 1 on its own samples."""

import json

import pytest
import torch

from gymnast.cli import main
from gymnast.policy.flow_vla import FlowVLA, FlowVLAConfig
from gymnast.rl.config import RL_PRESETS
from gymnast.rl.rollout import collect_rollouts
from gymnast.rl.train import update_policy
from gymnast.utils.checkpoint import save_checkpoint, write_run_config

from rl_helpers import JUDGE, WORLD_MODEL


@pytest.fixture(scope="module")
def flow_policy(tmp_path_factory, rl_dataset):
    """An untrained flow policy at the committed world model's image size, saved as a run."""
    run = tmp_path_factory.mktemp("flow_policy")
    torch.manual_seed(0)
    model = FlowVLA(FlowVLAConfig(width=32, layers=1, heads=2, steps=2), pretrained_vision=False)
    resolved = {"model": model.spec(), "data": str(rl_dataset)}
    write_run_config(run, resolved)
    save_checkpoint(run, 0, model, resolved)
    return run


@pytest.mark.parametrize("env, reward", [("imagined", f"judge:{JUDGE}"), ("sim", "sim-dense")])
def test_rl_trains_a_flow_policy_on_every_env(env, reward, flow_policy, tmp_path, capsys):
    out = tmp_path / "run"
    extra = ["--wm", str(WORLD_MODEL)] if env == "imagined" else []
    main(["rl", "--policy", str(flow_policy), "--env", env, "--reward", reward, "--out", str(out),
          "--preset", "debug", *extra])
    summary = json.loads((out / "summary.json").read_text())
    assert [point["step"] for point in summary["curve"]] == [0, 2]
    assert json.loads((out / "config.json").read_text())["model"].keys() == {"flow_vla"}


def test_grpo_sees_a_ratio_of_one_on_the_flow_policys_own_samples(flow_policy):
    from gymnast.config import EnvConfig
    from gymnast.envs.factory import EnvFactory
    from gymnast.envs.kinds import env_kind
    from gymnast.envs.starts import evaluation_starts
    from gymnast.policy.load import load_policy

    policy = load_policy(flow_policy)
    config = RL_PRESETS["debug"]
    env_config = EnvConfig(image_size=96, horizon=config.horizon)
    starts = evaluation_starts(["reach-v3"], 2, env_config)
    factory = EnvFactory(env_kind("sim"), policy.chunk_size, env_config, "mild", 1)
    try:
        batch = collect_rollouts(factory.train(2), policy, starts, 1.0, torch.Generator().manual_seed(0), seed=0)
    finally:
        factory.close()
    assert batch.tokens.dtype == torch.float32 and batch.logp.shape == batch.token_mask.shape
    values = update_policy(policy, torch.optim.SGD(policy.parameters(), lr=0.0), batch, torch.tensor([1.0, -1.0]),
                           config)
    assert values["train/ratio"] == pytest.approx(1.0, abs=1e-5)


def test_gymnast_eval_runs_a_flow_policy(flow_policy, tmp_path, capsys):
    out = tmp_path / "eval.json"
    main(["eval", "--policy", str(flow_policy), "--tasks", "reach-v3", "--episodes", "1", "--workers", "1",
          "--out", str(out), "--videos-per-task", "0"])
    assert json.loads(out.read_text())["episodes"] == 1


@pytest.mark.parametrize("gate, active", [(0.0, 1.0), (1e9, 0.0)])
def test_vla_rfts_imitation_loss_joins_the_update_unless_the_kl_gate_holds_it(gate, active, flow_policy, tmp_path,
                                                                              capsys):
    from gymnast.utils.metrics import read_metrics

    out = tmp_path / "run"
    main(["rl", "--policy", str(flow_policy), "--env", "sim", "--reward", "sim-dense", "--out", str(out),
          "--preset", "debug", "--imitation-coef", "0.5", "--imitation-kl-gate", str(gate)])
    updates = [m for m in read_metrics(out) if "train/imitation_active" in m]
    assert updates and all(m["train/imitation_active"] == active for m in updates)
    assert all(("train/imitation_loss" in m) == bool(active) for m in updates)
    if gate > 0:  # the gate reads the KL to the starting policy, which is then kept
        assert all("train/kl" in m for m in updates)


def test_the_imitation_loss_needs_expert_demonstrations_of_the_tasks(flow_policy, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["rl", "--policy", str(flow_policy), "--env", "sim", "--reward", "sim-dense", "--out", str(tmp_path / "r"),
              "--preset", "debug", "--imitation-coef", "0.5", "--tasks", "push-v3", "--fresh-scenes"])
    assert "has no successful expert episode of push-v3 to imitate" in capsys.readouterr().err
