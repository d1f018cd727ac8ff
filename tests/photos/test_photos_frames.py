"""Sampling sharp, well-spread frames from a video."""

from __future__ import annotations

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image, ImageFilter

from windowshop.errors import UserError
from windowshop.photos.frames import sample_frames

FRAMES, SPANS, SIZE = 48, 6, (96, 64)  # frames in the clip, frames asked for, (width, height)


def _frame(index: int, blurred: bool) -> np.ndarray:
    """(H, W, 3) uint8: a checkerboard shifted by `index` pixels, optionally blurred."""
    width, height = SIZE
    y, x = np.mgrid[0:height, 0:width]
    board = (((x + index) // 8 + y // 8) % 2 * 200 + 30).astype(np.uint8)
    image = Image.fromarray(np.stack([board] * 3, -1))
    return np.asarray(image.filter(ImageFilter.GaussianBlur(3)) if blurred else image)


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A 48-frame MP4 in which only frames 8k + 5 are sharp; the others are motion-blurred."""
    path = tmp_path_factory.mktemp("video") / "walk.mp4"
    writer = imageio_ffmpeg.write_frames(str(path), SIZE, fps=24, quality=10, macro_block_size=16)
    writer.send(None)
    for i in range(FRAMES):
        writer.send(np.ascontiguousarray(_frame(i, blurred=i % 8 != 5)))
    writer.close()
    return path


def test_a_video_named_with_spaces_gives_frames_working_names_without(clip, tmp_path):
    """COLMAP splits its list of pairs on whitespace; the user still sees the video's own name."""
    named = tmp_path / "my walk.mp4"
    named.write_bytes(clip.read_bytes())
    photos = sample_frames(named, SPANS, max_side=None)
    assert [p.name for p in photos] == [f"my_walk_{8 * k + 5:05d}" for k in range(SPANS)]
    assert [p.shown for p in photos] == [f"my walk_{8 * k + 5:05d}" for k in range(SPANS)]


def test_one_sharp_frame_per_span(clip):
    steps = []
    photos = sample_frames(clip, SPANS, max_side=None, advance=steps.append)
    assert [p.name for p in photos] == [f"walk_{8 * k + 5:05d}" for k in range(SPANS)]
    assert all(p.pixels.shape == (SIZE[1], SIZE[0], 3) for p in photos)
    assert all(p.source == clip for p in photos)
    assert sum(steps) == SPANS


def test_frames_are_shrunk(clip):
    photos = sample_frames(clip, 3, max_side=48)
    assert photos[0].pixels.shape == (32, 48, 3)
    assert photos[0].scale == pytest.approx(0.5)


def test_unreadable_video(tmp_path):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video at all")
    with pytest.raises(UserError, match=r"broken\.mp4: not a video we can read"):
        sample_frames(bad, 4, None)
