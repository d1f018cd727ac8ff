"""Which side of the object the photos saw: the covered arc of azimuth and its best-covered view.

A turntable should not invent the side nobody photographed. Azimuths are degrees about the orbit's
up axis; `covered_arc` finds the arc the cameras span (the circle less its largest empty gap), the
swing path goes across that arc and back, and the poster faces the densest cluster of cameras.
"""

from __future__ import annotations

import math

import numpy as np

FULL_TURN_SPAN = 300.0  # degrees: photos covering at least this much get a full turn
CLUSTER_WIDTH = 20.0  # degrees: spread of the kernel that finds the densest cluster of cameras


def azimuths_about(points: np.ndarray, centre: np.ndarray, up: np.ndarray,
                   reference: np.ndarray) -> np.ndarray:
    """(N,) azimuths in [0, 360) of `points` (N, 3) about `centre` (3,) and unit `up` (3,),
    measured from the unit `reference` (3,) (perpendicular to `up`) towards up x reference."""
    offsets = np.asarray(points, dtype=np.float64) - centre
    side = np.cross(up, reference)
    return np.degrees(np.arctan2(offsets @ side, offsets @ reference)) % 360.0


def gaps_between(azimuths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sorted azimuths (N,) in [0, 360), the empty gap after each (N,)), the last one wrapping
    round to the first."""
    a = np.sort(np.asarray(azimuths, dtype=np.float64) % 360.0)
    if a.size == 0:
        raise ValueError("no azimuths to cover")
    return a, np.diff(np.append(a, a[0] + 360.0))


def covered_arc(azimuths: np.ndarray) -> tuple[float, float]:
    """(start, span) in degrees of the smallest arc holding every azimuth (N,).

    The arc is the circle less its largest gap between neighbouring azimuths, so it runs from
    `start` (in [0, 360)) counter-clockwise through `span` degrees; a single azimuth spans 0 and
    cameras all round span 360 less their widest spacing.
    """
    a, gaps = gaps_between(azimuths)
    widest = int(np.argmax(gaps))
    start = a[(widest + 1) % a.size]
    return float(start), float(360.0 - gaps[widest])


def unbroken_arc(azimuths: np.ndarray, min_gap: float) -> tuple[float, float]:
    """(start, span) in degrees of the widest arc over which neighbouring azimuths (N,) stand
    less than `min_gap` apart: `covered_arc` less what lies beyond its other empty gaps (a photo
    alone across an empty arc widens the arc the cameras span, but shows only its own side)."""
    a, gaps = gaps_between(azimuths)
    empty = np.flatnonzero(gaps >= min_gap)
    if empty.size <= 1:
        return covered_arc(azimuths)
    starts = a[(empty + 1) % a.size]  # each run of photos begins after an empty gap
    spans = (a[np.roll(empty, -1)] - starts) % 360.0  # and ends where the next one begins
    widest = int(np.argmax(spans))
    return float(starts[widest]), float(spans[widest])


def swing_azimuths(start: float, span: float, frames: int) -> np.ndarray:
    """(frames,) azimuths going from `start` across `span` degrees and back with a cosine ease.

    The camera slows to rest at both ends of the arc; the last frame stops one step short of the
    first, so the video loops without a jump or a repeated frame.
    """
    phase = 2 * np.pi * np.arange(frames) / frames
    return start + span * (1 - np.cos(phase)) / 2


def turn_azimuths(start: float, frames: int) -> np.ndarray:
    """(frames,) azimuths evenly over one full turn from `start`, the last one step short of it."""
    return start + 360.0 * np.arange(frames) / frames


def best_covered_frame(frame_azimuths: np.ndarray, camera_azimuths: np.ndarray) -> int:
    """Index of the frame (of azimuths (F,)) facing the densest cluster of cameras (azimuths (N,)).

    Density is a sum of von Mises kernels about each camera (`CLUSTER_WIDTH` wide), so a lone
    stray photo does not outweigh the side most photos were taken from.
    """
    kappa = 1.0 / math.radians(CLUSTER_WIDTH) ** 2
    diff = np.radians(np.asarray(frame_azimuths)[:, None] - np.asarray(camera_azimuths)[None, :])
    density = np.exp(kappa * (np.cos(diff) - 1.0)).sum(axis=1)  # (F,)
    return int(np.argmax(density))
