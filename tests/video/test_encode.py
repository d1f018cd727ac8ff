"""Encoding: the MP4 decodes to exactly what was asked; GIF, WebP, depth video, poster, frames."""

from __future__ import annotations

from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from windowshop.errors import UserError
from windowshop.video.encode import (
    Mp4Writer,
    TurntableWriter,
    VideoOutputs,
    depth_colormap,
    probe_video,
    to_uint8,
)


def moving_bar(k: int, width: int, height: int) -> np.ndarray:
    """(H, W, 3) floats: a red bar that moves right with the frame index on a white ground."""
    image = np.ones((height, width, 3), dtype=np.float32)
    x = (4 * k) % (width - 4)
    image[:, x:x + 4, 1:] = 0.0
    return image


def decoded_frames(path: Path) -> tuple[dict, list[np.ndarray]]:
    """Decode every frame with the bundled ffmpeg (independent of our writer)."""
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    width, height = meta["size"]
    frames = [np.frombuffer(b, dtype=np.uint8).reshape(height, width, 3) for b in reader]
    return meta, frames


@pytest.mark.parametrize("size,fps,count", [((64, 48), 30.0, 17), ((32, 96), 12.5, 5)])
def test_mp4_decodes_to_the_requested_frames_size_and_rate(tmp_path, size, fps, count):
    width, height = size
    writer = Mp4Writer(tmp_path / "v.mp4", width, height, fps)
    for k in range(count):
        writer.write(to_uint8(moving_bar(k, width, height)))
    writer.close()
    meta, frames = decoded_frames(tmp_path / "v.mp4")
    assert len(frames) == count and meta["size"] == (width, height) and meta["fps"] == fps
    assert meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    # near-lossless: each decoded frame is its own source (and not its neighbour)
    for k in (0, count - 1):
        err = np.abs(frames[k].astype(float) - 255 * moving_bar(k, width, height)).mean()
        assert err < 4.0
    assert probe_video(tmp_path / "v.mp4")["frames"] == count


def test_mp4_is_faststart(tmp_path):
    writer = Mp4Writer(tmp_path / "v.mp4", 16, 16, 10)
    for k in range(3):
        writer.write(np.full((16, 16, 3), 40 * k, dtype=np.uint8))
    writer.close()
    data = (tmp_path / "v.mp4").read_bytes()
    assert 0 <= data.find(b"moov") < data.find(b"mdat")  # the index comes first: plays while loading


def test_odd_sizes_are_refused_before_writing(tmp_path):
    with pytest.raises(UserError, match="even"):
        Mp4Writer(tmp_path / "v.mp4", 33, 32, 30)
    assert not (tmp_path / "v.mp4").exists()


def test_depth_colormap_orders_near_and_far_and_blends_empty_space():
    depth_surface = np.array([[1.0, 2.0, 3.0, 2.0]])
    opacity = np.array([[1.0, 1.0, 1.0, 0.0]])
    # renderers return weight * distance, so half-transparent pixels carry half the depth
    rgb = depth_colormap(depth_surface * opacity, opacity, near=1.0, far=3.0).astype(float)
    brightness = rgb[0].sum(axis=1)
    assert brightness[0] > brightness[1] > brightness[2]  # near is bright
    assert brightness[3] == 0.0  # empty space shows the (black) background
    half = depth_colormap(np.array([[1.0]]), np.array([[0.5]]), 1.0, 3.0).astype(float)
    full = depth_colormap(np.array([[2.0]]), np.array([[1.0]]), 1.0, 3.0).astype(float)
    np.testing.assert_allclose(half, np.rint(full * 0.5), atol=1)  # same surface, half opacity


