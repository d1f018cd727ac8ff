"""Frames to files: H.264 MP4 or VP9 WebM (with alpha), animated GIF/WebP, a colour-mapped depth
video, a poster, images.

Frames arrive one at a time (`TurntableWriter.add`), so memory holds one full-size frame however
long or large the video: the videos stream into ffmpeg (imageio-ffmpeg's bundled binary, no shell),
images go straight to disk, and only the GIF/WebP previews, capped at `max_side` pixels, are kept
until the end (Pillow writes animations in one call). A transparent turntable keeps its alpha in
the WebM (yuva420p) and the PNGs; formats without alpha (MP4, JPEG, GIF, WebP previews) show it
over white.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import imageio_ffmpeg
import numpy as np
from PIL import Image

from windowshop.errors import UserError

DEPTH_COLORMAP = "inferno"  # perceptually uniform; near surfaces bright, far ones dark


def to_uint8(image: np.ndarray) -> np.ndarray:
    """(H, W, C) floats in [0, 1] to uint8, rounded."""
    return np.clip(np.rint(np.asarray(image, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def check_video_size(width: int, height: int) -> None:
    """H.264 in yuv420p (what browsers and phones play) halves the colour planes: sizes must be even."""
    if width < 2 or height < 2 or width % 2 or height % 2:
        raise UserError(f"an MP4 needs an even width and height (H.264 yuv420p); got {width}x{height}, "
                        "choose an even --size")


class _FfmpegWriter:
    """Streams (H, W, C) uint8 frames (C = 3 RGB or 4 RGBA) into ffmpeg's `codec`."""

    def __init__(self, path: str | Path, width: int, height: int, fps: float, codec: str,
                 channels: int, pix_fmt_out: str, output_params: list[str]):
        check_video_size(width, height)
        if not fps > 0:
            raise UserError(f"the frame rate must be positive, got --fps {fps}")
        self.path, self.size, self.channels, self.frames = Path(path), (width, height), channels, 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # quality=None: the rate is set by each format's -crf.
        self._gen = imageio_ffmpeg.write_frames(
            str(self.path), self.size, pix_fmt_in="rgba" if channels == 4 else "rgb24", fps=fps,
            codec=codec, pix_fmt_out=pix_fmt_out, quality=None, macro_block_size=1,
            ffmpeg_log_level="error", output_params=output_params)
        self._gen.send(None)

    def write(self, frame: np.ndarray) -> None:
        """Append one (H, W, C) uint8 frame."""
        if frame.shape != (self.size[1], self.size[0], self.channels) or frame.dtype != np.uint8:
            raise ValueError(f"frame {frame.shape} {frame.dtype} does not match {self.size} uint8 "
                             f"with {self.channels} channels")
        self._gen.send(np.ascontiguousarray(frame))
        self.frames += 1

    def close(self) -> None:
        """Finish the file."""
        self._gen.close()


class Mp4Writer(_FfmpegWriter):
    """Streams (H, W, 3) uint8 frames into an H.264 MP4 (yuv420p, +faststart for the web)."""

    def __init__(self, path: str | Path, width: int, height: int, fps: float, crf: int = 18):
        # crf 18: visually lossless for smooth renders; +faststart moves the index to the front.
        super().__init__(path, width, height, fps, "libx264", 3, "yuv420p",
                         ["-crf", str(crf), "-movflags", "+faststart"])


class WebmWriter(_FfmpegWriter):
    """Streams frames into a VP9 WebM: (H, W, 4) RGBA with `alpha` (yuva420p, which browsers play
    with transparency), else (H, W, 3) RGB (yuv420p)."""

    def __init__(self, path: str | Path, width: int, height: int, fps: float, alpha: bool = True,
                 crf: int = 30):
        # -b:v 0 makes -crf a constant quality; libvpx cannot carry alpha through alt-ref frames.
        super().__init__(path, width, height, fps, "libvpx-vp9", 4 if alpha else 3,
                         "yuva420p" if alpha else "yuv420p",
                         ["-crf", str(crf), "-b:v", "0", "-auto-alt-ref", "0"])


