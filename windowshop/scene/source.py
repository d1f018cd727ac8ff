"""What a reader returns: the source's cameras and image files, before any pixel is decoded.

Readers only parse their format; `windowshop.scene.loading.build_scene` then picks the views,
decodes, undistorts and resizes the images and normalises the frame, the same way for every format.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from windowshop.scene.distortion import Distortion
from windowshop.scene.types import Camera


@dataclass
class SourceFrame:
    """One view as the source describes it."""

    camera: Camera  # source world frame, OpenGL axes, pixels of the stored image
    image_path: Path
    split: str | None = None  # the source's own split, if it has one
    distortion: Distortion | None = None
    mask_path: Path | None = None  # a foreground mask image (white = object)
    pixels: np.ndarray | None = None  # (H, W, 3|4) float32, when the source holds the pixels itself
    prescaled: dict[int, Path] = field(default_factory=dict)  # factor -> a smaller copy on disk


@dataclass
class Source:
    """Everything a reader found, in the source's own world frame."""

    format: str
    path: Path
    frames: list[SourceFrame]
    points: np.ndarray | None = None  # (N, 3) sparse points on the object (and around it)
    box: np.ndarray | None = None  # (2, 3) a published object box, min and max corners
    background: str | None = None  # the background of images without alpha ("black"), if known
    up: np.ndarray | None = None  # (3,) the world's published up direction, if the format fixes one
    normalized: bool = False  # the frame is already a windowshop normalised frame (our writer's)
    # what the reader used, or left out, besides its main file, in words (`inspect` shows them)
    notes: list[str] = field(default_factory=list)
