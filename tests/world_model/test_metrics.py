"""Image-quality measures against hand-computed values and slow loop references."""

import math

import numpy as np
import pytest
import torch

from gymnast.world_model.metrics import (
    PerceptualDistance,
    masked_psnr,
    moving_mask,
    psnr,
    ssim,
    summarize_horizons,
    to_unit_float,
)


def _images(*shape: int, seed: int = 0) -> torch.Tensor:
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed))


def _noisy(images: torch.Tensor, sigma: float, seed: int = 1) -> torch.Tensor:
    noise = torch.randn(images.shape, generator=torch.Generator().manual_seed(seed))
    return (images + sigma * noise).clamp(0, 1)


@pytest.fixture(scope="module")
def perceptual() -> PerceptualDistance:
    return PerceptualDistance()


def test_to_unit_float_moves_channels_first_and_scales():
    frames = torch.randint(0, 256, (2, 5, 8, 9, 3), dtype=torch.uint8)
    out = to_unit_float(frames)
    assert out.shape == (2, 5, 3, 8, 9) and out.dtype == torch.float32
    assert torch.equal(out[1, 2, :, 3, 4], frames[1, 2, 3, 4].float() / 255)


@pytest.mark.parametrize("frames", [torch.zeros(2, 8, 8, 3), torch.zeros(2, 8, 8, 4, dtype=torch.uint8)])
def test_to_unit_float_rejects_wrong_dtype_or_shape_naming_the_shape(frames):
    with pytest.raises(ValueError, match=str(tuple(frames.shape)).replace("(", r"\(").replace(")", r"\)")):
        to_unit_float(frames)


def test_psnr_of_identical_images_is_max_db():
    x = _images(2, 3, 3, 16, 16)
    assert torch.equal(psnr(x, x), torch.full((2, 3), 100.0))
    assert torch.allclose(psnr(x, x, max_db=60.0), torch.full((2, 3), 60.0))


def test_psnr_of_a_known_mse_follows_the_formula():
    x = torch.full((4, 3, 8, 8), 0.5)
    y = x + torch.tensor([0.1, 0.01, 0.2, 0.05]).view(4, 1, 1, 1)  # mse = offset^2
    expected = torch.tensor([20.0, 40.0, 10 * math.log10(25), 10 * math.log10(400)])
    assert torch.allclose(psnr(y, x), expected, atol=1e-4)


def test_psnr_is_float32_for_half_inputs():
    x = _images(2, 3, 8, 8)
    assert psnr(x.half(), _noisy(x, 0.1).half()).dtype == torch.float32


def test_masked_psnr_counts_only_masked_pixels():
    target = _images(2, 3, 16, 16)
    pred = _noisy(target, 0.1)
    mask = torch.zeros(2, 1, 16, 16, dtype=torch.bool)
    mask[:, :, 4:10, 2:12] = True
    changed = torch.where(mask, pred, torch.rand_like(pred))  # unmasked pixels scrambled
    assert torch.allclose(masked_psnr(pred, target, mask), masked_psnr(changed, target, mask))
    manual = (pred - target)[:, :, 4:10, 2:12].square().mean(dim=(1, 2, 3))
    assert torch.allclose(masked_psnr(pred, target, mask), 10 * torch.log10(1 / manual), atol=1e-4)
    assert torch.allclose(masked_psnr(pred, target, torch.ones_like(mask)), psnr(pred, target))


def test_masked_psnr_is_nan_for_an_empty_mask():
    target = _images(2, 3, 8, 8)
    mask = torch.zeros(2, 1, 8, 8)
    mask[0, 0, 3, 3] = 1.0
    out = masked_psnr(_noisy(target, 0.1), target, mask)
    assert torch.isfinite(out[0]) and torch.isnan(out[1])


def test_moving_mask_picks_exactly_the_changed_pixels_and_broadcasts():
    first = _images(2, 1, 3, 8, 8)
    target = first.repeat(1, 4, 1, 1, 1)  # (B, T, 3, H, W), static
    target[0, 2, 1, 5, 6] += 0.2  # one channel moves enough
    target[1, 3, 0, 2, 2] += 0.01  # below the threshold
    mask = moving_mask(target, first)
    assert mask.shape == (2, 4, 1, 8, 8) and mask.dtype == torch.bool
    expected = torch.zeros_like(mask)
    expected[0, 2, 0, 5, 6] = True
    assert torch.equal(mask, expected)


def _ssim_reference(x: np.ndarray, y: np.ndarray) -> float:
    """SSIM of two (3, H, W) images, one window position at a time."""
    g = np.exp(-((np.arange(11) - 5.0) ** 2) / (2 * 1.5**2))
    w = np.outer(g, g) / np.outer(g, g).sum()
    c1, c2 = 0.01**2, 0.03**2
    values = []
    for c in range(3):
        for i in range(x.shape[1] - 10):
            for j in range(x.shape[2] - 10):
                a, b = x[c, i : i + 11, j : j + 11], y[c, i : i + 11, j : j + 11]
                mu_a, mu_b = (w * a).sum(), (w * b).sum()
                var_a, var_b = (w * (a - mu_a) ** 2).sum(), (w * (b - mu_b) ** 2).sum()
                cov = (w * (a - mu_a) * (b - mu_b)).sum()
                values.append((2 * mu_a * mu_b + c1) * (2 * cov + c2) / ((mu_a**2 + mu_b**2 + c1) * (var_a + var_b + c2)))
    return float(np.mean(values))


