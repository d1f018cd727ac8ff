"""The model file's frame: +Y up (glTF, USD with upAxis Y), the object standing on its support
plane at the origin, in metres when a real height is given, else in the scene source's units.

The scene's normalised frame has up = +z (a prepared capture's support-plane normal, or the
cameras' up), so the support plane is the lowest level of the carved object along z. The matrix
that takes the model's coordinates back to the scene's source frame (what `windowshop inspect
--json` reports cameras in) goes into a side file, so the model can be laid over the photos.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# normalised (x, y, z) with z up -> model (x, z, -y) with y up: a rotation about x
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class ModelFrame:
    """How model coordinates relate to the scene's frames."""

    to_model: np.ndarray  # (4, 4) normalised frame -> model (a similarity)
    to_source: np.ndarray  # (4, 4) model -> the scene's source frame
    height: float  # the object's height in model units
    units: str  # "metres" (a real height was given) or "source units"


def model_frame(vertices: np.ndarray, source_transform: np.ndarray,
                size_cm: float | None) -> ModelFrame:
    """The frame of a mesh with `vertices` (V, 3) in the normalised frame of a scene whose
    `source_transform` (4, 4) maps its source frame to the normalised one; `size_cm` scales the
    object to that real height (None: the source's own units)."""
    lo, hi = vertices.min(0), vertices.max(0)
    base = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])  # footprint centre, bottom
    height_normalised = float(hi[2] - lo[2])
    if size_cm is not None:
        scale, units = size_cm / 100.0 / max(height_normalised, 1e-12), "metres"
    else:
        scale, units = 1.0 / float(np.cbrt(np.linalg.det(source_transform[:3, :3]))), "source units"
    to_model = np.eye(4)
    to_model[:3, :3] = scale * Z_UP_TO_Y_UP
    to_model[:3, 3] = -scale * Z_UP_TO_Y_UP @ base
    to_source = np.linalg.inv(source_transform) @ np.linalg.inv(to_model)
    return ModelFrame(to_model=to_model, to_source=to_source, height=scale * height_normalised,
                      units=units)


def apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """`points` (N, 3) through the affine `matrix` (4, 4)."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def write_side_file(path: Path, frame: ModelFrame, extra: dict) -> None:
    """`path` (FILE.json): the model -> source matrix (row-major, column vectors: x_source =
    M @ [x_model, 1]) and what else is worth knowing about the export."""
    record = {"model_to_source": frame.to_source.tolist(),
              "normalised_to_model": frame.to_model.tolist(),
              "up": "+y", "units": frame.units, "height": frame.height, **extra}
    path.write_text(json.dumps(record, indent=2) + "\n")