class AnimationWriter:
    """Collects frames for an animated GIF or WebP (by suffix), downscaled to `max_side` pixels."""

    def __init__(self, path: str | Path, fps: float, max_side: int = 512):
        self.path, self.fps, self.max_side = Path(path), fps, max_side
        self.kind = self.path.suffix.lower().lstrip(".")
        if self.kind not in ("gif", "webp"):
            raise UserError(f"{self.path}: an animation must end in .gif or .webp")
        self._frames: list[Image.Image] = []

    def write(self, frame: np.ndarray) -> None:
        """Keep one (H, W, 3) uint8 frame (GIF frames as 256-colour images: a quarter of the memory)."""
        image = Image.fromarray(frame)
        image.thumbnail((self.max_side, self.max_side), Image.Resampling.LANCZOS)
        self._frames.append(image.quantize(256) if self.kind == "gif" else image)

    def close(self) -> None:
        """Write the looping animation."""
        if not self._frames:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        first, rest = self._frames[0], self._frames[1:]
        options = {"lossless": False, "quality": 85} if self.kind == "webp" else {"optimize": False}
        # GIF durations are whole centiseconds; Pillow rounds each frame's milliseconds.
        first.save(self.path, save_all=True, append_images=rest, duration=1000.0 / self.fps, loop=0,
                   **options)
        self._frames = []


def save_image(frame: np.ndarray, path: str | Path) -> Path:
    """Write one (H, W, 3) RGB or (H, W, 4) RGBA uint8 frame as PNG or JPEG (by suffix; RGB only)."""
    path = Path(path)
    if path.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise UserError(f"{path}: a poster or frame image must end in .png, .jpg or .jpeg")
    path.parent.mkdir(parents=True, exist_ok=True)
    options = {"quality": 92} if path.suffix.lower() != ".png" else {}
    Image.fromarray(frame).save(path, **options)
    return path


