"""Devices: resolved once from a name, with a clear error where CUDA is asked for and absent."""

import pytest
import torch

from gymnast.utils.device import resolve_device

def test_auto_is_cuda_exactly_where_torch_sees_a_gpu():
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert resolve_device("cpu") == torch.device("cpu")


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_cuda_without_a_gpu_is_refused_with_the_fix():
    with pytest.raises(ValueError, match="sees no CUDA GPU here; use --device cpu"):
        resolve_device("cuda")


def test_an_unknown_device_is_named():
    with pytest.raises(ValueError, match="unknown device 'tpu'"):
        resolve_device("tpu")
