"""The turntable: a trained model rendered along a camera path, frame by frame, into files.

`render_run` is what `windowshop render`, the demo and the web service call; `render_turntable`
does the work for any `RadianceModel` and list of cameras. `render_run` also says which path it
took and how much of the object the photos covered, in its result and in the run's `render.json`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from windowshop.config import VideoOptions
from windowshop.device import ThreadTuner
from windowshop.errors import UserError
from windowshop.memory import MEMORY_BUDGET
from windowshop.model import Bounds, RadianceModel
from windowshop.progress import bar as progress_bar
from windowshop.scene.cameras import box_corners
from windowshop.scene.types import BACKGROUNDS, Camera
from windowshop.video.encode import TurntableWriter, VideoOutputs
from windowshop.video.paths import TurntablePlan, plan_turntable, write_camera_path

NORMALISED_UP = (0.0, 0.0, 1.0)  # a normalised scene's up axis (SceneOptions.normalize)
RENDER_SUMMARY = "render.json"  # in the run folder: the last turntable's path and coverage
# The video's backgrounds: a scene colour, or "transparent", rendered over black (colour
# premultiplied by alpha) and kept with its alpha.
VIDEO_BACKGROUNDS = {**BACKGROUNDS, "transparent": BACKGROUNDS["black"]}


@dataclass(frozen=True)
class TurntableResult:
    """What one turntable render wrote, and how fast."""

    frames: int
    width: int
    height: int
    fps: float
    files: list[Path]
    render_seconds: float  # rendering and encoding, excluding loading the run
    path: dict = dataclasses.field(default_factory=dict)  # render_run's TurntablePlan.summary()
    background: str = "white"

    @property
    def frames_per_second(self) -> float:
        return self.frames / max(self.render_seconds, 1e-9)

    def summary(self) -> dict:
        """JSON-ready: frames, size, files, background, and the path and its coverage."""
        return {"frames": self.frames, "width": self.width, "height": self.height, "fps": self.fps,
                "files": [str(p) for p in self.files], "background": self.background, **self.path}


def depth_range(cameras: list[Camera], bounds: Bounds) -> tuple[float, float]:
    """Fixed (near, far) for the depth video: the box's nearest and farthest points over all cameras."""
    lo, hi = np.asarray(bounds.aabb, dtype=np.float64)
    corners = box_corners(bounds.aabb)
    eyes = np.stack([c.center for c in cameras])  # (F, 3)
    outside = np.maximum(np.maximum(lo - eyes, eyes - hi), 0.0)  # (F, 3): 0 inside the box
    near = float(np.linalg.norm(outside, axis=1).min())
    far = float(np.linalg.norm(eyes[:, None] - corners[None], axis=2).max())
    near, far = max(near, bounds.near), min(far, bounds.far)
    return (near, far) if far > near else (bounds.near, bounds.far)


def render_turntable(model: RadianceModel, cameras: list[Camera], outputs: VideoOutputs, fps: float,
                     background: tuple[float, float, float] = (1.0, 1.0, 1.0),
                     memory_budget: int = MEMORY_BUDGET,
                     progress: bool = True,
                     on_frame: Callable[[int, int], None] | None = None) -> TurntableResult:
    """Render `cameras` (one size) with `model` on its device and write every requested output.

    Each frame is rendered in chunks of rays within `memory_budget` bytes and handed to the
    writers at once, so memory stays bounded at any resolution and length. `on_frame(done,
    total)` reports progress (the web service's jobs); `progress` shows a bar on stderr (plain
    lines when it is not a terminal).
    """
    from windowshop.render.frames import model_device, render_camera

    if not cameras:
        raise UserError("the camera path is empty: nothing to render")
    width, height = cameras[0].width, cameras[0].height
    if any((c.width, c.height) != (width, height) for c in cameras):
        raise ValueError("every camera of a video must have the same image size")
    outputs = dataclasses.replace(outputs, poster_frame=min(outputs.poster_frame or 0, len(cameras) - 1))
    start = time.perf_counter()
    tuner = ThreadTuner(model_device(model), trial_steps=2)  # ffmpeg takes a core too
    with TurntableWriter(outputs, width, height, fps, depth_range(cameras, model.bounds)) as writer, \
            contextlib.closing(tuner):
        for k, camera in enumerate(progress_bar(cameras, desc="render", unit="frame", show=progress)):
            tuner.before_step()
            began = time.perf_counter()
            frame = render_camera(model, camera, background=background, memory_budget=memory_budget)
            writer.add(frame.rgb, frame.depth, frame.opacity)
            tuner.after_step(time.perf_counter() - began)
            if on_frame is not None:
                on_frame(k + 1, len(cameras))
    if outputs.frames_dir is not None:
        write_camera_path(cameras, Path(outputs.frames_dir) / "camera_path.json", fps)
    return TurntableResult(frames=len(cameras), width=width, height=height, fps=fps,
                           files=outputs.files(), render_seconds=time.perf_counter() - start)


