"""The phone's sensors as priors: `capture.json` beside the photos, written by the page's capture
mode (windowshop/service/static/capture.js; format in docs/capture.md).

Each photo may carry
    up           the direction opposite to gravity in the photo's camera frame (OpenCV axes: x
                 right and y down in the upright image, z forward), from the accelerometer
    heading_deg  which way the camera looked, around the vertical (only differences matter)
    order        when it was taken

A phone's accelerometer knows up to a degree or two whatever the photo's roll or pitch, and the
support plane cannot tell a table from a slope or a pedestal's side: so with gravity, up comes
from it (a robust mean over the photos, each carried into the world by its pose), and the plane
only bounds the object when it agrees. The same vectors check the poses: a photo whose gravity,
carried by its pose, points elsewhere than the others' is placed wrong (windowshop.photos.verify
.gravity). Headings and order choose the pairs to match (windowshop.photos.pairs.heading_pairs):
photos taken from opposite sides are never matched, so an object whose sides look alike cannot
be folded through them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from windowshop.errors import UserError

CAPTURE_FILE = "capture.json"
FORMAT = "windowshop-capture"
MAX_BYTES = 2_000_000  # a thousand photos' entries are ~200 kB
MIN_SHARE = 0.5  # gravity (or headings) must come with at least this share of the photos to be used
INLIER_DEG = 10.0  # photos whose world up is further than this from the mean are left out of it
# cos(10 deg): a hand-held phone's gravity is good to ~1-3 deg (steady frames), a pose to ~1 deg


@dataclass
class Priors:
    """What the phone knew about each photo, by photo name (file stem as prepare names it)."""

    sensors: str  # "deviceorientation", "devicemotion" or "none"
    up: dict[str, np.ndarray] = field(default_factory=dict)  # unit (3,), camera frame (OpenCV)
    heading: dict[str, float] = field(default_factory=dict)  # degrees
    order: dict[str, int] = field(default_factory=dict)

    def usable(self, names: list[str], what: dict) -> bool:
        """Whether `what` (self.up or self.heading) covers at least MIN_SHARE of `names`."""
        return bool(names) and sum(n in what for n in names) >= MIN_SHARE * len(names)


def find_capture(files: list[Path]) -> Path | None:
    """The capture.json among the input's files (a folder's, or a zip's unpacked)."""
    return next((f for f in files if f.name.lower() == CAPTURE_FILE), None)


def _fail(path: Path, why: str) -> UserError:
    return UserError(f"{path}: {why}; it should be the capture.json the page's capture mode "
                     f"writes (docs/capture.md): remove it to use the photos alone")


def _vector(value, path: Path, file: str) -> np.ndarray | None:
    if value is None:
        return None
    try:
        up = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise _fail(path, f"the up of {file} is not three numbers") from None
    if up.shape != (3,) or not np.all(np.isfinite(up)) or np.linalg.norm(up) < 0.5:
        raise _fail(path, f"the up of {file} is not a direction (three numbers of length ~1)")
    return up / np.linalg.norm(up)


def _number(value, path: Path, what: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(path, f"{what} is not a number")
    return float(value)


def read_capture(path: Path, names: dict[str, str]) -> Priors:
    """Priors from the capture.json at `path`; `names` maps the photos' file names to the names
    prepare gives them. Entries of photos not used (dropped, or not sent) are ignored; a file that
    is not the page's capture.json is a UserError."""
    if path.stat().st_size > MAX_BYTES:
        raise _fail(path, f"it is larger than {MAX_BYTES // 1_000_000} MB")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise _fail(path, f"not valid JSON ({err})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT \
            or not isinstance(data.get("photos"), list):
        raise _fail(path, f"not a {FORMAT} file (no \"format\": \"{FORMAT}\" and \"photos\" list)")
    priors = Priors(sensors=str(data.get("sensors", "none")))
    for entry in data["photos"]:
        if not isinstance(entry, dict) or not isinstance(entry.get("file"), str):
            raise _fail(path, "a photo entry has no \"file\"")
        name = names.get(entry["file"])
        if name is None:
            continue
        up = _vector(entry.get("up"), path, entry["file"])
        heading = _number(entry.get("heading_deg"), path, f"the heading of {entry['file']}")
        order = _number(entry.get("order"), path, f"the order of {entry['file']}")
        if up is not None:
            priors.up[name] = up
        if heading is not None:
            priors.heading[name] = heading % 360.0
        if order is not None:
            priors.order[name] = int(order)
    return priors


def gl_up(c2w: np.ndarray, up_cv: np.ndarray) -> np.ndarray:
    """A camera-frame direction (OpenCV axes) carried into the world by an OpenGL
    camera-to-world matrix (4, 4) (OpenGL's y and z are OpenCV's negated)."""
    return c2w[:3, :3] @ (up_cv * np.array([1.0, -1.0, -1.0]))


def world_up(c2ws: dict[str, np.ndarray], ups: dict[str, np.ndarray]
             ) -> tuple[np.ndarray, dict[str, float]] | None:
    """(robust mean world up (3,), each photo's angle from it in degrees) of the photos in both
    `c2ws` (OpenGL camera-to-world) and `ups` (camera frame, OpenCV); None without any."""
    names = [n for n in c2ws if n in ups]
    if not names:
        return None
    vectors = np.stack([gl_up(c2ws[n], ups[n]) for n in names])
    vectors /= np.linalg.norm(vectors, axis=1, keepdims=True)
    up = vectors.mean(0)
    for _ in range(3):  # leave out what is far from the mean (a folded photo, a shaken phone)
        up /= np.linalg.norm(up)
        near = vectors @ up >= np.cos(np.radians(INLIER_DEG))
        if not near.any():
            break
        up = vectors[near].mean(0)
    up /= np.linalg.norm(up)
    angles = np.degrees(np.arccos(np.clip(vectors @ up, -1.0, 1.0)))
    return up, {n: float(a) for n, a in zip(names, angles)}


UP_WORDS = {"gravity": "the phone's gravity", "plane": "the surface it stands on",
            "photos": "the photos' level", "cameras": "the cameras' mean up"}


def describe(priors: Priors | None, names: list[str], up_source: str, plane_kept: bool,
             matcher: str) -> dict:
    """report.json's "priors": what the phone gave, and where up and the pairs came from."""
    gravity = 0 if priors is None else sum(n in priors.up for n in names)
    headings = 0 if priors is None else sum(n in priors.heading for n in names)
    words = f"up from {UP_WORDS.get(up_source, up_source)}"
    if up_source == "gravity":
        words += (f" ({gravity} of {len(names)} photos; "
                  + ("the surface it stands on agrees)" if plane_kept else "no level surface "
                     "under the object agrees with it)"))
    elif priors is not None and gravity:
        words += f" (the phone's gravity came with only {gravity} of {len(names)} photos)"
    if matcher == "heading":
        words += "; photos matched by the phone's headings and shooting order"
    return {"capture": priors is not None, "sensors": None if priors is None else priors.sensors,
            "gravity": gravity, "headings": headings, "up": up_source,
            "pairs": matcher, "summary": words}
