"""The known-turntable prior: a ring fitted to placed cameras, and guesses for the rest."""

from __future__ import annotations

import numpy as np
import pytest

from windowshop.photos.ring import Ring, fill_azimuths, fit_ring, guess_poses

TRUE = Ring(centre=np.array([0.3, -1.0, 2.0]), axis=np.array([0.0, 0.6, 0.8]), radius=4.0,
            height=1.5)


def _cameras(azimuths_deg) -> np.ndarray:
    return np.stack([TRUE.camera(np.radians(a)) for a in azimuths_deg])


def _in_view(c2w: np.ndarray, point: np.ndarray) -> np.ndarray:
    """`point` in the camera's OpenGL axes (x right, y up, z backward)."""
    return c2w[:3, :3].T @ (point - c2w[:3, 3])


def test_fit_recovers_a_known_ring_from_three_cameras():
    ring = fit_ring(_cameras([10, 100, 250]))
    # (the centre's weak pull towards the cameras' mean moves it by about 1e-6)
    assert np.allclose(ring.centre, TRUE.centre, atol=1e-4)
    assert np.allclose(ring.axis, TRUE.axis, atol=1e-6)  # the sign too: along the cameras' up
    assert ring.radius == pytest.approx(TRUE.radius, abs=1e-4)
    assert ring.height == pytest.approx(TRUE.height, abs=1e-4)


def test_a_camera_on_the_ring_looks_at_the_centre_upright():
    c2w = TRUE.camera(np.radians(37.0))
    seen = _in_view(c2w, TRUE.centre)
    assert np.allclose(seen[:2], 0.0, atol=1e-9) and seen[2] < 0  # centre of the image, ahead
    assert c2w[:3, 1] @ TRUE.axis > 0.5  # its up is the ring's up
    assert abs(c2w[:3, 0] @ TRUE.axis) < 1e-9  # no roll
    assert TRUE.azimuth(c2w[None, :3, 3])[0] == pytest.approx(np.radians(37.0))


def test_fill_interpolates_by_shooting_order_across_the_wrap():
    # 8 photos 45 degrees apart, going clockwise; 0, 3 and 7 missing
    known = {i: np.radians(-45.0 * i) for i in (1, 2, 4, 5, 6)}
    filled = fill_azimuths(8, known)
    assert sorted(filled) == [0, 3, 7]
    for i, angle in filled.items():
        assert np.angle(np.exp(1j * (angle - np.radians(-45.0 * i)))) == pytest.approx(0.0,
                                                                                        abs=1e-9)


def test_fill_extrapolates_an_open_arc():
    # 6 photos 20 degrees apart over 100 degrees: the order does not close the ring
    known = {i: np.radians(20.0 * i) for i in (1, 2, 3)}
    filled = fill_azimuths(6, known)
    assert np.degrees([filled[0], filled[4], filled[5]]) == pytest.approx([0.0, 80.0, 100.0])


def test_guesses_land_on_the_true_cameras():
    azimuths = [45.0 * i for i in range(8)]
    truth = _cameras(azimuths)
    placed = {i: truth[i] for i in (0, 1, 4, 6)}
    guesses = guess_poses(placed, 8)
    assert sorted(guesses) == [2, 3, 5, 7]
    for i, c2w in guesses.items():
        assert np.allclose(c2w, truth[i], atol=1e-4)
