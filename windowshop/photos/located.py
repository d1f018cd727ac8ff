"""The object found in a reconstruction (windowshop.photos.prepare.locate), in a module of its
own so that the verifier (windowshop.photos.verify) reads it without importing prepare."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from windowshop.photos.output import PosedPhoto
from windowshop.photos.plane import Plane


@dataclass
class Located:
    """The object found in a reconstruction, and the normalised cameras."""

    photos: list[PosedPhoto]  # normalised frame
    transform: np.ndarray  # (4, 4) COLMAP frame -> normalised frame
    aabb: np.ndarray  # (2, 3) normalised
    points: np.ndarray  # (Q, 3) the object's sparse points, normalised
    masks: dict[str, np.ndarray]  # photo name -> (H, W) bool; empty when none are made
    mask_kind: str  # "given" (the photos' cut-outs), "segmented" (GrabCut), "still" (GrabCut
    # with a still backdrop, windowshop.photos.still), "colour"
    # (plain background), "rembg" or "none"
    background: str
    plane: Plane | None  # the support plane, COLMAP frame
    # the masks before they were cut to each other's visual hull (the verifier compares them)
    raw_masks: dict[str, np.ndarray] = field(default_factory=dict)
    up_source: str = "plane"  # "plane" (its normal), "gravity" (the phone's), "photos" (their
    # level) or "cameras"
