"""Image files to float arrays, with clear errors, and resizing with an area (box) filter."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TypeVar

import numpy as np
from PIL import Image, UnidentifiedImageError

from windowshop.errors import UserError

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp"}
T = TypeVar("T")
R = TypeVar("R")


def _open(path: Path, at_least: tuple[int, int] | None = None) -> tuple[Image.Image, tuple[int, int]]:
    """The decoded Pillow image at `path` and its stored (width, height); UserError if it fails.

    With `at_least` (width, height), a JPEG may be decoded straight at a 1/2, 1/4 or 1/8 scale
    that is still at least that large (much faster when the images are downscaled anyway).
    """
    if not path.is_file():
        raise UserError(f"{path}: image file not found; check the path in the scene description")
    try:
        image = Image.open(path)
        size = image.size
        if at_least is not None:
            image.draft(image.mode, at_least)
        image.load()
    except (UnidentifiedImageError, OSError, ValueError) as err:
        raise UserError(f"{path}: cannot decode the image ({err}); replace or remove it") from err
    return image, size


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) read from the file header only."""
    if not path.is_file():
        raise UserError(f"{path}: image file not found; check the path in the scene description")
    try:
        with Image.open(path) as image:
            return image.size
    except (UnidentifiedImageError, OSError) as err:
        raise UserError(f"{path}: cannot read the image ({err}); replace or remove it") from err


def sixteen_bit_grey(image: Image.Image) -> bool:
    """Whether Pillow holds the image as 16-bit grey (I;16, or I as some files give it): its
    `convert` to 8 bits would clip every value over 255, a photo turned white."""
    return image.mode in ("I;16", "I;16B", "I;16L", "I")


def eight_bit(image: Image.Image) -> Image.Image:
    """The image, a 16-bit grey one scaled to 8-bit grey ("L"); any other as it is."""
    if not sixteen_bit_grey(image):
        return image
    grey = np.asarray(image, dtype=np.float32) * np.float32(255.0 / 65535.0)
    return Image.fromarray(np.clip(np.rint(grey), 0, 255).astype(np.uint8), "L")


def _to_float(image: Image.Image) -> np.ndarray:
    """Pillow image -> float32 (H, W, 3) or (H, W, 4) with straight (not premultiplied) alpha."""
    has_alpha = image.mode in ("RGBA", "LA", "PA") or "transparency" in image.info
    if sixteen_bit_grey(image):
        grey = np.asarray(image, dtype=np.float32) / 65535.0
        return np.repeat(grey[..., None], 3, axis=-1)
    mode = "RGBA" if has_alpha else "RGB"
    array = np.asarray(image if image.mode == mode else image.convert(mode)).astype(np.float32)
    array *= np.float32(1.0 / 255.0)
    return array


def load_pixels(path: Path, at_least: tuple[int, int] | None = None
                ) -> tuple[np.ndarray, tuple[int, int]]:
    """float32 (H, W, 3), or (H, W, 4) when the file has alpha, values in [0, 1], and the stored
    (width, height); see `_open` for `at_least`."""
    image, size = _open(path, at_least)
    return _to_float(image), size


def load_mask(path: Path) -> np.ndarray:
    """A foreground mask image as float32 (H, W) in [0, 1] (its alpha if it has one)."""
    pixels, _ = load_pixels(path)
    return pixels[..., 3] if pixels.shape[-1] == 4 else pixels.mean(-1)


def resize(array: np.ndarray, width: int, height: int) -> np.ndarray:
    """`array` (H, W) or (H, W, C) float32 resampled to height x width with a box (area) filter."""
    if array.shape[1] == width and array.shape[0] == height:
        return array
    channels = array[..., None] if array.ndim == 2 else array
    out = np.stack([np.asarray(Image.fromarray(np.ascontiguousarray(channels[..., c]))
                               .resize((width, height), Image.Resampling.BOX))
                    for c in range(channels.shape[-1])], axis=-1)
    return out[..., 0] if array.ndim == 2 else out


def parallel_map(fn: Callable[[T], R], items: Sequence[T],
                 advance: Callable[[int], object] = lambda n=1: None) -> list[R]:
    """[fn(x) for x in items] on a thread pool (Pillow and numpy release the GIL while decoding);
    `advance(1)` is called in the calling thread as each result comes, in order."""
    if len(items) < 2:
        return [_advanced(fn(x), advance) for x in items]
    with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1, len(items))) as pool:
        return [_advanced(result, advance) for result in pool.map(fn, items)]


def _advanced(result: R, advance: Callable[[int], object]) -> R:
    advance(1)
    return result
