"""PSNR and SSIM against closed forms."""

import math

import numpy as np
import pytest

from windowshop.metrics import gaussian_window, psnr, ssim


def test_psnr_of_a_known_error():
    a = np.zeros((8, 8, 3))
    assert psnr(a, a + 0.1) == pytest.approx(20.0)  # MSE 0.01
    assert psnr(a, a) == math.inf


def test_ssim_of_identical_images_is_one():
    img = np.random.default_rng(0).random((32, 32, 3))
    assert ssim(img, img) == pytest.approx(1.0)


def test_ssim_of_constant_images_is_the_luminance_term():
    # no variance: SSIM = (2 m1 m2 + C1) / (m1^2 + m2^2 + C1)
    m1, m2, c1 = 0.3, 0.7, 0.01 ** 2
    expected = (2 * m1 * m2 + c1) / (m1 ** 2 + m2 ** 2 + c1)
    assert ssim(np.full((20, 20, 3), m1), np.full((20, 20, 3), m2)) == pytest.approx(expected)


def test_ssim_of_a_contrast_flip_is_negative_and_symmetric():
    rng = np.random.default_rng(1)
    img = rng.random((24, 24, 3))
    assert ssim(img, 1 - img) < 0
    noisy = np.clip(img + 0.05 * rng.standard_normal(img.shape), 0, 1)
    assert ssim(img, noisy) == pytest.approx(ssim(noisy, img))
    assert 0 < ssim(img, noisy) < 1


def test_window_is_the_papers_gaussian():
    w = gaussian_window()
    assert w.shape == (11,) and w.sum() == pytest.approx(1.0)
    assert w[6] / w[5] == pytest.approx(math.exp(-0.5 / 1.5 ** 2))


def test_mismatched_shapes_are_rejected():
    with pytest.raises(ValueError):
        psnr(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))


