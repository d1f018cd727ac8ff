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