def depth_colormap(depth: np.ndarray, opacity: np.ndarray, near: float, far: float,
                   background: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Colour-map a rendered depth (H, W) between `near` and `far` into (H, W, 3) uint8.

    `depth` is the renderers' sum of weights times distance, so dividing by `opacity` (H, W) gives
    the distance of the surface; pixels then blend into `background` by opacity, as empty space has
    no meaningful depth. One fixed range for the whole video keeps the colours from flickering.
    """
    import matplotlib

    lut = matplotlib.colormaps[DEPTH_COLORMAP](np.linspace(0.0, 1.0, 256))[:, :3]  # (256, 3)
    alpha = np.clip(np.asarray(opacity, dtype=np.float64), 0.0, 1.0)
    surface = np.asarray(depth, dtype=np.float64) / np.maximum(alpha, 1e-6)
    t = np.clip((far - surface) / max(far - near, 1e-9), 0.0, 1.0)
    colour = lut[np.rint(t * 255).astype(np.int64)]
    alpha = alpha[..., None]
    return to_uint8(alpha * colour + (1 - alpha) * np.asarray(background))


@dataclass(frozen=True)
class VideoOutputs:
    """Which files one turntable writes; None skips an output."""

    mp4: Path | None = None
    webm: Path | None = None  # VP9; with alpha when `transparent`
    gif: Path | None = None
    webp: Path | None = None
    depth: Path | None = None  # a colour-mapped depth MP4
    poster: Path | None = None  # one frame, PNG or JPEG
    poster_frame: int | None = None  # None: the first (render_run picks the best-covered one)
    frames_dir: Path | None = None  # every frame as frame_0000.<frames_format>
    frames_format: str = "png"  # "png" or "jpg"
    preview_side: int = 512  # longer side of the GIF/WebP frames at most
    transparent: bool = False  # frames carry alpha: kept by the WebM and PNGs, over white elsewhere

    def files(self) -> list[Path]:
        """The single files that will be written (not the frames folder)."""
        return [p for p in (self.mp4, self.webm, self.gif, self.webp, self.depth, self.poster)
                if p is not None]


def straight_rgba(rgb: np.ndarray, opacity: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 RGBA with straight (unassociated) alpha, as PNG and VP9 store it, from a
    frame `rgb` (H, W, 3) rendered over black (so premultiplied by `opacity` (H, W))."""
    alpha = np.clip(np.asarray(opacity, dtype=np.float32), 0.0, 1.0)[..., None]
    colour = np.where(alpha > 0, np.asarray(rgb, dtype=np.float32) / np.maximum(alpha, 1e-6), 0.0)
    return to_uint8(np.concatenate([np.clip(colour, 0.0, 1.0), alpha], axis=-1))


class TurntableWriter:
    """Feeds each rendered frame to every requested output; use as a context manager."""

    def __init__(self, outputs: VideoOutputs, width: int, height: int, fps: float,
                 depth_range: tuple[float, float] = (0.0, 1.0)):
        if outputs.frames_format not in ("png", "jpg"):
            raise UserError(f"frames format must be png or jpg, got {outputs.frames_format!r}")
        if outputs.transparent and outputs.mp4 is not None:
            raise UserError(f"{outputs.mp4}: an H.264 MP4 has no alpha channel; write a transparent "
                            "turntable to a .webm file (VP9 with alpha)")
        self.outputs, self.depth_range, self.frames = outputs, depth_range, 0
        if outputs.mp4 is not None or outputs.webm is not None or outputs.depth is not None:
            check_video_size(width, height)  # before any file is started
        self._videos = [Mp4Writer(p, width, height, fps) for p in (outputs.mp4,) if p is not None]
        self._alpha_videos = [WebmWriter(p, width, height, fps, alpha=outputs.transparent)
                              for p in (outputs.webm,) if p is not None]
        self._depth = Mp4Writer(outputs.depth, width, height, fps) if outputs.depth else None
        self._animations = [AnimationWriter(p, fps, outputs.preview_side)
                            for p in (outputs.gif, outputs.webp) if p is not None]
        if outputs.frames_dir is not None:
            Path(outputs.frames_dir).mkdir(parents=True, exist_ok=True)

    def add(self, rgb: np.ndarray, depth: np.ndarray | None = None,
            opacity: np.ndarray | None = None) -> None:
        """The next frame: colour (H, W, 3) in [0, 1]; depth and opacity (H, W) for the depth video.

        A transparent turntable's `rgb` is rendered over black and `opacity` is its alpha.
        """
        if self.outputs.transparent:
            rgba = straight_rgba(rgb, opacity)
            frame = to_uint8(np.asarray(rgb) + (1.0 - np.asarray(opacity))[..., None])  # over white
        else:
            rgba = frame = to_uint8(rgb)
        for writer in [*self._videos, *self._animations]:
            writer.write(frame)
        for writer in self._alpha_videos:
            writer.write(rgba)
        if self._depth is not None:
            self._depth.write(depth_colormap(depth, opacity, *self.depth_range))
        if self.outputs.poster is not None and self.frames == (self.outputs.poster_frame or 0):
            self._save(rgba, frame, self.outputs.poster)
        if self.outputs.frames_dir is not None:
            name = f"frame_{self.frames:04d}.{self.outputs.frames_format}"
            self._save(rgba, frame, Path(self.outputs.frames_dir) / name)
        self.frames += 1

    @staticmethod
    def _save(rgba: np.ndarray, flat: np.ndarray, path: Path) -> None:
        """PNGs keep the alpha; JPEGs have none and get the frame over white."""
        save_image(rgba if path.suffix.lower() == ".png" else flat, path)

    def close(self) -> None:
        """Finish every file."""
        for writer in [*self._videos, *self._alpha_videos, *self._animations,
                       *([self._depth] if self._depth else [])]:
            writer.close()

    def __enter__(self) -> "TurntableWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_video(path: str | Path, alpha: bool = False) -> tuple[dict, Iterator[np.ndarray]]:
    """Decode a video with ffmpeg: its metadata ("size", "fps", "codec", ...), its (H, W, 3) uint8
    frames, or with `alpha` (H, W, 4) RGBA ones (a WebM's alpha, opaque for other videos)."""
    channels = 4 if alpha else 3
    # ffmpeg's own VP9 decoder drops the alpha plane; libvpx's keeps it.
    vp9 = alpha and Path(path).suffix.lower() == ".webm"
    reader = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgba" if alpha else "rgb24", bpp=channels,
                                        input_params=["-c:v", "libvpx-vp9"] if vp9 else None)
    meta = next(reader)
    width, height = meta["size"]
    return meta, (np.frombuffer(b, dtype=np.uint8).reshape(height, width, channels) for b in reader)


def probe_video(path: str | Path) -> dict:
    """What a video holds, decoded: {"frames", "width", "height", "fps", "codec"}."""
    meta, frames = read_video(path)
    return {"frames": sum(1 for _ in frames), "width": int(meta["size"][0]),
            "height": int(meta["size"][1]), "fps": float(meta["fps"]), "codec": meta.get("codec", "")}