def render_run(run_dir: str | Path, options: VideoOptions, outputs: VideoOutputs,
               device: torch.device | str = "cpu", progress: bool = True,
               on_frame: Callable[[int, int], None] | None = None) -> TurntableResult:
    """The turntable of a run folder: its model along the path `options` describe, into `outputs`.

    The poster is the best-covered frame unless `outputs.poster_frame` names one. The result's
    `path` (also written to the run's `render.json`) says whether the path swung across the
    photographed arc instead of turning fully, and how many degrees the photos cover.
    """
    from windowshop.fit.checkpoint import load_run

    if options.background not in VIDEO_BACKGROUNDS:
        raise UserError(f"--background must be one of {', '.join(VIDEO_BACKGROUNDS)}, got {options.background!r}")
    run = load_run(run_dir, device)
    plan = run_plan(run, options)
    poster = plan.poster_frame if outputs.poster_frame is None else outputs.poster_frame
    outputs = dataclasses.replace(outputs, poster_frame=poster,
                                  transparent=options.background == "transparent")
    result = render_turntable(run.model, plan.cameras, outputs, options.fps,
                              background=VIDEO_BACKGROUNDS[options.background],
                              memory_budget=options.memory_budget,
                              progress=progress, on_frame=on_frame)
    result = dataclasses.replace(result, path={**plan.summary(), "poster_frame": poster},
                                 background=options.background)
    (Path(run_dir) / RENDER_SUMMARY).write_text(json.dumps(result.summary(), indent=2) + "\n")
    return result


def run_plan(run, options: VideoOptions) -> TurntablePlan:
    """The turntable cameras of a loaded run (`load_run`) for `options`, as `render_run` films."""
    up = np.array(NORMALISED_UP) if run.scene_options.normalize else None  # else fit to the cameras
    return plan_turntable(run.train_cameras, options, run.bounds, up)


VIDEO_SUFFIXES = (".mp4", ".webm")


def check_video_name(out: Path) -> None:
    """Refuse, before any work, a video file whose name gives no format the encoder writes."""
    if out.suffix.lower() not in VIDEO_SUFFIXES:
        raise UserError(f"{out}: name the video .mp4 (H.264, plays everywhere) or .webm (VP9, "
                        f"keeps transparency), e.g. --out spin.mp4")


def default_outputs(out: str | Path, gif: bool | str = False, webp: bool | str = False,
                    depth: bool | str = False, poster: bool | str = False,
                    frames_dir: str | Path | None = None, frames_format: str = "png",
                    transparent: bool = False) -> VideoOutputs:
    """Outputs beside the video `out` (an H.264 .mp4, or a VP9 .webm, which keeps `transparent`
    frames' alpha): True names a file after it (spin.gif, spin_depth.mp4, spin_poster.jpg, or
    spin_poster.png when transparent), a string is used as the file's path."""
    out = Path(out)
    check_video_name(out)

    def pick(flag: bool | str, name: str) -> Path | None:
        return None if not flag else Path(flag) if isinstance(flag, str) else out.with_name(name)

    webm = out.suffix.lower() == ".webm"
    return VideoOutputs(mp4=None if webm else out, webm=out if webm else None,
                        gif=pick(gif, f"{out.stem}.gif"), webp=pick(webp, f"{out.stem}.webp"),
                        depth=pick(depth, f"{out.stem}_depth.mp4"),
                        poster=pick(poster, f"{out.stem}_poster.{'png' if transparent else 'jpg'}"),
                        frames_dir=Path(frames_dir) if frames_dir else None, frames_format=frames_format,
                        transparent=transparent)


def render_command(run_dir: str | Path, options: VideoOptions, outputs: VideoOutputs,
                   device: torch.device | str) -> TurntableResult:
    """`windowshop render`: render the run's turntable and say what was written."""
    result = render_run(run_dir, options, outputs, device)
    print(f"{result.frames} frames {result.width}x{result.height} at {result.fps:g} fps, rendered at "
          f"{result.frames_per_second:.2f} frames/s on {device}")
    if result.path.get("swing"):
        print(f"the photos cover {result.path['covered_span_degrees']:.0f} degrees of the circle: the "
              "turntable swings across them and back (--full-turn to go all the way round)")
    for path in [*result.files, *([outputs.frames_dir] if outputs.frames_dir else [])]:
        print(f"wrote {path}")
    return result
