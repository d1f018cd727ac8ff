"""How well recovered poses agree with reference poses, up to the similarity SfM cannot know.

Structure from motion fixes poses only up to scale, rotation and translation of the whole world,
so the recovered camera centres are first aligned to the reference ones (Umeyama 1991), then
each camera's rotation and centre are compared. Centre errors are given as a share of the
capture radius: the median distance from the reference cameras to the point they look at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from windowshop.scene.cameras import nearest_point_to_axes


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(scale, rotation (3, 3), translation (3,)) minimising |scale R src + t - dst|^2 over
    corresponding points src, dst (N, 3), N >= 3."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    u, sig, vt = np.linalg.svd(xd.T @ xs / len(src))
    d = np.eye(3)
    d[2, 2] = np.sign(np.linalg.det(u @ vt))
    rot = u @ d @ vt
    scale = float(np.trace(np.diag(sig) @ d) / (xs**2).sum(-1).mean())
    return scale, rot, mu_d - scale * rot @ mu_s


def rotation_between(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) R minimising sum |R src_i - dst_i|^2 (Frobenius) over corresponding
    camera rotations src, dst (N, 3, 3): the world turn between two frames read from where the
    cameras look, which a narrow arc's centres, nearly on a line, leave loose."""
    u, _, vt = np.linalg.svd(np.einsum("nij,nkj->ik", dst, src))
    d = np.eye(3)
    d[2, 2] = np.sign(np.linalg.det(u @ vt))
    return u @ d @ vt


@dataclass
class PoseErrors:
    """Per-camera errors after alignment, in the order of the names given."""

    names: list[str]
    rotation_deg: np.ndarray  # (N,)
    centre_share: np.ndarray  # (N,) centre error / capture radius
    radius: float  # capture radius, reference units


def rotation_angle(rot: np.ndarray) -> float:
    """Angle (degrees) of a rotation matrix (3, 3)."""
    return float(np.degrees(np.arccos(np.clip((np.trace(rot) - 1.0) / 2.0, -1.0, 1.0))))


def pose_errors(estimated: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> PoseErrors:
    """Compare camera-to-world matrices (4, 4) (same camera axes in both) of the names present in
    both dicts, after aligning the estimated centres to the reference ones."""
    names = sorted(set(estimated) & set(reference))
    est = np.stack([estimated[n] for n in names])
    ref = np.stack([reference[n] for n in names])
    scale, rot, t = umeyama(est[:, :3, 3], ref[:, :3, 3])
    centres = scale * est[:, :3, 3] @ rot.T + t
    radius = float(np.median(np.linalg.norm(ref[:, :3, 3] - nearest_point_to_axes(ref), axis=-1)))
    rotation = np.array([rotation_angle(r.T @ rot @ e)
                         for r, e in zip(ref[:, :3, :3], est[:, :3, :3])])
    return PoseErrors(names=names, rotation_deg=rotation,
                      centre_share=np.linalg.norm(centres - ref[:, :3, 3], axis=-1) / radius,
                      radius=radius)
