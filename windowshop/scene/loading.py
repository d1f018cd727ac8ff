"""Source -> Scene, the same for every format: pick the views, decode, undistort and resize the
images, composite the background, and normalise the world frame."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from windowshop.config import SceneOptions
from windowshop.errors import UserError
from windowshop.scene import hull, normalize
from windowshop.scene.cameras import nearest_point_to_axes, up_vector
from windowshop.scene.distortion import undistort_image, undistorted_camera
from windowshop.scene.images import load_mask, load_pixels, parallel_map, resize
from windowshop.scene.selection import assign_splits
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import BACKGROUND_CHOICES, Scene, View, composite_colour

BLACK_LEVEL = 0.05  # brighter pixels of a black-background source count as the object


def target_size(width: int, height: int, options: SceneOptions) -> tuple[int, int]:
    """(width, height) after the options' downscale factor and maximum side."""
    if options.downscale <= 0:
        raise UserError(f"downscale must be positive, got {options.downscale}")
    scale = 1.0 / options.downscale
    if options.max_side is not None:
        scale = min(scale, options.max_side / max(width, height))
    return max(1, round(width * scale)), max(1, round(height * scale))


def _read_pixels(frame: SourceFrame, width: int, height: int) -> np.ndarray:
    """The frame's pixels (h, w, 3|4), decoded at no less than `width` x `height` (the smallest
    stored copy, or a reduced JPEG decode, that is at least that large)."""
    if frame.pixels is not None:
        return frame.pixels
    for factor in sorted(frame.prescaled, reverse=True):
        if frame.camera.width / factor >= width - 0.5 and frame.prescaled[factor].is_file():
            return load_pixels(frame.prescaled[factor], (width, height))[0]
    pixels, size = load_pixels(frame.image_path, (width, height))
    stored = (frame.camera.width, frame.camera.height)
    if size != stored:
        raise UserError(f"{frame.image_path}: the image is {size[0]}x{size[1]} but its camera is "
                        f"{stored[0]}x{stored[1]}; give per-image intrinsics (w, h, fl_x, ...) "
                        f"or make all images the same size")
    return pixels


def _read_mask(frame: SourceFrame, width: int, height: int) -> np.ndarray:
    """The frame's foreground mask (height, width), checked against the stored image size."""
    mask = load_mask(frame.mask_path)
    if (mask.shape[1], mask.shape[0]) != (frame.camera.width, frame.camera.height):
        raise UserError(f"{frame.mask_path}: the mask is {mask.shape[1]}x{mask.shape[0]} but its "
                        f"image is {frame.camera.width}x{frame.camera.height}")
    return resize(mask, width, height)


def _load_view(frame: SourceFrame, split: str, options: SceneOptions) -> View:
    """One decoded view, in the source's world frame (normalised later)."""
    width, height = target_size(frame.camera.width, frame.camera.height, options)
    pixels = resize(_read_pixels(frame, width, height), width, height)
    # an alpha matte (RGBA) is composited over the background; a separate mask is only recorded
    matte = pixels.shape[-1] == 4 and frame.mask_path is None
    alpha = pixels[..., 3] if matte else None
    rgb = pixels[..., :3] * alpha[..., None] if matte else pixels[..., :3]  # premultiplied
    if frame.mask_path is not None:
        alpha = _read_mask(frame, width, height)
    camera = frame.camera.resized(width, height)
    if frame.distortion is not None and not frame.distortion.is_identity:
        stored = camera
        camera = undistorted_camera(stored, frame.distortion)
        stack = np.concatenate([rgb, alpha[..., None]], -1) if alpha is not None else rgb
        stack = undistort_image(stack, stored, camera, frame.distortion)
        rgb, alpha = (stack[..., :3], stack[..., 3]) if alpha is not None else (stack, None)
    if matte and options.background == "alpha":
        rgb = straight_colour(rgb, alpha)
    elif matte:
        colour = np.asarray(composite_colour(options.background), dtype=rgb.dtype)
        rgb = rgb + (1.0 - alpha[..., None]) * colour
    return View(camera=camera, image=np.ascontiguousarray(rgb, dtype=np.float32), split=split,
                name=str(frame.image_path), alpha=alpha, stored_camera=frame.camera,
                distortion=frame.distortion.as_dict() if frame.distortion else None)


