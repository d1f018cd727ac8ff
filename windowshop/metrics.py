"""Image quality as the NeRF papers measure it, on (H, W, 3) float arrays in [0, 1].

PSNR = -10 log10(MSE); SSIM (Wang et al. 2004) with an 11x11 Gaussian window of sigma 1.5,
K1 = 0.01, K2 = 0.03, 'valid' filtering (as `tf.image.ssim` used by NeRF), averaged over pixels
and channels.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


def mse(a: np.ndarray, b: np.ndarray) -> float:
    """Mean squared difference of two images of the same shape."""
    a, b = _pair(a, b)
    return float(np.mean((a - b) ** 2))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """Peak signal-to-noise ratio in dB of images in [0, 1] (inf for identical images)."""
    error = mse(a, b)
    return float("inf") if error == 0 else float(-10.0 * np.log10(error))


def aligned_psnr(render: np.ndarray, truth: np.ndarray, max_shift: float = 0.03) -> float:
    """PSNR of `render` against `truth` (H, W, 3) after the whole-pixel shift that best aligns
    them (phase correlation), at most `max_shift` of the image's longer side, over the part the
    two share: a small error in a held-out photo's camera moves its picture almost rigidly, and
    this measures the model rather than that error."""
    import cv2  # only this check needs OpenCV here

    render, truth = _pair(render, truth)
    grey = [np.ascontiguousarray(x.mean(axis=-1), dtype=np.float64) for x in (render, truth)]
    (dx, dy), _ = cv2.phaseCorrelate(grey[0], grey[1])
    limit = max_shift * max(truth.shape[:2])
    dx, dy = (int(round(float(np.clip(d, -limit, limit)))) for d in (dx, dy))
    h, w = truth.shape[:2]
    moved = render[max(0, -dy):h - max(0, dy), max(0, -dx):w - max(0, dx)]
    seen = truth[max(0, dy):h - max(0, -dy), max(0, dx):w - max(0, -dx)]
    return psnr_of_mse(float(np.mean((moved - seen) ** 2)))


def psnr_of_mse(error: float) -> float:
    """PSNR in dB of a mean squared error (of [0, 1] values)."""
    return float("inf") if error <= 0 else float(-10.0 * np.log10(error))


def gaussian_window(size: int = 11, sigma: float = 1.5) -> np.ndarray:
    """(size,) normalised 1D Gaussian taps."""
    x = np.arange(size, dtype=np.float64) - (size - 1) / 2
    taps = np.exp(-0.5 * (x / sigma) ** 2)
    return taps / taps.sum()


def ssim(a: np.ndarray, b: np.ndarray, size: int = 11, sigma: float = 1.5,
         k1: float = 0.01, k2: float = 0.03) -> float:
    """Structural similarity of two (H, W, C) or (H, W) images in [0, 1]; H, W at least `size`."""
    a, b = _pair(a, b)
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    if min(a.shape[:2]) < size:
        raise ValueError(f"SSIM needs images of at least {size}x{size} pixels, got {a.shape[:2]}")
    taps = torch.from_numpy(gaussian_window(size, sigma))
    x = torch.from_numpy(np.stack([a, b])).permute(0, 3, 1, 2).reshape(-1, 1, *a.shape[:2])

    def blur(img: torch.Tensor) -> torch.Tensor:  # separable 'valid' Gaussian filter
        img = F.conv2d(img, taps.view(1, 1, 1, -1))
        return F.conv2d(img, taps.view(1, 1, -1, 1))

    channels = a.shape[2]
    xa, xb = x[:channels], x[channels:]
    mu_a, mu_b = blur(xa), blur(xb)
    var_a = blur(xa * xa) - mu_a ** 2
    var_b = blur(xb * xb) - mu_b ** 2
    cov = blur(xa * xb) - mu_a * mu_b
    c1, c2 = k1 ** 2, k2 ** 2
    index = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))
    return float(index.mean())


def _pair(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    return a, b