def test_turntable_writer_writes_every_output(tmp_path):
    width, height, count, fps = 40, 24, 6, 10.0
    outputs = VideoOutputs(mp4=tmp_path / "spin.mp4", gif=tmp_path / "spin.gif",
                           webp=tmp_path / "spin.webp", depth=tmp_path / "spin_depth.mp4",
                           poster=tmp_path / "poster.png", poster_frame=2,
                           frames_dir=tmp_path / "frames", frames_format="jpg", preview_side=20)
    depth, opacity = np.full((height, width), 2.0), np.ones((height, width))
    with TurntableWriter(outputs, width, height, fps, depth_range=(1.0, 3.0)) as writer:
        for k in range(count):
            writer.add(moving_bar(k, width, height), depth, opacity)
    for video in (outputs.mp4, outputs.depth):
        info = probe_video(video)
        assert (info["frames"], info["width"], info["height"], info["fps"]) == (count, width, height, fps)
    for animation in (outputs.gif, outputs.webp):
        with Image.open(animation) as im:
            assert im.n_frames == count and max(im.size) == 20  # previews are capped
            assert im.info.get("duration") in (None, 100)  # WebP keeps durations per frame
    poster = np.asarray(Image.open(outputs.poster).convert("RGB"))
    np.testing.assert_array_equal(poster, to_uint8(moving_bar(2, width, height)))  # PNG: exact
    frames = sorted((tmp_path / "frames").glob("frame_*.jpg"))
    assert [f.name for f in frames] == [f"frame_{k:04d}.jpg" for k in range(count)]
    assert Image.open(frames[0]).size == (width, height)


def disc(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """A red disc's frame rendered over black (colour premultiplied by alpha) and its alpha (H, W)."""
    rows, cols = np.mgrid[0:height, 0:width] + 0.5
    alpha = (np.hypot(rows - height / 2, cols - width / 2) < height / 3).astype(np.float32)
    return alpha[..., None] * np.array([0.9, 0.2, 0.1], dtype=np.float32), alpha


def test_a_transparent_turntable_keeps_its_alpha_in_the_webm_and_the_pngs(tmp_path):
    width, height, count = 32, 24, 4
    outputs = VideoOutputs(webm=tmp_path / "spin.webm", poster=tmp_path / "poster.jpg",
                           frames_dir=tmp_path / "frames", transparent=True)
    rgb, alpha = disc(width, height)
    with TurntableWriter(outputs, width, height, fps=10.0) as writer:
        for _ in range(count):
            writer.add(rgb, np.zeros((height, width)), alpha)
    # Decoded independently of our reader; ffmpeg's own VP9 decoder would drop the alpha plane.
    reader = imageio_ffmpeg.read_frames(str(outputs.webm), pix_fmt="rgba", bpp=4,
                                        input_params=["-c:v", "libvpx-vp9"])
    meta = next(reader)
    frames = [np.frombuffer(b, dtype=np.uint8).reshape(height, width, 4) for b in reader]
    assert meta["codec"] == "vp9" and meta["pix_fmt"].startswith("yuva420p") and len(frames) == count
    for frame in frames:
        assert frame[12, 16, 3] > 245 and frame[0, 0, 3] < 10 and frame[-1, -1, 3] < 10
        assert frame[12, 16, 0] > 200 and frame[12, 16, 1] < 80  # straight colour: the disc's red
    png = np.asarray(Image.open(tmp_path / "frames" / "frame_0000.png"))
    assert png.shape == (height, width, 4)
    np.testing.assert_array_equal(png[..., 3], to_uint8(alpha[..., None])[..., 0])  # PNG: exact
    assert tuple(png[12, 16, :3]) == (230, 51, 26)
    poster = np.asarray(Image.open(outputs.poster))  # a JPEG has no alpha: over white
    assert poster.shape == (height, width, 3) and poster[0, 0].min() > 245


def test_a_transparent_mp4_is_refused(tmp_path):
    with pytest.raises(UserError, match="webm"):
        TurntableWriter(VideoOutputs(mp4=tmp_path / "v.mp4", transparent=True), 16, 16, 10.0)
    assert not (tmp_path / "v.mp4").exists()
