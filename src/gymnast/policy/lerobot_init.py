"""A new, untrained LeRobot ACT policy written as a pretrained_model folder, for trying the
LeRobot path end to end without a trained one (docs/lerobot.md):

    python -m gymnast.policy.lerobot_init OUT [--image-size 96] [--action-dim 4] [--chunk 5] [--cameras front,gripper]
        [--state-dim 4]

The policy reads one camera image (``observation.image``; with ``--cameras front,gripper`` one
``observation.images.<camera>`` each; with ``--state-dim 4`` also the robot's state,
``observation.state``, which only a simulator gives) and acts
in A dimensions; actions are normalised by a mean of 0 and a standard deviation of 1, which is
Meta-World's [-1, 1] range as it is. It is small (one encoder and one decoder layer of width 64)
and its ResNet-18 backbone starts from random weights, since none can be downloaded here.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Sequence

import torch

from gymnast.policy.lerobot_import import require_lerobot
from gymnast.utils.torchvision_ops import allow_torchvision_import


def new_act(out: Path, image_size: int = 96, action_dim: int = 4, chunk: int = 5, predicted: int | None = None,
            width: int = 64, action_std: float = 1.0, seed: int = 0, cameras: Sequence[str] = (),
            state_dim: int = 0) -> Path:
    """Writes a randomly initialised ACT policy and its processors to `out`; returns `out`.

    Args:
        image_size: side of the square ``observation.image`` it reads.
        action_dim: A, its action's size.
        chunk: actions executed per call (``n_action_steps``), gymnast's K.
        predicted: actions predicted per call (``chunk_size``); default `chunk`.
        width: the transformer's width.
        action_std: the actions' normalisation standard deviation (their mean is 0).
        seed: the weights' seed.
        cameras: the cameras it reads, one ``observation.images.<camera>`` each; default: one
            ``observation.image``.
        state_dim: D > 0 adds the robot's state, ``observation.state`` (D,), normalised by a zero
            mean and a standard deviation of 1.
    """
    require_lerobot()
    from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy

    config = ACTConfig(
        input_features=_input_features(cameras, image_size, state_dim),
        output_features={"action": PolicyFeature(FeatureType.ACTION, (action_dim,))},
        chunk_size=predicted or chunk, n_action_steps=chunk, dim_model=width, n_heads=2, dim_feedforward=2 * width,
        n_encoder_layers=1, n_decoder_layers=1, n_vae_encoder_layers=1, latent_dim=8,
        pretrained_backbone_weights=None, device="cpu",
        # Images reach the backbone as [0, 1]; actions are normalised by the statistics below.
        normalization_mapping={"VISUAL": NormalizationMode.IDENTITY, "STATE": NormalizationMode.MEAN_STD,
                               "ACTION": NormalizationMode.MEAN_STD})
    return _save_new(ACTPolicy, config, Path(out), action_dim, action_std, seed)


def new_smolvla(out: Path, image_size: int = 96, action_dim: int = 4, chunk: int = 5, predicted: int = 8,
                steps: int = 3, action_std: float = 1.0, seed: int = 0, full_size: bool = False,
                cameras: Sequence[str] = (), state_dim: int = 0) -> Path:
    """Writes a randomly initialised SmolVLA policy to `out`, with the vision-language model it is
    built on in ``out/vlm`` (SmolVLA reads its VLM's config, tokenizer and image processor from
    ``vlm_model_name``; a real one comes from a model hub, which is not reachable here). For
    exercising the flow path offline, not for acting well.

    Args:
        chunk: actions executed per call (``n_action_steps``), gymnast's K.
        predicted: actions predicted per call (``chunk_size``).
        steps: flow integration steps.
        full_size: LeRobot's published SmolVLA architecture (`SMOLVLM2_500M`, SmolVLA's own
            defaults for the layers kept, the image side, the token and padding lengths) instead
            of a tiny one: for timing the real thing (benchmarks/lerobot_gpu.py).
        cameras, state_dim: as `new_act`'s.
    """
    require_lerobot()
    from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
    from lerobot.policies.smolvla.configuration_smolvla import SmolVLAConfig
    from lerobot.policies.smolvla.modeling_smolvla import SmolVLAPolicy

    out = Path(out)
    sizes = SMOLVLM2_500M if full_size else TINY_VLM
    vlm = write_vlm(out / "vlm", sizes)
    # Full size keeps SmolVLA's defaults (16 VLM layers, 48 tokens, 32 padded dimensions).
    shape = {} if full_size else {"max_state_dim": 8, "max_action_dim": 8, "tokenizer_max_length": 16,
                                  "num_vlm_layers": 2}
    config = SmolVLAConfig(
        input_features=_input_features(cameras, image_size, state_dim),
        output_features={"action": PolicyFeature(FeatureType.ACTION, (action_dim,))},
        chunk_size=predicted, n_action_steps=chunk, num_steps=steps,
        resize_imgs_with_padding=(sizes.image_side, sizes.image_side), vlm_model_name=str(vlm.resolve()),
        load_vlm_weights=False, device="cpu", **shape,
        normalization_mapping={"VISUAL": NormalizationMode.IDENTITY, "STATE": NormalizationMode.MEAN_STD,
                               "ACTION": NormalizationMode.MEAN_STD})
    return _save_new(SmolVLAPolicy, config, out, action_dim, action_std, seed)


@dataclasses.dataclass(frozen=True)
class VLMSizes:
    """The sizes of a SmolVLM: a SigLIP vision tower, a pixel shuffle, a Llama text model."""

    image_side: int
    patch: int
    vision_width: int
    vision_layers: int
    vision_heads: int
    vision_ffn: int
    text_width: int
    text_layers: int
    text_heads: int
    text_kv_heads: int
    text_ffn: int
    vocabulary: int  # rows of the token embedding (the word-level tokenizer below uses a few)
    shuffle: int  # pixel-shuffle factor: (image_side / patch / shuffle) ** 2 image tokens

    @property
    def image_tokens(self) -> int:
        return (self.image_side // self.patch // self.shuffle) ** 2


# 16 patches of 8 px, 4 image tokens after the shuffle.
TINY_VLM = VLMSizes(image_side=32, patch=8, vision_width=32, vision_layers=1, vision_heads=2, vision_ffn=64,
                    text_width=64, text_layers=2, text_heads=4, text_kv_heads=2, text_ffn=128, vocabulary=0,
                    shuffle=2)
# HuggingFaceTB/SmolVLM2-500M-Video-Instruct, SmolVLA's backbone: SigLIP base patch16/512 and
# SmolLM2-360M (SmolVLA keeps its first 16 of 32 layers).
SMOLVLM2_500M = VLMSizes(image_side=512, patch=16, vision_width=768, vision_layers=12, vision_heads=12,
                         vision_ffn=3072, text_width=960, text_layers=32, text_heads=15, text_kv_heads=5,
                         text_ffn=2560, vocabulary=49280, shuffle=4)
_WORDS = ("reach the goal push puck open close drawer window press button pick and place a to of "
          "red green blue put on in").split()


def write_vlm(out: Path, sizes: VLMSizes = TINY_VLM) -> Path:
    """Writes a SmolVLM config of `sizes`, a word-level tokenizer and an image processor to `out`."""
    allow_torchvision_import()  # transformers' processors import torchvision where it is installed
    from tokenizers import Tokenizer, models, pre_tokenizers
    from transformers import (PreTrainedTokenizerFast, SmolVLMConfig, SmolVLMImageProcessor, SmolVLMProcessor,
                              SmolVLMVideoProcessor)

    special = {"fake_image_token": "<fake_token_around_image>", "image_token": "<image>",
               "global_image_token": "<global-img>", "end_of_utterance_token": "<end_of_utterance>"}
    vocab = {word: i for i, word in enumerate(dict.fromkeys(["<unk>", "<pad>", *special.values(), "\n", *_WORDS]))}
    tokenizer = Tokenizer(models.WordLevel(vocab=vocab, unk_token="<unk>"))
    tokenizer.pre_tokenizer = pre_tokenizers.WhitespaceSplit()
    fast = PreTrainedTokenizerFast(tokenizer_object=tokenizer, unk_token="<unk>", pad_token="<pad>",
                                   extra_special_tokens=special)
    side = {"longest_edge": sizes.image_side}
    images = SmolVLMImageProcessor(do_resize=False, do_image_splitting=False, max_image_size=side, size=side)
    SmolVLMProcessor(image_processor=images, tokenizer=fast, video_processor=SmolVLMVideoProcessor(),
                     image_seq_len=sizes.image_tokens).save_pretrained(out)
    vocabulary = max(sizes.vocabulary, len(vocab))
    head_dim = sizes.text_width // sizes.text_heads
    SmolVLMConfig(
        vision_config={"hidden_size": sizes.vision_width, "intermediate_size": sizes.vision_ffn,
                       "num_hidden_layers": sizes.vision_layers, "num_attention_heads": sizes.vision_heads,
                       "image_size": sizes.image_side, "patch_size": sizes.patch},
        text_config={"model_type": "llama", "hidden_size": sizes.text_width, "intermediate_size": sizes.text_ffn,
                     "num_hidden_layers": sizes.text_layers, "num_attention_heads": sizes.text_heads,
                     "num_key_value_heads": sizes.text_kv_heads, "head_dim": head_dim, "vocab_size": vocabulary,
                     "max_position_embeddings": 8192 if sizes.vocabulary else 256},
        scale_factor=sizes.shuffle, image_token_id=vocab["<image>"], vocab_size=vocabulary).save_pretrained(out)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the pretrained_model folder to write")
    parser.add_argument("--image-size", type=int, default=96, help="side of the square camera image it reads")
    parser.add_argument("--action-dim", type=int, default=4, help="action dimensions A")
    parser.add_argument("--chunk", type=int, default=5, help="actions executed per call (gymnast's chunk K)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random weights")
    parser.add_argument("--cameras", default="", help="cameras it reads, comma-separated (default: one observation.image)")
    parser.add_argument("--state-dim", type=int, default=0, help="size of the robot state it reads (0: none)")
    args = parser.parse_args(argv)
    cameras = [name for name in args.cameras.split(",") if name]
    print(new_act(args.out, args.image_size, args.action_dim, args.chunk, seed=args.seed, cameras=cameras,
                  state_dim=args.state_dim))



def _input_features(cameras: Sequence[str], image_size: int, state_dim: int) -> dict:
    """The input features of a policy of `cameras` (none: one ``observation.image``) and, for
    `state_dim` > 0, a robot state."""
    from lerobot.configs.types import FeatureType, PolicyFeature

    keys = [f"observation.images.{name}" for name in cameras] or ["observation.image"]
    features = {key: PolicyFeature(FeatureType.VISUAL, (3, image_size, image_size)) for key in keys}
    if state_dim:
        features["observation.state"] = PolicyFeature(FeatureType.STATE, (state_dim,))
    return features


def _save_new(policy_class, config, out: Path, action_dim: int, action_std: float, seed: int) -> Path:
    """Builds `policy_class(config)` from `seed` and writes it to `out` with its pre- and
    post-processors, the actions normalised by a zero mean and `action_std` (a state by a zero
    mean and a standard deviation of 1)."""
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(seed)
    policy = policy_class(config)
    stats = {"action": {"mean": torch.zeros(action_dim), "std": torch.full((action_dim,), float(action_std))}}
    if "observation.state" in config.input_features:
        size = config.input_features["observation.state"].shape[0]
        stats["observation.state"] = {"mean": torch.zeros(size), "std": torch.ones(size)}
    preprocessor, postprocessor = make_pre_post_processors(config, dataset_stats=stats)
    for part in (policy, preprocessor, postprocessor):
        part.save_pretrained(out)
    return out


if __name__ == "__main__":
    main()
