"""`train_sft` with the debug preset in float32 (bf16 autocast off), for torchrun in
test_distributed.py: python sft_in_fp32.py DATA OUT (one process, or each of torchrun's)."""

import dataclasses
import sys
from pathlib import Path

from gymnast.policy.sft import SFT_PRESETS, train_sft

if __name__ == "__main__":
    config = dataclasses.replace(SFT_PRESETS["debug"], steps=4, bf16=False, device="cpu")
    train_sft(Path(sys.argv[1]), Path(sys.argv[2]), config, progress=False)
