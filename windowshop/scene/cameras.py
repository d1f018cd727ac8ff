"""Pose conventions: every source's camera axes converted to OpenGL camera-to-world, and checks."""

from __future__ import annotations

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.types import Camera

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


def camera_from_fov(width: int, height: int, angle_x: float, c2w: np.ndarray) -> Camera:
    """A centred pinhole camera with horizontal field of view `angle_x` (radians)."""
    focal = 0.5 * width / np.tan(0.5 * angle_x)
    return Camera(fx=focal, fy=focal, cx=width / 2, cy=height / 2, width=width, height=height, c2w=c2w)


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


def nearest_point_to_axes(c2ws: np.ndarray) -> np.ndarray:
    """(3,) least-squares point closest to every camera's optical axis; c2ws (N, 4, 4)."""
    dirs = -c2ws[:, :3, 2]
    origins = c2ws[:, :3, 3]
    proj = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]  # (N, 3, 3) off-axis projectors
    lhs, rhs = proj.sum(0), np.einsum("nij,nj->i", proj, origins)
    if np.linalg.cond(lhs) > 1e8:  # parallel axes (one camera, or all facing one way)
        return origins.mean(0) + dirs.mean(0)
    return np.linalg.solve(lhs, rhs)
