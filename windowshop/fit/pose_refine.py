"""A held-out camera's pose, refined against the trained model before the photo is scored.

A photo held out of training keeps the pose structure-from-motion gave it, and a pose a few
tenths of a degree off moves every edge of the render by pixels: its PSNR then measures the pose
and not the model (NeRF-- and BARF refine test poses for this reason before scoring them). Here a
few Levenberg-Marquardt steps on a small, blurred copy of the photo, with the Jacobian taken by
finite differences of whole renders (the model needs no gradient with respect to its rays), move
the camera by at most MAX_TURN: enough for the error of a good pose, never enough to turn a
wrong (folded) camera into a right one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from windowshop.model import RadianceModel
from windowshop.render.frames import render_camera
from windowshop.scene.types import Camera

# Coarse to fine: (pixels of the longer side of the copy fitted, blur's sigma in its pixels).
# The blurred small copies give a basin as wide as a degree's error; the last level, at most
# the photo's own size, makes it exact (at 64 pixels point-sampled renders of lego_tiny's
# 100-pixel photos settled 0.4 degrees off their true poses)
LEVELS = ((64, 1.5), (128, 1.0), (128, 0.5))
MAX_TURN = math.radians(3.0)  # the largest correction: a rotation, or a move of that angle's tangent
STEP = math.radians(0.25)  # finite-difference step of every parameter
ITERATIONS = 3  # per level
# What a correction of a degree (or a move of its tangent) must lower the mean squared error by
# to be taken: a real capture's model errs by 0.003-0.008 (22-25 dB), and without this price
# kermit's held-out cameras wandered 0.4-2.4 degrees along the valley where a turn and a move
# nearly cancel, to a pose that scored worse at full size
PRIOR = 1e-4


@dataclass(frozen=True)
class Refined:
    """A camera after refinement, and how far it moved."""

    camera: Camera
    turn_deg: float  # rotation of the correction
    shift: float  # move of the camera's centre, as a share of its distance to the object


def moved(camera: Camera, delta: np.ndarray) -> Camera:
    """`camera` turned by the rotation vector `delta[:3]` (radians, its own axes) about its centre
    and moved by `delta[3:]` (its own axes, in units of its distance to the origin, the object)."""
    local = np.eye(4)
    local[:3, :3] = rotation(delta[:3])
    local[:3, 3] = delta[3:] * max(float(np.linalg.norm(camera.center)), 1e-6)
    return replace(camera, c2w=camera.c2w @ local)


def rotation(vector: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a rotation vector."""
    return Rotation.from_rotvec(vector).as_matrix()


def small_copy(image: np.ndarray, camera: Camera, size: int, blur: float) -> tuple[np.ndarray, Camera]:
    """`image` (H, W, 3) area-averaged to `size` on its longer side (never enlarged) and
    blurred by `blur`, with its camera."""
    scale = min(1.0, size / max(camera.width, camera.height))
    width, height = max(8, round(camera.width * scale)), max(8, round(camera.height * scale))
    small = cv2.resize(np.asarray(image, dtype=np.float32), (width, height), interpolation=cv2.INTER_AREA)
    return blurred(small, blur), camera.resized(width, height)


def blurred(image: np.ndarray, sigma: float) -> np.ndarray:
    """`image` (H, W, 3) under a Gaussian of `sigma` pixels (edges repeated)."""
    return cv2.GaussianBlur(np.asarray(image, dtype=np.float32), (0, 0), sigma,
                            borderType=cv2.BORDER_REPLICATE)


def limited(delta: np.ndarray) -> np.ndarray:
    """`delta` with its rotation and its move each at most MAX_TURN (the move as its tangent)."""
    out = delta.copy()
    for part, limit in ((slice(0, 3), MAX_TURN), (slice(3, 6), math.tan(MAX_TURN))):
        norm = float(np.linalg.norm(out[part]))
        if norm > limit:
            out[part] *= limit / norm
    return out


def refine_camera(model: RadianceModel, camera: Camera, image: np.ndarray,
                  background: tuple[float, float, float], memory_budget: int) -> Refined:
    """`camera` moved (by at most MAX_TURN) so that the model's render best matches `image`."""
    delta = np.zeros(6)
    for size, blur in LEVELS:
        delta = _fit_level(model, camera, image, background, memory_budget, size, blur, delta)
    return Refined(moved(camera, delta), math.degrees(float(np.linalg.norm(delta[:3]))),
                   float(np.linalg.norm(delta[3:])))


def _fit_level(model: RadianceModel, camera: Camera, image: np.ndarray,
               background: tuple[float, float, float], memory_budget: int, size: int, blur: float,
               delta: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt steps from `delta` on one level's copy; the correction."""
    target, small = small_copy(image, camera, size, blur)

    def residual(at: np.ndarray) -> np.ndarray:
        frame = render_camera(model, moved(small, at), background, memory_budget)
        image = (blurred(frame.rgb, blur) - target).reshape(-1).astype(np.float64)
        return np.concatenate([image / math.sqrt(image.size), math.sqrt(PRIOR) * at / math.radians(1.0)])

    damping, r = 1e-3, residual(delta)
    # the Jacobian of the level's start serves all its steps (6 renders, not 6 per step): the
    # corrections are small against the blur, so it hardly changes
    jacobian = np.stack([(residual(delta + STEP * e) - r) / STEP for e in np.eye(6)], axis=1)
    normal = jacobian.T @ jacobian
    for _ in range(ITERATIONS):
        gradient = jacobian.T @ r
        for _ in range(3):  # damping raised until a step lowers the error
            step = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-9), -gradient)
            candidate = limited(delta + step)
            tried = residual(candidate)
            if tried @ tried < r @ r:
                delta, r, damping = candidate, tried, damping / 3
                break
            damping *= 10
        else:
            break
    return delta
