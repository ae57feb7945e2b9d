"""bfloat16 autocast is used only where the hardware computes bfloat16 natively."""

import pytest
import torch

from gymnast.utils import device as device_module
from gymnast.utils.device import bf16_autocast, bf16_status


@pytest.mark.parametrize(("native", "wanted", "dtype"), [(True, True, torch.bfloat16), (True, False, torch.float32),
                                                        (False, True, torch.float32), (False, False, torch.float32)])
def test_autocast_only_where_wanted_and_native(monkeypatch, native, wanted, dtype):
    monkeypatch.setattr(device_module, "bf16_is_native", lambda device_type: native)
    layer = torch.nn.Linear(4, 4)
    with bf16_autocast(torch.device("cpu"), wanted):
        assert layer(torch.ones(2, 4)).dtype == dtype


def test_doctor_line_names_the_cpu_and_the_choice():
    line = bf16_status()
    assert torch.backends.cpu.get_cpu_capability() in line
    assert ("native, used" in line) == device_module.bf16_is_native("cpu")