def straight_colour(premultiplied: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """(H, W, 3) colour not multiplied by `alpha` (H, W): what "alpha" scenes keep, as their masked
    photos do, so that training and scoring composite each pixel once as rgb * a + bg * (1 - a)
    (a premultiplied edge pixel would be darkened twice). Resampling is done premultiplied first,
    so no colour of a transparent pixel leaks in; fully transparent pixels get black."""
    a = alpha[..., None]
    straight = np.where(a > 0, premultiplied / np.maximum(a, 1e-6), 0.0)
    return straight.clip(0.0, 1.0).astype(premultiplied.dtype)


def _silhouette(view: View, source: Source) -> np.ndarray | None:
    """(H, W) the object's mask: the alpha, or for a black-background source any non-black pixel."""
    if view.alpha is not None:
        return view.alpha
    if source.background == "black":
        return (view.image.max(-1) > BLACK_LEVEL).astype(np.float32)
    return None


def _object_box(source: Source, views: list[View], rotation: np.ndarray,
                target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the object in the rotated source frame, from the best evidence at hand."""
    cameras = [f.camera for f in source.frames]
    radius = normalize.inscribed_radius(cameras, target)
    if source.box is not None:
        corners = np.array([[source.box[i, 0], source.box[j, 1], source.box[k, 2]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return normalize.box_of(corners, rotation, padding=0.0)
    masked = [(v.camera, _silhouette(v, source)) for v in views]
    masked = [(cam, mask) for cam, mask in masked if mask is not None]
    if len(masked) >= 2:
        half = min(2.0 * radius, 0.95 * min(np.linalg.norm(c.center - target) for c in cameras))
        inside = hull.hull_points(*map(list, zip(*masked)), target, half)
        if inside is not None:
            lo, hi = normalize.box_of(inside, rotation, padding=0.0)
            voxel = 2.0 * half / hull.GRID
            return lo - voxel, hi + voxel
    if source.points is not None and len(source.points) >= 8:
        near = source.points[np.linalg.norm(source.points - target, axis=-1) < 2.0 * radius]
        if len(near) >= 8:
            return normalize.box_of(near, rotation, percentile=2.0)
    centre = rotation @ target
    return centre - radius, centre + radius


def _up(source: Source) -> np.ndarray:
    """(3,) unit up of the source world: the published one, else from the cameras."""
    if source.up is not None:
        return np.asarray(source.up, dtype=np.float64) / np.linalg.norm(source.up)
    return up_vector(np.stack([f.camera.c2w for f in source.frames]))


def _object_target(source: Source) -> np.ndarray:
    """(3,) a first guess of the object centre in the source frame."""
    if source.box is not None:
        return source.box.mean(0)
    return nearest_point_to_axes(np.stack([f.camera.c2w for f in source.frames]))


def build_scene(source: Source, options: SceneOptions) -> Scene:
    """The Scene of `source` under `options` (see SceneOptions)."""
    if not source.frames:
        raise UserError(f"{source.path}: the scene has no frames (an empty frame list)")
    if options.background not in BACKGROUND_CHOICES:
        raise UserError(f"unknown background {options.background!r}; use white, black or alpha")
    target = _object_target(source)
    centres = np.stack([f.camera.center for f in source.frames])
    splits = assign_splits([f.split for f in source.frames], centres, target, options.views,
                           options.test_views, options.view_ids, options.test_every)
    kept = [(f, s) for f, s in zip(source.frames, splits) if s is not None]
    views = parallel_map(lambda fs: _load_view(fs[0], fs[1], options), kept)
    normalizing = options.normalize and not source.normalized
    rotation = normalize.rotation_to_z(_up(source)) if normalizing else np.eye(3)
    lo, hi = _object_box(source, views, rotation, target)
    if normalizing:
        transform, aabb = normalize.similarity(rotation, lo, hi)
    else:
        transform, aabb = np.eye(4), np.stack([lo, hi])
    views = [replace(v, camera=v.camera.transformed(transform)) for v in views]
    near, far = normalize.near_far(np.stack([v.camera.center for v in views]), aabb)
    return Scene(views=views, format=source.format, source=source.path, aabb=aabb, near=near,
                 far=far, transform=transform, background=_background(source, views, options),
                 options=options, notes=tuple(source.notes))


def _background(source: Source, views: list[View], options: SceneOptions) -> str:
    """What the images' background is: the option for alpha mattes, else the source's own."""
    if any(v.alpha is not None for v in views) and all(f.mask_path is None for f in source.frames):
        return options.background
    if source.background is not None:
        return source.background
    return "white" if options.background == "alpha" else options.background
