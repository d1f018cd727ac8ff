"""Camera geometry, the one home for it: pose conventions (every source's camera axes converted to
OpenGL camera-to-world, and checks), look-at, the point the cameras look at, and a capture's up."""

from __future__ import annotations

from typing import Literal

import numpy as np

from windowshop.errors import UserError

# OpenCV/COLMAP camera axes (x right, y down, z forward) -> OpenGL (x right, y up, z backward).
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def checked_rotation(rot: np.ndarray, where: str, tol: float = 1e-2) -> np.ndarray:
    """`rot` (3, 3) re-orthonormalised, or a UserError naming `where` if it is not a rotation."""
    rot = np.asarray(rot, dtype=np.float64)
    if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
        raise UserError(f"{where}: the pose's rotation is not a finite 3x3 matrix")
    err = np.abs(rot.T @ rot - np.eye(3)).max()
    if err > tol or np.linalg.det(rot) < 0:
        raise UserError(f"{where}: the pose is not a rotation (R^T R deviates from I by {err:.3g}, "
                        f"det {np.linalg.det(rot):.3g}); fix or re-export the camera poses")
    u, _, vt = np.linalg.svd(rot)
    return u @ vt


def c2w_matrix(c2w: np.ndarray, where: str) -> np.ndarray:
    """A (4, 4) camera-to-world from a (3, 4) or (4, 4) matrix, its rotation checked."""
    c2w = np.asarray(c2w, dtype=np.float64)
    if c2w.shape not in ((3, 4), (4, 4)):
        raise UserError(f"{where}: a pose must be a 3x4 or 4x4 matrix, got shape {c2w.shape}")
    out = np.eye(4)
    out[:3, :3] = checked_rotation(c2w[:3, :3], where)
    out[:3, 3] = c2w[:3, 3]
    if not np.all(np.isfinite(out)):
        raise UserError(f"{where}: the pose has non-finite entries")
    return out


def opencv_w2c_to_gl_c2w(rot: np.ndarray, t: np.ndarray, where: str) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) from an OpenCV world-to-camera rotation (3, 3) and t (3,)."""
    rot = checked_rotation(rot, where)
    c2w = np.eye(4)
    c2w[:3, :3] = rot.T
    c2w[:3, 3] = -rot.T @ np.asarray(t, dtype=np.float64)
    return c2w @ CV_TO_GL


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) of a camera at `eye` (3,) looking at `target` with `up`."""
    back = eye - target
    back = back / np.linalg.norm(back)
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-8:  # looking straight along `up`: any horizontal right works
        right = np.cross([0.0, 1.0, 0.0] if abs(up[1]) < 0.9 else [1.0, 0.0, 0.0], back)
    right = right / np.linalg.norm(right)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, np.cross(back, right), back, eye
    return c2w


def nearest_point_to_axes(c2ws: np.ndarray, prior: np.ndarray | None = None,
                          weight: float = 1e-6) -> np.ndarray:
    """(3,) the point nearest, in least squares, to every camera's optical axis; c2ws (N, 4, 4).

    Parallel axes (one camera, or a forward-facing capture) leave the point along them open:
    with a `prior` (3,), a weak pull of `weight` towards it decides it (moving a converging
    capture's answer negligibly; the turntable's orbit); without, nearly parallel axes give the
    mean camera centre one unit ahead of the mean viewing direction (the scene readers).
    """
    dirs = -c2ws[:, :3, 2]
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = c2ws[:, :3, 3]
    proj = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]  # (N, 3, 3) off-axis projectors
    lhs, rhs = proj.sum(0), np.einsum("nij,nj->i", proj, origins)
    if prior is not None:
        pull = weight * len(dirs)
        return np.linalg.solve(lhs + pull * np.eye(3), rhs + pull * np.asarray(prior))
    if np.linalg.cond(lhs) > 1e8:
        return origins.mean(0) + dirs.mean(0)
    return np.linalg.solve(lhs, rhs)


def up_vector(c2ws: np.ndarray, method: Literal["mean", "level"] = "mean") -> np.ndarray:
    """(3,) unit "up" of a capture, cameras `c2ws` (N, 4, 4).

    "mean" (normalising a scene): the mean camera up, or the normal of the camera ring when the
    ups cancel out (a gantry whose lower views are upside down, photos at mixed rolls), signed so
    that the cameras stand above the point they look at.
    "level" (the turntable's orbit): the direction most perpendicular to every camera's right
    axis, since photos are taken with the camera level, signed like the mean up; the mean up
    when the right axes do not spread over a plane (cameras at a single azimuth).
    """
    return _level_up(c2ws) if method == "level" else _mean_up(c2ws)


def _mean_up(c2ws: np.ndarray) -> np.ndarray:
    ups = c2ws[:, :3, 1]
    mean = ups.mean(0)
    if np.linalg.norm(mean) > 0.5 or len(c2ws) < 3:
        return mean / max(np.linalg.norm(mean), 1e-12)
    centres = c2ws[:, :3, 3]
    normal = np.linalg.svd(centres - centres.mean(0))[2][-1]
    # signed so that the cameras stand above what they look at, as round an object on a table
    # (photos at mixed rolls, their EXIF lost, have no majority up: 0/90/180/270-degree beer_can
    # frames came out 130 degrees off by the ups' signs)
    return normal if (centres.mean(0) - nearest_point_to_axes(c2ws)) @ normal >= 0 else -normal


def _level_up(c2ws: np.ndarray) -> np.ndarray:
    mean_up = c2ws[:, :3, 1].mean(0)
    if np.linalg.norm(mean_up) < 1e-6:
        mean_up = np.array([0.0, 0.0, 1.0])
    rights = c2ws[:, :3, 0]
    eigvals, eigvecs = np.linalg.eigh(rights.T @ rights / len(rights))  # ascending
    up = eigvecs[:, 0] if eigvals[1] > 0.02 else mean_up
    up = up if up @ mean_up >= 0 else -up
    return up / np.linalg.norm(up)


LEVEL_SPREAD_DEG = 6.0  # photos whose right axes lie within this (RMS) of one level agree on up


def photos_level(c2ws: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit up (3,) most perpendicular to the cameras' right axes, signed like their mean up;
    the RMS angle in degrees between the right axes and the horizontal it defines), for
    camera-to-world matrices (N, 4, 4) with OpenGL axes."""
    rights = c2ws[:, :3, 0]
    eigvals, eigvecs = np.linalg.eigh(rights.T @ rights / len(rights))  # ascending
    up = eigvecs[:, 0]
    if up @ c2ws[:, :3, 1].sum(0) < 0:
        up = -up
    spread = float(np.degrees(np.arcsin(np.sqrt(max(eigvals[0], 0.0)))))
    return up, spread


def agreed_level(c2ws: np.ndarray) -> np.ndarray | None:
    """The photos' up (3,) when their right axes agree on one (spread under LEVEL_SPREAD_DEG)
    and they turn round it (not all at one azimuth, where any up fits), else None."""
    if len(c2ws) < 3:
        return None
    up, spread = photos_level(c2ws)
    rights = c2ws[:, :3, 0]
    turned = np.linalg.eigvalsh(rights.T @ rights / len(rights))[1] > 0.02
    return up if spread <= LEVEL_SPREAD_DEG and turned else None


def box_corners(aabb) -> np.ndarray:
    """The eight corners (8, 3) of the box `aabb` ((3,) min corner, (3,) max corner)."""
    lo, hi = np.asarray(aabb, dtype=np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
