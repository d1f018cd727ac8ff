"""Which side of the model the photos saw, as a 3D viewer's orbit: the covered arc of azimuth, a
margin, and the side to open on (the best-photographed one, as the turntable's poster).

Azimuths here are a viewer's: the angle about the model's +Y (up) from +Z towards +X, the camera
at (sin a, ., cos a) from the object's centre. That is model-viewer's theta (`camera-orbit`,
`min-camera-orbit`, `max-camera-orbit`) and viewer.js's yaw. The model frame is the normalised
frame turned +Z up -> +Y up (frame.Z_UP_TO_Y_UP: model (x, y, z) = normalised (x, z, -y)), so a
camera at normalised offset (x, y) from the centre sits at azimuth atan2(x, -y).

When the photos cover FULL_TURN_SPAN degrees or more the orbit is free, as the turntable turns
all round; else it is limited to the arc plus MARGIN degrees either side.
"""

from __future__ import annotations

from html import escape

import numpy as np

from windowshop.scene.types import Camera
from windowshop.video.coverage import FULL_TURN_SPAN, best_covered_frame, covered_arc

MARGIN = 15.0  # degrees a viewer may turn past either end of the covered arc


def viewer_azimuths(cameras: list[Camera], centre: np.ndarray) -> np.ndarray:
    """(N,) degrees in [0, 360): each camera's azimuth about the model's up through `centre` (3,)
    of the normalised frame, in the viewer's convention (see the module docstring)."""
    offsets = np.stack([c.center for c in cameras]) - np.asarray(centre, dtype=np.float64)
    return np.degrees(np.arctan2(offsets[:, 0], -offsets[:, 1])) % 360.0


def covered_orbit(cameras: list[Camera], centre: np.ndarray, margin: float = MARGIN) -> dict:
    """The viewer's orbit for a model photographed by `cameras` (normalised frame) about
    `centre` (3,): JSON-ready degrees: `start` (the side to open on), `covered_degrees`, and, when
    limited, `min` <= start <= `max` (an unwrapped range: max may exceed 360); the model-viewer
    attributes that say the same (`model_viewer`)."""
    azimuths = viewer_azimuths(cameras, centre)
    first, span = covered_arc(azimuths)
    along = first + np.arange(0.0, span + 0.5, 1.0)  # candidate sides, unwrapped, across the arc
    start = float(along[best_covered_frame(along, azimuths)])
    orbit = {"start": round(start, 1), "covered_degrees": round(span, 1),
             "covered_from": round(first % 360.0, 1), "limited": span < FULL_TURN_SPAN}
    attributes = {"camera-orbit": f"{start:.1f}deg 75deg auto"}
    if orbit["limited"]:
        orbit.update({"min": round(first - margin, 1), "max": round(first + span + margin, 1),
                      "margin": margin})
        attributes.update({"min-camera-orbit": f"{orbit['min']:.1f}deg auto auto",
                           "max-camera-orbit": f"{orbit['max']:.1f}deg auto auto"})
    orbit["model_viewer"] = attributes
    orbit["embed"] = embed_snippet(attributes, "model.glb")
    return orbit


def embed_snippet(attributes: dict, src: str, ios_src: str | None = None) -> str:
    """A <model-viewer> element showing the GLB at `src` (and, in AR on iOS, the USDZ at
    `ios_src`) with the orbit's `attributes` (`model_viewer`). The service's page writes the same
    element with the job's addresses (static/app.js; its browser test holds the two equal)."""
    def quoted(values: dict) -> list[str]:
        return [f'{k}="{escape(str(v))}"' for k, v in values.items() if v is not None]

    parts = [*quoted({"src": src, "ios-src": ios_src}), "camera-controls", *quoted(attributes)]
    return f"<model-viewer {' '.join(parts)}></model-viewer>"
