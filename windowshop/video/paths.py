"""Camera paths for the turntable: an orbit fitted to the training cameras, a spiral, or a file.

Every path yields `windowshop.scene.types.Camera`s (OpenGL camera-to-world) in the run's normalised
frame. The orbit is fitted from the cameras alone, not from the normalisation, so it keeps the
object centred and upright for any capture:
- centre: the point nearest to every camera's optical axis (least squares),
- up: the direction most perpendicular to every camera's x (right) axis, since photos are taken
  with the camera level; the average camera up when the right axes do not span a plane,
- radius, elevation and field of view: the medians of the training views.

Camera-path files use nerfstudio's layout: top-level `render_width`, `render_height` (and `fps`,
`seconds`), and `camera_path`, a list of `{"camera_to_world": 16 floats row-major, "fov": vertical
degrees, "aspect": width / height}`; poses are in the run's normalised frame.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from windowshop.config import VideoOptions
from windowshop.errors import UserError
from windowshop.scene.cameras import look_at, nearest_point_to_axes, up_vector
from windowshop.scene.types import Camera

MAX_ELEVATION = 85.0  # degrees; looking straight down the up axis leaves "upright" undefined


@dataclass(frozen=True)
class Orbit:
    """A circle around `centre` (3,) about the unit axis `up` (3,).

    Azimuth 0 lies along the unit `reference` (3,) (perpendicular to `up`), elevation is in degrees
    above the plane through the centre, `fov` is the vertical field of view in degrees.
    """

    centre: np.ndarray
    up: np.ndarray
    reference: np.ndarray
    radius: float
    elevation: float
    fov: float

    def position(self, azimuth: float, elevation: float) -> np.ndarray:
        """(3,) point of the sphere of `radius` at `azimuth`, `elevation` (degrees)."""
        az, el = math.radians(azimuth), math.radians(elevation)
        side = np.cross(self.up, self.reference)
        horizontal = math.cos(az) * self.reference + math.sin(az) * side
        return self.centre + self.radius * (math.cos(el) * horizontal + math.sin(el) * self.up)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def vertical_fov(camera: Camera) -> float:
    """Vertical field of view of `camera` in degrees."""
    return math.degrees(2 * math.atan(camera.height / (2 * camera.fy)))


def fit_orbit(cameras: list[Camera]) -> Orbit:
    """The orbit of the training `cameras`: their centre, up axis and median radius/elevation.

    `fov` is the median of each camera's narrower field of view; the turntable gives it to its own
    narrower side, so whatever the photos kept in frame stays in frame.
    """
    if not cameras:
        raise UserError("the run has no training cameras to fit a turntable orbit to")
    c2ws = np.stack([c.c2w for c in cameras]).astype(np.float64)
    centre = nearest_point_to_axes(c2ws, prior=np.zeros(3))
    up = up_vector(c2ws, method="level")
    offsets = c2ws[:, :3, 3] - centre
    dist = np.linalg.norm(offsets, axis=1)
    elev = np.degrees(np.arcsin(np.clip(offsets @ up / np.maximum(dist, 1e-12), -1, 1)))
    fovs = [min(vertical_fov(c), math.degrees(2 * math.atan(c.width / (2 * c.fx)))) for c in cameras]
    return Orbit(centre=centre, up=up, reference=_reference(offsets[0], up), radius=float(np.median(dist)),
                 elevation=float(np.median(elev)), fov=float(np.median(fovs)))


def _reference(offset: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Unit direction (3,) of `offset` (3,) within the plane perpendicular to `up` (any if on the axis)."""
    flat = offset - (offset @ up) * up
    if np.linalg.norm(flat) < 1e-9 * max(1.0, np.linalg.norm(offset)):
        flat = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    return _unit(flat)


def pinhole(c2w: np.ndarray, width: int, height: int, fov: float) -> Camera:
    """A centred pinhole camera of vertical field of view `fov` degrees and square pixels."""
    focal = height / (2 * math.tan(math.radians(fov) / 2))
    return Camera(fx=focal, fy=focal, cx=width / 2, cy=height / 2, width=width, height=height,
                  c2w=np.asarray(c2w, dtype=np.float64))


def orbit_cameras(orbit: Orbit, frames: int, width: int, height: int, start_angle: float = 0.0,
                  elevations: np.ndarray | None = None) -> list[Camera]:
    """`frames` cameras evenly spaced in azimuth over one turn, all looking at the centre.

    The last frame stops one step short of the first, so the video loops without a repeated frame.
    `elevations` (frames,) in degrees replace the orbit's constant elevation (the spiral).
    """
    if elevations is None:
        elevations = np.full(frames, orbit.elevation)
    elevations = np.clip(elevations, -MAX_ELEVATION, MAX_ELEVATION)
    cameras = []
    for k in range(frames):
        eye = orbit.position(start_angle + 360.0 * k / frames, float(elevations[k]))
        cameras.append(pinhole(look_at(eye, orbit.centre, orbit.up), width, height, orbit.fov))
    return cameras


