"""Lens distortion (OpenCV radial-tangential, and OpenCV's equidistant fisheye, as COLMAP and
nerfstudio write them) and undistortion.

Images are undistorted on load: every output pixel of an ideal pinhole camera is mapped through
the forward distortion model into the stored image and sampled bilinearly, so no model inverse
is needed. The pinhole camera is zoomed just enough that every output pixel lands inside the
stored image (no invented border pixels).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from windowshop.scene.types import Camera


@dataclass(frozen=True)
class Distortion:
    """radial = 1 + k1 r^2 + k2 r^4 + k3 r^6 + k4 r^8, plus tangential p1, p2 (OpenCV order).

    `fisheye` (OpenCV's fisheye model, COLMAP's OPENCV_FISHEYE / RADIAL_FISHEYE): the ray at angle
    theta = atan(r) off the axis lands at radius theta (1 + k1 theta^2 + ... + k4 theta^8); p1, p2
    are unused. A fisheye is never the identity, even with every k zero (equidistant, not pinhole).
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    fisheye: bool = False

    @property
    def is_identity(self) -> bool:
        return not any(asdict(self).values())

    def as_dict(self) -> dict[str, float]:
        """The non-zero terms (and `fisheye: 1.0` for a fisheye) as floats."""
        return {k: float(v) for k, v in asdict(self).items() if v}


def _distort_fisheye(xy: np.ndarray, d: Distortion) -> np.ndarray:
    r = np.linalg.norm(xy, axis=-1)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1.0 + t2 * (d.k1 + t2 * (d.k2 + t2 * (d.k3 + t2 * d.k4))))
    scale = np.where(r > 1e-12, theta_d / np.maximum(r, 1e-12), 1.0)  # theta_d / r -> 1 at the axis
    return xy * scale[:, None]


def distort(xy: np.ndarray, d: Distortion) -> np.ndarray:
    """Distorted normalised coordinates (N, 2) of ideal ones `xy` (N, 2), OpenCV axes (y down)."""
    if d.fisheye:
        return _distort_fisheye(xy, d)
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * (d.k3 + r2 * d.k4)))
    xd = x * radial + 2.0 * d.p1 * x * y + d.p2 * (r2 + 2.0 * x * x)
    yd = y * radial + d.p1 * (r2 + 2.0 * y * y) + 2.0 * d.p2 * x * y
    return np.stack([xd, yd], axis=-1)


def distort_pixels(uv: np.ndarray, pinhole: Camera, stored: Camera, d: Distortion) -> np.ndarray:
    """Where pixels `uv` (N, 2) of the undistorted `pinhole` camera lie in the `stored` image."""
    xy = np.stack([(uv[:, 0] - pinhole.cx) / pinhole.fx, (uv[:, 1] - pinhole.cy) / pinhole.fy], -1)
    xd = distort(xy, d)
    return np.stack([stored.fx * xd[:, 0] + stored.cx, stored.fy * xd[:, 1] + stored.cy], -1)


def _border_pixels(width: int, height: int) -> np.ndarray:
    """(M, 2) continuous coordinates of the outer edge of a width x height image."""
    u = np.linspace(0.0, width, 64)
    v = np.linspace(0.0, height, 64)
    return np.concatenate([np.stack([u, np.zeros_like(u)], -1), np.stack([u, np.full_like(u, height)], -1),
                           np.stack([np.zeros_like(v), v], -1), np.stack([np.full_like(v, width), v], -1)])


def undistorted_camera(stored: Camera, d: Distortion) -> Camera:
    """The pinhole camera (same size and centre) whose every pixel samples inside `stored`.

    Its focal lengths are the stored ones times the smallest zoom (found by bisection) for which
    the image border maps inside the stored image. A fisheye may need a much wider pinhole (its
    edge rays may be far off the axis), so its search starts lower.
    """
    border = _border_pixels(stored.width, stored.height)

    def inside(zoom: float) -> bool:
        cam = replace(stored, fx=stored.fx * zoom, fy=stored.fy * zoom)
        src = distort_pixels(border, cam, stored, d)
        eps = 1e-6
        return bool(np.all((src[:, 0] >= -eps) & (src[:, 0] <= stored.width + eps)
                           & (src[:, 1] >= -eps) & (src[:, 1] <= stored.height + eps)))

    lo, hi = (0.05 if d.fisheye else 0.5), 2.0
    if inside(lo):
        return replace(stored, fx=stored.fx * lo, fy=stored.fy * lo)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if inside(mid) else (mid, hi)
    return replace(stored, fx=stored.fx * hi, fy=stored.fy * hi)


def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Sample `image` (H, W, C) at continuous pixel coordinates `uv` (..., 2), edges clamped.

    The plain numpy reference of `remap` (tests hold the fast path to it).
    """
    h, w = image.shape[:2]
    x = np.clip(uv[..., 0] - 0.5, 0.0, w - 1.0)
    y = np.clip(uv[..., 1] - 0.5, 0.0, h - 1.0)
    x0 = np.clip(np.floor(x).astype(np.int64), 0, max(w - 2, 0))
    y0 = np.clip(np.floor(y).astype(np.int64), 0, max(h - 2, 0))
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(image.dtype)


def remap(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """`bilinear`, through torch's grid_sample (multi-threaded C++): (H, W, C) at uv (h, w, 2)."""
    import torch
    import torch.nn.functional as F

    h, w = image.shape[:2]
    grid = torch.from_numpy(np.stack([2.0 * uv[..., 0] / w - 1.0, 2.0 * uv[..., 1] / h - 1.0], -1)
                            .astype(np.float32))[None]
    src = torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32)).permute(2, 0, 1)[None]
    out = F.grid_sample(src, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return out[0].permute(1, 2, 0).numpy()


def undistort_image(image: np.ndarray, stored: Camera, pinhole: Camera, d: Distortion) -> np.ndarray:
    """`image` (H, W, C) of the distorted `stored` camera resampled as seen by `pinhole`."""
    j, i = np.meshgrid(np.arange(pinhole.height) + 0.5, np.arange(pinhole.width) + 0.5, indexing="ij")
    src = distort_pixels(np.stack([i.ravel(), j.ravel()], -1), pinhole, stored, d)
    return remap(image, src.reshape(pinhole.height, pinhole.width, 2))
