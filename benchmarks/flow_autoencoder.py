"""The ceiling a flow world model's autoencoder puts on its frames, on held-out episodes.

Every imagined frame of the flow backend is decoded from a latent, so no rollout can be sharper
than the autoencoder: this encodes and decodes every frame of the run's held-out episodes (the
anchor being the episode's first frame, as in a rollout from t = 0) and reports PSNR over whole
frames and over the moving pixels (those that differ from the first frame, as eval-wm counts
them). If the moving-pixel figure is low, a better velocity network cannot help; a wider
autoencoder (or more training) must come first.

    .venv/bin/python benchmarks/flow_autoencoder.py --wm RUN --data data/mt10 [--out JSON]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

import gymnast  # noqa: F401  (sets MUJOCO_GL)
from gymnast.data.lerobot import EpisodeDataset
from gymnast.utils.atomic import write_json
from gymnast.world_model.base import load_world_model
from gymnast.world_model.data import split_episodes
from gymnast.world_model.evaluate import heldout_fraction
from gymnast.world_model.metrics import masked_psnr, moving_mask, psnr, to_unit_float


@torch.inference_mode()
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wm", type=Path, required=True, help="a flow world-model run")
    parser.add_argument("--data", type=Path, required=True, help="its dataset")
    parser.add_argument("--out", type=Path, default=None, help="the JSON to write (default: print only)")
    args = parser.parse_args()
    model = load_world_model(args.wm)
    if getattr(model, "backend", None) != "flow":
        raise SystemExit(f"{args.wm} is not a flow world model")
    dataset = EpisodeDataset(args.data)
    _, heldout = split_episodes(dataset.episodes, heldout_fraction(args.wm))
    whole, moving = [], []
    for index in heldout:
        frames = to_unit_float(torch.from_numpy(dataset.load(index).frames))  # (T+1, 3, H, W)
        with model.autocast():
            skips = [s.expand(len(frames), -1, -1, -1) for s in model.anchor(frames[:1])]
            decoded = model.decode(model.encode(frames), *skips).float()
        whole.append(psnr(decoded[1:], frames[1:]))
        moving.append(masked_psnr(decoded[1:], frames[1:], moving_mask(frames[1:], frames[:1])))
    whole_t, moving_t = torch.cat(whole), torch.cat(moving)
    result = {"wm": str(args.wm), "episodes": len(heldout), "frames": len(whole_t),
              "reconstruction_psnr": round(whole_t.mean().item(), 2),
              "reconstruction_moving_psnr": round(moving_t[moving_t.isfinite()].mean().item(), 2)}
    print(json.dumps(result, indent=2))
    if args.out:
        write_json(args.out, result)


if __name__ == "__main__":
    main()