def spiral_elevations(elevation: float, amplitude: float, frames: int) -> np.ndarray:
    """(frames,) elevations swinging once up and down by `amplitude` degrees over one turn."""
    return elevation + amplitude * np.sin(2 * np.pi * np.arange(frames) / frames)


def _vertical_fov_for(fov: float, width: int, height: int) -> float:
    """Vertical field of view (degrees) that gives the narrower side of the image `fov` degrees."""
    if width >= height:
        return fov
    return math.degrees(2 * math.atan(math.tan(math.radians(fov) / 2) * height / width))


def parse_size(text: str) -> tuple[int, int]:
    """"256" (square) or "320x240" (width x height) as (width, height)."""
    parts = str(text).lower().split("x")
    try:
        width, height = (int(parts[0]), int(parts[0])) if len(parts) == 1 else (int(parts[0]), int(parts[1]))
    except ValueError:
        width = height = 0
    if len(parts) > 2 or width < 1 or height < 1:
        raise UserError(f"--size must be N or WxH in pixels (e.g. 256 or 320x240), got {text!r}")
    return width, height


def turntable_path(train_cameras: list[Camera], options: VideoOptions) -> list[Camera]:
    """The cameras of the video `options` describe: orbit, spiral or a camera-path file."""
    if options.frames < 1:
        raise UserError(f"--frames must be at least 1, got {options.frames}")
    if options.path not in ("orbit", "spiral"):
        return read_camera_path(options.path)
    orbit = fit_orbit(train_cameras)
    if options.radius is not None and options.radius <= 0:
        raise UserError(f"--radius must be positive, got {options.radius}")
    if options.fov is not None and not 0 < options.fov < 180:
        raise UserError(f"--fov must be between 0 and 180 degrees, got {options.fov}")
    orbit = Orbit(centre=orbit.centre, up=orbit.up, reference=orbit.reference,
                  radius=options.radius or orbit.radius,
                  elevation=orbit.elevation if options.elevation is None else options.elevation,
                  fov=options.fov or _vertical_fov_for(orbit.fov, options.width, options.height))
    elevations = None
    if options.path == "spiral":
        elevations = spiral_elevations(orbit.elevation, options.spiral_amplitude, options.frames)
    return orbit_cameras(orbit, options.frames, options.width, options.height, options.start_angle,
                         elevations)


def write_camera_path(cameras: list[Camera], path: str | Path, fps: float = 30.0) -> Path:
    """Write `cameras` (one size, centred principal points) as a nerfstudio camera-path JSON."""
    path = Path(path)
    width, height = cameras[0].width, cameras[0].height
    doc = {
        "camera_type": "perspective",
        "render_width": width,
        "render_height": height,
        "fps": fps,
        "seconds": len(cameras) / fps,
        "camera_path": [{"camera_to_world": np.asarray(c.c2w, dtype=float).reshape(-1).tolist(),
                         "fov": vertical_fov(c), "aspect": c.width / c.height} for c in cameras],
    }
    path.write_text(json.dumps(doc, indent=1))
    return path


def read_camera_path(path: str | Path) -> list[Camera]:
    """The cameras of a nerfstudio camera-path JSON file (square pixels, centred principal point)."""
    path = Path(path)
    fix = "give --path orbit, spiral or a nerfstudio camera-path JSON file"
    if not path.is_file():
        raise UserError(f"camera path {path} does not exist; {fix}")
    try:
        doc = json.loads(path.read_text())
        width, height = int(doc["render_width"]), int(doc["render_height"])
        entries = doc["camera_path"]
        poses = [(np.asarray(e["camera_to_world"], dtype=np.float64).reshape(-1), float(e["fov"]))
                 for e in entries]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise UserError(f"{path} is not a camera-path JSON ({type(err).__name__}: {err}); it needs "
                        "render_width, render_height and camera_path: [{camera_to_world, fov}]") from err
    if width < 1 or height < 1 or not poses:
        raise UserError(f"{path}: render_width/render_height must be positive and camera_path "
                        "must list at least one camera")
    cameras = []
    for k, (flat, fov) in enumerate(poses):
        if flat.size not in (12, 16) or not 0 < fov < 180:
            raise UserError(f"{path}: camera {k} needs camera_to_world of 16 (or 12) numbers, row "
                            f"by row, and fov in (0, 180) degrees; got {flat.size} numbers, fov {fov}")
        c2w = np.eye(4)
        c2w[:3] = flat[:12].reshape(3, 4)
        cameras.append(pinhole(c2w, width, height, fov))
    return cameras
