"""Sharp, well-spread frames from a video walking around the object.

The video is cut into equal spans of time and the sharpest frame (variance of the Laplacian) of
each span is kept, so the frames cover the whole walk and motion blur is avoided.
"""

from __future__ import annotations

import logging
from pathlib import Path

import imageio_ffmpeg
import numpy as np

from windowshop.errors import UserError
from windowshop.photos.ingest import Photo, sharpness, working_name


def _open(path: Path, max_side: int | None):
    """(meta, frame generator) of imageio-ffmpeg, frames shrunk by ffmpeg so that the longer
    side is at most `max_side` (decoding and shrinking in C: 4x faster than shrinking each frame
    in Python); UserError when ffmpeg cannot read the file."""
    shrink = None if max_side is None else [
        "-vf", f"scale=w=min(iw\\,{max_side}):h=min(ih\\,{max_side})"
               f":force_original_aspect_ratio=decrease:flags=lanczos"]  # never enlarged
    quiet = logging.getLogger("imageio_ffmpeg")  # it warns that the size differs: we asked
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        frames = imageio_ffmpeg.read_frames(str(path), output_params=shrink)
        meta = next(frames)
    except (OSError, RuntimeError, StopIteration) as err:
        raise UserError(f"{path}: not a video we can read ({err}); "
                        f"export it as MP4 (H.264)") from err
    finally:
        quiet.setLevel(level)
    return meta, frames


def sample_frames(path: str | Path, count: int, max_side: int | None,
                  advance=lambda n=1: None) -> list[Photo]:
    """The sharpest frame of each of `count` equal spans of the video at `path`, in time order.

    `advance(n)` is called as frames are decoded, with n in fractions of `count` (for a bar of
    `count` steps). Frames are named `<video stem>_<frame index>` (5 digits).
    """
    path = Path(path)
    meta, frames = _open(path, max_side)
    width, height = meta["size"]
    scale = max(width, height) / max(meta["source_size"])  # a rotation swaps the sides
    expected = round(float(meta.get("duration") or 0) * float(meta.get("fps") or 0))
    if expected < count:  # no usable duration in the header: count the frames (a fast decode)
        expected = imageio_ffmpeg.count_frames_and_secs(str(path))[0]
    expected = max(expected, 1)
    best: dict[int, tuple[float, int, np.ndarray, float]] = {}  # span -> (sharpness, index, ...)
    reported = 0
    for index, raw in enumerate(frames):
        frame = np.frombuffer(raw, dtype=np.uint8).reshape(height, width, 3)
        span = min(index * count // expected, count - 1)
        score = sharpness(frame)
        if span not in best or score > best[span][0]:
            best[span] = (score, index, frame, scale)
        if span > reported:
            advance(span - reported)
            reported = span
    advance(count - reported)
    if not best:
        raise UserError(f"{path}: the video has no frames")
    return [Photo(name=f"{working_name(path.stem)}_{index:05d}", source=path, pixels=pixels,
                  scale=scale, camera_key=("video", pixels.shape), sharpness=score,
                  shown=f"{path.stem}_{index:05d}")
            for score, index, pixels, scale in (best[s] for s in sorted(best))]
