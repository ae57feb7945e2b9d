"""bfloat16 autocast is used only where the hardware computes bfloat16 natively."""

import pytest
import torch

from gymnast.utils import device as device_module
from gymnast.utils.device import bf16_autocast, bf16_status


@pytest.mark.parametrize(("native", "wanted", "dtype"), [(True, True, torch.bfloat16), (True, False, torch.float32),
                                                        (False, True, torch.float32), (False, False, torch.float32)])
def test_autocast_only_where_wanted_and_native(monkeypatch, native, wanted, dtype):
    monkeypatch.setattr(device_module, "bf16_is_native", lambda device_type: native)
    monkeypatch.delenv(device_module.CPU_BF16_VARIABLE, raising=False)
    layer = torch.nn.Linear(4, 4)
    with bf16_autocast(torch.device("cpu"), wanted):
        assert layer(torch.ones(2, 4)).dtype == dtype


def test_doctor_line_names_the_cpu_and_the_choice(monkeypatch):
    monkeypatch.delenv(device_module.CPU_BF16_VARIABLE, raising=False)
    line = bf16_status()
    assert torch.backends.cpu.get_cpu_capability() in line
    assert ("native, used" in line) == device_module.bf16_is_native("cpu")


@pytest.mark.parametrize("setting", ["off", " OFF "])
def test_turned_off_on_the_cpu_runs_float32_even_where_native(monkeypatch, setting):
    monkeypatch.setattr(device_module, "bf16_is_native", lambda device_type: True)
    monkeypatch.setenv(device_module.CPU_BF16_VARIABLE, setting)
    layer = torch.nn.Linear(4, 4)
    with bf16_autocast(torch.device("cpu")):
        assert layer(torch.ones(2, 4)).dtype == torch.float32
    assert "native, float32 used instead (GYMNAST_CPU_BF16=off)" in bf16_status()


def test_auto_leaves_the_choice_to_the_hardware(monkeypatch):
    monkeypatch.setattr(device_module, "bf16_is_native", lambda device_type: True)
    monkeypatch.setenv(device_module.CPU_BF16_VARIABLE, "auto")
    with bf16_autocast(torch.device("cpu")):
        assert torch.nn.Linear(4, 4)(torch.ones(2, 4)).dtype == torch.bfloat16


@pytest.mark.parametrize("native", [True, False])
def test_an_unknown_setting_is_named_whatever_the_cpu(monkeypatch, native):
    monkeypatch.setattr(device_module, "bf16_is_native", lambda device_type: native)
    monkeypatch.setenv(device_module.CPU_BF16_VARIABLE, "fast")
    with pytest.raises(ValueError, match="GYMNAST_CPU_BF16='fast'"):
        bf16_autocast(torch.device("cpu"))
