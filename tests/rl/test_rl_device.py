"""The RL loop on the device it is given: by name on the CPU it is the default run; on a GPU
(only where torch sees one) it writes a policy the host loads."""

import json

import pytest
import torch

from gymnast.cli import main

from rl_helpers import JUDGE, POLICY, WORLD_MODEL

needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")


def _rl(device, out, data):
    main(["rl", "--policy", str(POLICY), "--env", "imagined", "--wm", str(WORLD_MODEL), "--reward", f"judge:{JUDGE}",
          "--out", str(out), "--data", str(data), "--preset", "debug", "--device", device, "--watch-every", "0",
          "--no-real-eval"])
    return json.loads((out / "summary.json").read_text())


def test_rl_on_the_cpu_by_name_is_the_default_run(rl_dataset, tmp_path):
    named, default = _rl("cpu", tmp_path / "cpu", rl_dataset), _rl("auto", tmp_path / "auto", rl_dataset)
    if not torch.cuda.is_available():  # auto is the CPU here: the same run, draw for draw
        assert named["curve"] == default["curve"]
    assert json.loads((tmp_path / "cpu" / "config.json").read_text())["rl"]["device"] == "cpu"


@needs_cuda
def test_rl_on_a_gpu_writes_a_policy_the_cpu_loads(rl_dataset, tmp_path):
    from gymnast.policy.load import load_policy

    _rl("cuda", tmp_path / "gpu", rl_dataset)
    policy = load_policy(tmp_path / "gpu")  # on the host
    image = torch.zeros(1, policy.config.image_size, policy.config.image_size, 3, dtype=torch.uint8)
    on_host = policy.act(image, ["reach the red target"])
    on_gpu = policy.to("cuda").act(image, ["reach the red target"])
    torch.testing.assert_close(on_gpu, on_host, atol=2 / 256, rtol=0)  # one bin apart at most
