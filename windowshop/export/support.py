"""The support plane is not the object: its contact shadow cut away, the base closed flat on it.

Only a capture `windowshop prepare` made (photos of a real object, which stands on something) is
cut; a posed dataset's object (lego) need not stand on anything. A prepared capture that found
the surface the object stands on puts that plane at the floor of
the object's box (normalised frame, +z up; photos/prepare.py); one that did not takes up from the
photos' level, so the surface the object stands on is still horizontal, at its lowest point. A
mask that took the object's contact shadow for object, and a field that learned it, leave a dark
slab on that surface under and around the object. On the density lattice, from the lowest layer
the object occupies (the floor):
- every layer within CUT cells (or CUT_SHARE of the object's height, the larger) of the floor
  is emptied, so the surface closes there in a flat cap;
- within BAND of the height above the floor, columns outside the object's footprint just above
  that band (grown by GROW cells) that stop within the band are emptied: a shadow lies flat, a
  wide base of the object itself stands taller than the band.
- then pieces left apart from the object on the support, low (their top within LOW of the
  object's height above the floor) and small (under SMALL of the largest piece's voxels), are
  debris of the support: a plate's visual hull, the rest of a shadow. (A figure on a white
  plate, rendered: the masks hold the plate, the field fills the hull above its rim with white
  lumps up to a quarter of the figure's height, which the band does not reach: 12 of 15 pieces,
  8% of the voxels, gone. A second object of its own, a shoe beside its pair, is kept.)
After marching cubes (and again after the surface is moved), `flatten_base` puts the cap's
vertices on the floor, so the model stands flat on the plane.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import ndimage

CUT = 1.5  # cells above the floor emptied at least
CUT_SHARE = 0.01  # of the object's height above the floor emptied at least
BAND = 0.1  # of the object's height: how high a shadow's slab may reach
GROW = 2  # cells the footprint grows by
LOW = 0.25  # of the object's height: a separate piece whose top is under this may be debris ...
SMALL = 0.1  # ... when it holds under this share of the largest piece's voxels


def prepared_report(scene_source: str | Path) -> dict | None:
    """The report.json `windowshop prepare` wrote beside the scene at `scene_source` (None for a
    scene it did not prepare: a posed dataset, whose object need not stand on anything)."""
    path = Path(scene_source)
    report = (path if path.is_dir() else path.parent) / "report.json"
    try:
        data = json.loads(report.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def plane_found(report: dict | None) -> bool:
    """Whether prepare's `report` (prepared_report) says it found a support plane."""
    plane = (report or {}).get("plane")
    return bool(plane.get("found")) if isinstance(plane, dict) else False


def cut_support(volume: np.ndarray, level: float, aabb: np.ndarray
                ) -> tuple[np.ndarray, float, float]:
    """(densities without the slab and the layers next to the floor, the cut's height: the
    highest z emptied, the floor's z) for `volume` (X, Y, Z) over `aabb` (2, 3), +z up."""
    shape = np.asarray(volume.shape)
    cell = (aabb[1, 2] - aabb[0, 2]) / (shape[2] - 1)
    layers = np.flatnonzero((volume > level).any((0, 1)))
    if layers.size == 0:
        return volume, float(aabb[0, 2]), float(aabb[0, 2])
    floor = int(layers[0])
    occupied = volume[:, :, floor:] > level
    height = int(layers[-1]) - floor  # in cells above the floor
    out = volume[:, :, floor:].copy()
    band = max(2, int(round(BAND * height)))
    above = occupied[:, :, band:2 * band].any(2)
    footprint = ndimage.binary_dilation(above, iterations=GROW) if above.any() else above
    slab = ~footprint & occupied[:, :, :band].any(2) & ~occupied[:, :, band]
    out[slab, :band] = 0.0
    cut = int(np.ceil(max(CUT, CUT_SHARE * height)))
    out[:, :, :cut + 1] = 0.0
    drop_debris(out, level, height)
    whole = volume.copy()
    whole[:, :, floor:] = out
    return whole, float(aabb[0, 2] + (floor + cut) * cell), float(aabb[0, 2] + floor * cell)


def drop_debris(volume: np.ndarray, level: float, height: int) -> None:
    """Empty, in `volume` (X, Y, Z) whose lowest layer is the floor, the separate pieces (above
    `level`) that stay under LOW of the object's `height` (cells) and hold under SMALL of the
    largest piece's voxels (the module docstring)."""
    labels, count = ndimage.label(volume > level)
    if count < 2:
        return
    voxels = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    # each piece's top from its bounding slices (a tenth of the time of ndimage.maximum over
    # the lattice: 0.03 s against 0.3 s on fruit's)
    boxes = ndimage.find_objects(labels)
    tops = np.array([box[2].stop - 1 for box in boxes])
    for piece in np.flatnonzero((voxels < SMALL * voxels.max()) & (tops < LOW * height)):
        box = boxes[piece]
        volume[box][labels[box] == piece + 1] = 0.0


def flatten_base(vertices: np.ndarray, cut_z: float, floor_z: float, cell: float) -> np.ndarray:
    """(V, 3) `vertices` with the base cap's (under `cut_z` plus a cell) put on `floor_z`, and
    none below it."""
    out = vertices.copy()
    base = out[:, 2] < cut_z + cell
    out[base, 2] = floor_z
    out[:, 2] = np.maximum(out[:, 2], floor_z)
    return out
