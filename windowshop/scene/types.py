"""The one Scene type every reader returns, and its cameras.

Conventions (as NeRF, nerfstudio and instant-ngp):
- `c2w` is a (4, 4) camera-to-world matrix with OpenGL camera axes: x right, y up, z backward
  (the camera looks along -z).
- Pixel coordinates are continuous with the top-left pixel's centre at (0.5, 0.5), as COLMAP;
  the ray through pixel (i, j) passes through (i + 0.5, j + 0.5).
- Images are float32 RGB in [0, 1], shape (H, W, 3); `alpha` (H, W) is the source's alpha or
  foreground mask when it has one.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

SPLITS = ("train", "val", "test")
# A scene's background colour (RGB in [0, 1]) by name. "alpha" names none: its images keep their
# straight (not premultiplied) colour beside their alpha, and the model learns them over random colours.
BACKGROUNDS = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0)}
BACKGROUND_CHOICES = (*BACKGROUNDS, "alpha")


def composite_colour(background: str) -> tuple[float, float, float]:
    """(3,) the colour a scene of `background` has its images composited over (black for alpha)."""
    return BACKGROUNDS["black" if background == "alpha" else background]


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: intrinsics in pixels of its own image, pose as OpenGL camera-to-world."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    c2w: np.ndarray  # (4, 4) float64

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return self.c2w[:3, 3]

    def resized(self, width: int, height: int) -> "Camera":
        """The same camera for an image resampled to `width` x `height`."""
        sx, sy = width / self.width, height / self.height
        return replace(self, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy,
                       width=width, height=height)

    def transformed(self, transform: np.ndarray) -> "Camera":
        """This camera after a similarity `transform` (4, 4) of the world (rotation kept orthonormal)."""
        scale = np.cbrt(np.linalg.det(transform[:3, :3]))
        c2w = transform @ self.c2w
        c2w[:3, :3] /= scale
        return replace(self, c2w=c2w)


@dataclass
class View:
    """One posed image."""

    camera: Camera
    image: np.ndarray  # (H, W, 3) float32 in [0, 1]
    split: str  # "train" | "val" | "test"
    name: str  # path of the image on disk (or a synthetic name)
    alpha: np.ndarray | None = None  # (H, W) float32 in [0, 1]
    # The camera exactly as the source file gives it: the source's own world frame, OpenGL axes,
    # pixels of the image as stored on disk (before undistortion or resizing); None if made here.
    stored_camera: Camera | None = None
    distortion: dict[str, float] | None = None  # the source's lens distortion (undistorted on load)


@dataclass
class Scene:
    """Posed views of one object, in a normalised world frame.

    `transform` (4, 4) is the similarity that took the source's own world frame to this one
    (x_norm = transform @ x_source): object centred at the origin, average camera up along +z,
    object box scaled into [-1, 1]^3. `aabb` (2, 3) bounds the object in the normalised frame;
    `near`/`far` bound every ray's useful interval in it.
    """

    views: list[View]
    format: str
    source: Path
    aabb: np.ndarray  # (2, 3): min corner, max corner
    near: float
    far: float
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    # "white" | "black" | "alpha". Every view's `image` is its colour composited over this
    # background (over black for "alpha"), so with `alpha` it can be put over any colour c as
    # image + (1 - alpha) * (c - background colour). Sources without alpha keep their own pixels.
    background: str = "white"
    # How the source was loaded (windowshop.config.SceneOptions), so a run that records it reloads
    # the scene exactly as it was trained on.
    options: Any = None
    notes: tuple[str, ...] = ()  # the reader's: which files it used or left out, in words

    def split(self, name: str) -> list[View]:
        """The views of one split, in order."""
        return [v for v in self.views if v.split == name]

    @property
    def scale(self) -> float:
        """How many normalised units one source unit is."""
        return float(np.cbrt(np.linalg.det(self.transform[:3, :3])))

    def source_camera(self, camera: Camera) -> Camera:
        """Map a camera of this scene back to the source's world frame."""
        return camera.transformed(np.linalg.inv(self.transform))