def test_ssim_matches_a_loop_reference():
    x = _images(2, 3, 3, 16, 14)
    y = _noisy(x, 0.15)
    out = ssim(x, y)
    assert out.shape == (2, 3)
    for b in range(2):
        for t in range(3):
            expected = _ssim_reference(x[b, t].double().numpy(), y[b, t].double().numpy())
            assert abs(out[b, t].item() - expected) < 1e-4


def test_ssim_is_one_for_identical_images_and_drops_with_noise():
    x = _images(4, 3, 32, 32)
    assert torch.allclose(ssim(x, x), torch.ones(4), atol=1e-5)
    slight, heavy = ssim(_noisy(x, 0.05), x), ssim(_noisy(x, 0.2), x)
    assert (slight < 1).all() and (heavy < slight).all()


def test_perceptual_distance_is_zero_for_identical_images_and_symmetric(perceptual):
    x = _images(3, 3, 64, 64)
    y = _noisy(x, 0.1)
    assert torch.allclose(perceptual(x, x), torch.zeros(3))
    assert (perceptual(x, y) > 0).all()
    assert torch.allclose(perceptual(x, y), perceptual(y, x))


def test_perceptual_distance_grows_as_images_diverge(perceptual):
    x = _images(3, 3, 64, 64)
    assert (perceptual(_noisy(x, 0.05), x) < perceptual(_noisy(x, 0.2), x)).all()


def test_perceptual_distance_keeps_leading_dims_and_is_frozen(perceptual):
    x = _images(2, 3, 3, 96, 96)
    out = perceptual(_noisy(x, 0.1), x)
    assert out.shape == (2, 3) and out.dtype == torch.float32
    assert not perceptual.training and not any(p.requires_grad for p in perceptual.parameters())
    perceptual.train()
    assert not perceptual.training


def test_perceptual_distance_does_not_depend_on_chunking(perceptual):
    x = _images(300, 3, 16, 16)
    y = _noisy(x, 0.1)
    whole = perceptual(x, y)  # two chunks: 256 + 44
    parts = torch.cat([perceptual(x[:100], y[:100]), perceptual(x[100:], y[100:])])
    assert whole.shape == (300,)
    assert torch.allclose(whole, parts, atol=1e-5)


def test_summarize_horizons_on_ragged_rollouts():
    values = torch.arange(2 * 40, dtype=torch.float32).view(2, 40)  # row 0: 0..39, row 1: 40..79
    values[1, 20:] = math.nan  # the second episode ended after 20 frames
    out = summarize_horizons(values)
    assert out["h1"] == pytest.approx(20.0)  # (0 + 40) / 2
    assert out["h8"] == pytest.approx(27.0)  # (7 + 47) / 2
    assert out["h32"] == pytest.approx(31.0)  # only row 0
    assert out["avg32"] == pytest.approx((sum(range(32)) + sum(range(40, 60))) / 52)
    assert out["full"] == pytest.approx((sum(range(40)) + sum(range(40, 60))) / 60)
    short = summarize_horizons(values[:, :10])
    assert short["h32"] is None and short["avg32"] is None and short["h8"] == pytest.approx(27.0)
    # Every 5th step measured (a model of one frame per chunk of 5): each horizon at the next measured step.
    chunks = summarize_horizons(values, measured_every=5)
    assert chunks["h1"] == pytest.approx(24.0) and chunks["h8"] == pytest.approx(29.0)  # steps 5 and 10
    assert chunks["h32"] == pytest.approx(34.0)  # step 35, row 0 only


def test_distances_to_shared_references_equal_the_pairwise_ones():
    from gymnast.world_model.metrics import PerceptualDistance

    perceptual = PerceptualDistance(pretrained=False, chunk_size=5)  # chunks that cut across rollouts
    generator = torch.Generator().manual_seed(0)
    pred = torch.rand(3, 4, 3, 32, 32, generator=generator)
    references = torch.rand(2, 4, 3, 32, 32, generator=generator)
    index = torch.tensor([1, 0, 1])
    shared = perceptual.against_references(pred, references, index)
    assert shared.shape == (3, 4)
    torch.testing.assert_close(shared, perceptual(pred, references[index]), atol=1e-5, rtol=1e-5)
    # Repeated frames (a model of one frame per chunk): the same distances, the repeats computed once.
    held_pred, held_references = pred.repeat_interleave(3, dim=1), references.repeat_interleave(3, dim=1)
    held_references[0, 1] = references[0, 0] * 0.5  # a reference that changes where its rollouts repeat
    torch.testing.assert_close(perceptual.against_references(held_pred, held_references, index),
                               perceptual(held_pred, held_references[index]), atol=1e-5, rtol=1e-5)
    with pytest.raises(ValueError, match="must agree"):
        perceptual.against_references(pred, references[:, :3], index)
