"""Middlebury multi-view `*_par.txt`: per image `name k11..k33 r11..r33 t1 t2 t3`, the projection
K [R | t] world-to-camera in OpenCV axes. A bounding box published in the README is used."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.cameras import opencv_w2c_to_gl_c2w
from windowshop.scene.images import image_size
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import Camera

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_BOX = re.compile(rf"bounding box.*?\(\s*({_NUMBER})\s+({_NUMBER})\s+({_NUMBER})\s*\)\s*"
                  rf"\(\s*({_NUMBER})\s+({_NUMBER})\s+({_NUMBER})\s*\)", re.IGNORECASE | re.DOTALL)


def published_box(folder: Path) -> np.ndarray | None:
    """(2, 3) the box a README in `folder` gives as "bounding box ... (x y z) (x y z)", if any."""
    for readme in sorted(folder.glob("README*")):
        match = _BOX.search(readme.read_text(errors="replace"))
        if match:
            return np.array([float(v) for v in match.groups()]).reshape(2, 3)
    return None


def _frame(line: str, folder: Path, where: str) -> SourceFrame:
    parts = line.split()
    if len(parts) != 22:
        raise UserError(f"{where}: expected 'name' and 21 numbers (K, R, t), got {len(parts)} fields")
    try:
        values = np.array([float(v) for v in parts[1:]])
    except ValueError as err:
        raise UserError(f"{where}: {err}") from err
    k, rot, t = values[:9].reshape(3, 3), values[9:18].reshape(3, 3), values[18:]
    image = folder / parts[0]
    width, height = image_size(image)
    camera = Camera(fx=k[0, 0], fy=k[1, 1], cx=k[0, 2], cy=k[1, 2], width=width, height=height,
                    c2w=opencv_w2c_to_gl_c2w(rot, t, where))
    return SourceFrame(camera=camera, image_path=image)


def read_middlebury(path: Path) -> Source:
    """The frames of a `*_par.txt` (its first line may be the image count)."""
    try:
        lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as err:
        raise UserError(f"{path}: cannot read ({err})") from err
    if lines and len(lines[0].split()) == 1:
        lines = lines[1:]
    if not lines:
        raise UserError(f"{path}: no cameras listed (an empty frame list)")
    frames = [_frame(line, path.parent, f"{path} line for {line.split()[0]}") for line in lines]
    return Source(format="middlebury", path=path, frames=frames, box=published_box(path.parent),
                  background="black")
