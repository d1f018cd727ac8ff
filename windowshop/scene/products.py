"""Rendered product captures with known cameras: test and benchmark cases for pose and object
checks, built from scratch (no downloads) with a fixed seed, written as a capture folder:

    out/images/<stem>.jpg   the photos (JPEG quality 95)
    out/masks/<stem>.png    ground-truth object masks (white = object)
    out/transforms.json     nerfstudio layout: fl_x fl_y cx cy w h, frames with file_path,
                            mask_path and transform_matrix (OpenGL camera-to-world), so
                            `windowshop.scene.read_source(out)` reads it back

Cases:
- `doppelganger_box`: a carton whose opposite sides carry the same print, on pure white, a ring
  of hand-held photos: incremental SfM tends to fold the far side onto the near one.
- `figure_on_granite`: a smooth untextured figure on a feature-rich granite table: nearly every
  SIFT point lies on the table, none on the object. With `slope_deg` the table slopes (a statue
  on a sloping street) while the figure stands plumb and the photos are taken level: the support
  plane's normal is then not the true up (world +z).
- `turned`: real photos re-shot by the same camera rotated about its centre (roll about the
  optical axis, pitch up or down): a pure rotation is an exact image warp for any scene. Each
  frame also records the true gravity direction in camera axes (`"gravity"`).

Images are drawn with the project's rasteriser (windowshop.export.raster) at twice the size and
box-filtered down (antialiasing). Shading is Lambert-like and baked (per face on the box, per
vertex on the figure, one value on the table), from the fixed light `LIGHT`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch
from PIL import Image

from windowshop.export.raster import rasterise, shade
from windowshop.scene.cameras import look_at, up_vector
from windowshop.scene.distortion import Distortion, distort
from windowshop.scene.source import SourceFrame
from windowshop.scene.types import Camera

LIGHT = np.array([0.6, -0.35, 0.7]) / np.linalg.norm([0.6, -0.35, 0.7])  # towards the light
JPEG_QUALITY = 95
SUPERSAMPLE = 2  # render at 2x, box-filter down
FOCAL_SHARE = 0.8  # focal length / image width (a phone's ~64 degree horizontal view)
BOX_SIZE = (1.0, 0.7, 1.6)  # carton width (x), depth (y), height (z); stands on z = 0
BOX_TOP = (0.93, 0.88, 0.78)  # plain light top
PRINT_PX = 420  # print pixels per unit
GREY = (0.82, 0.82, 0.82)  # the room behind the granite table
TABLE_HALF = 6.0  # the table is a square of side 12 around the origin
DTU_SIZE = (1600, 1200)  # the image size DTU's projection matrices are for


# ----------------------------------------------------------------------------- capture on disk

def write_capture(out: str | Path, cameras: list[Camera], images: list[np.ndarray],
                  masks: list[np.ndarray] | None, names: list[str],
                  distortions: list[Distortion | None] | None = None,
                  extra: list[dict] | None = None) -> Path:
    """Write `images` (H, W, 3) uint8 as images/<name>.jpg, `masks` (H, W) bool as masks/<name>.png
    and transforms.json (intrinsics global when shared, else per frame; `extra` keys per frame)."""
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    if masks is not None:
        (out / "masks").mkdir(exist_ok=True)
    distortions = distortions or [None] * len(cameras)

    def intrinsics(cam: Camera, d: Distortion | None) -> dict:
        lens = {} if d is None else {k: v for k, v in d.as_dict().items() if k != "fisheye"}
        return {"fl_x": cam.fx, "fl_y": cam.fy, "cx": cam.cx, "cy": cam.cy, "w": cam.width,
                "h": cam.height, **lens}

    first = intrinsics(cameras[0], distortions[0])
    shared = all(intrinsics(c, d) == first for c, d in zip(cameras, distortions))
    frames = []
    for k, (cam, image, name) in enumerate(zip(cameras, images, names)):
        Image.fromarray(image).save(out / "images" / f"{name}.jpg", quality=JPEG_QUALITY)
        frame = {"file_path": f"images/{name}.jpg", "transform_matrix": cam.c2w.tolist()}
        if masks is not None:
            Image.fromarray(np.where(masks[k], 255, 0).astype(np.uint8)).save(
                out / "masks" / f"{name}.png")
            frame["mask_path"] = f"masks/{name}.png"
        frames.append({**frame, **({} if shared else intrinsics(cam, distortions[k])),
                       **(extra[k] if extra else {})})
    meta = {"camera_model": "OPENCV", **(first if shared else {}), "frames": frames}
    (out / "transforms.json").write_text(json.dumps(meta, indent=2))
    return out


def _downsample(image: np.ndarray, factor: int = SUPERSAMPLE) -> np.ndarray:
    """Box-filter (H*f, W*f, ...) down to (H, W, ...)."""
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return image.reshape(h, factor, w, factor, *image.shape[2:]).mean((1, 3))


def _to_uint8(rgb: np.ndarray) -> np.ndarray:
    return np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)


def _camera(eye: np.ndarray, target: np.ndarray, roll_deg: float, size: tuple[int, int]
            ) -> Camera:
    """A level camera at `eye` looking at `target`, rolled by `roll_deg` about its axis."""
    w, h = size
    c2w = look_at(eye, target, np.array([0.0, 0.0, 1.0]))
    c2w[:3, :3] = c2w[:3, :3] @ _rot_z(roll_deg)
    focal = FOCAL_SHARE * w
    return Camera(fx=focal, fy=focal, cx=w / 2, cy=h / 2, width=w, height=h, c2w=c2w)


def ring_cameras(count: int, size: tuple[int, int], target: np.ndarray, distance: float,
                 elevation_deg: float, seed: int, jitter_deg: float = 1.5,
                 jitter_share: float = 0.03) -> list[Camera]:
    """`count` hand-held cameras evenly all round `target` at `elevation_deg`, level up to a small
    random roll; azimuth, elevation and roll jitter by up to `jitter_deg`, distance by
    `jitter_share`."""
    rng = np.random.default_rng(seed)
    cams = []
    for k in range(count):
        az = np.radians(360.0 * k / count + rng.uniform(-jitter_deg, jitter_deg))
        el = np.radians(elevation_deg + rng.uniform(-jitter_deg, jitter_deg))
        dist = distance * (1.0 + rng.uniform(-jitter_share, jitter_share))
        roll = rng.uniform(-jitter_deg, jitter_deg)
        eye = target + dist * np.array([np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), np.sin(el)])
        cams.append(_camera(eye, target, roll, size))
    return cams


def _distance_for(height: float, share: float, size: tuple[int, int]) -> float:
    """Camera distance at which an object `height` tall fills `share` of the frame height."""
    return height * FOCAL_SHARE * size[0] / (share * size[1])


# ----------------------------------------------------------------------------- procedural prints

def noise(shape: tuple[int, int], rng: np.random.Generator, octaves: tuple[int, ...] = (4, 16, 64)
          ) -> np.ndarray:
    """Multi-scale value noise (H, W) in about [0, 1]: random grids of `octaves` cells across,
    upsampled bicubically and summed with weights halving per octave."""
    h, w = shape
    total, weight = np.zeros(shape), 0.0
    for k, cells in enumerate(octaves):
        grid = rng.random((max(2, cells * h // max(h, w)) + 1, cells + 1)).astype(np.float32)
        total += 0.5**k * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        weight += 0.5**k
    return np.clip(total / weight, 0.0, 1.0)


def product_print(width: int, height: int, seed: int) -> np.ndarray:
    """(height, width, 3) uint8: a carton's printed side, rich in SIFT detail and not symmetric:
    a tinted multi-scale noise ground, blobs, brush strokes, block letters, a barcode."""
    rng = np.random.default_rng(seed)
    base = np.array(rng.uniform(0.55, 0.95, 3))
    ground = noise((height, width), rng)[..., None]
    img = (255 * base * (0.8 + 0.35 * ground)).clip(0, 255).astype(np.uint8)
    img = np.ascontiguousarray(img)
    colour = lambda: tuple(int(c) for c in rng.integers(0, 256, 3))  # noqa: E731
    band = int(rng.integers(height // 8, height // 4))  # a coloured band near the top
    cv2.rectangle(img, (0, band), (width, band + height // 7), colour(), -1)
    for _ in range(int(width * height / 2500)):  # blobs, many sizes
        centre = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        axes = (int(rng.integers(3, width // 8)), int(rng.integers(3, width // 8)))
        cv2.ellipse(img, centre, axes, float(rng.uniform(0, 180)), 0, 360, colour(), -1, cv2.LINE_AA)
    for _ in range(int(width * height / 8000)):  # strokes
        points = np.cumsum(rng.normal(0, width / 10, (6, 2)), 0) + rng.uniform(0, [width, height])
        cv2.polylines(img, [points.astype(np.int32)], False, colour(), int(rng.integers(2, 8)),
                      cv2.LINE_AA)
    letters = "ABCDEFGHJKLMNPQRSTUVWXYZ0123456789"
    for row in range(3):  # block letters, left-aligned words
        word = "".join(rng.choice(list(letters), int(rng.integers(3, 7))))
        y = int(height * (0.42 + 0.13 * row))
        scale = width / 160 * (1.3 - 0.3 * row)
        cv2.putText(img, word, (int(width * 0.06), y), cv2.FONT_HERSHEY_DUPLEX, scale, colour(),
                    max(2, int(scale * 2.5)), cv2.LINE_AA)
    x, x1 = int(width * 0.08), int(width * 0.62)  # barcode, lower left
    y0, y1 = int(height * 0.8), int(height * 0.93)
    cv2.rectangle(img, (x - 6, y0 - 6), (x1 + 6, y1 + 6), (250, 250, 250), -1)
    while x < x1:
        bar = int(rng.integers(1, 5)) * max(1, width // 200)
        if rng.random() < 0.55:
            img[y0:y1, x:x + bar] = 20
        x += bar
    return img


# ----------------------------------------------------------------------------- the carton

@dataclass
class Carton:
    """A textured box mesh: `face_side` names the side each triangle is on."""

    vertices: np.ndarray  # (V, 3)
    faces: np.ndarray  # (F, 3)
    uv: np.ndarray  # (V, 2) into `atlas`, glTF's (v = 0 at the top row)
    atlas: np.ndarray  # (H, W, 3) uint8: the front/back print, the left/right print, the top
    face_side: list[str]  # per triangle: front back left right top
    brightness: np.ndarray  # (F,) baked Lambert shading per triangle


SIDES = {  # outward normal, the viewer's right when facing it from outside (up = +z), print
    "front": ((0, -1, 0), (1, 0, 0), 0), "back": ((0, 1, 0), (-1, 0, 0), 0),
    "right": ((1, 0, 0), (0, 1, 0), 1), "left": ((-1, 0, 0), (0, -1, 0), 1),
}


def lambert(normals: np.ndarray) -> np.ndarray:
    """Baked brightness of surfaces with unit `normals` (N, 3): ambient plus a wrapped Lambert term,
    so every side of the box differs."""
    return 0.6 + 0.4 * (0.5 + 0.5 * normals @ LIGHT)


def carton(seed: int = 0, size: tuple[float, float, float] = BOX_SIZE) -> Carton:
    """The doppelganger carton: front and back carry print 0, left and right print 1 (each the
    right way up when seen from outside), a plain light top; no bottom (never seen)."""
    sx, sy, sz = size
    pw, ph = int(sx * PRINT_PX), int(sz * PRINT_PX)
    qw = int(sy * PRINT_PX)
    pad = 4  # gutter between tiles (bilinear sampling stays inside a tile)
    prints = [product_print(pw, ph, seed * 7 + 1), product_print(qw, ph, seed * 7 + 2)]
    top = np.full((qw, pw, 3), _to_uint8(np.array(BOX_TOP)), np.uint8)
    tiles = [prints[0], prints[1], top]
    atlas_w = sum(t.shape[1] + 2 * pad for t in tiles)
    atlas = np.zeros((ph + 2 * pad, atlas_w, 3), np.uint8)
    boxes, x = [], 0  # uv rectangles (u0, v0, u1, v1) of each tile
    for t in tiles:
        th, tw = t.shape[:2]
        atlas[:th + 2 * pad, x:x + tw + 2 * pad] = np.pad(t, ((pad, pad), (pad, pad), (0, 0)), "edge")
        boxes.append(((x + pad) / atlas_w, pad / atlas.shape[0], (x + pad + tw) / atlas_w,
                      (pad + th) / atlas.shape[0]))
        x += tw + 2 * pad
    half = np.array([sx, sy, 0.0]) / 2
    verts, uvs, faces, sides, bright = [], [], [], [], []

    def quad(corners: np.ndarray, rect: tuple, side: str, normal: np.ndarray) -> None:
        """corners: bottom-left, bottom-right, top-right, top-left as seen from outside."""
        u0, v0, u1, v1 = rect
        base = len(verts)
        verts.extend(corners)
        uvs.extend([(u0, v1), (u1, v1), (u1, v0), (u0, v0)])
        faces.extend([(base, base + 1, base + 2), (base, base + 2, base + 3)])
        sides.extend([side, side])
        bright.extend([lambert(normal[None])[0]] * 2)

    for side, (normal, right, tile) in SIDES.items():
        n, r = np.array(normal, float), np.array(right, float)
        centre = n * half + np.array([0, 0, 0.0])
        extent = abs(r @ np.array([sx, sy, 0])) / 2
        bl = centre - r * extent
        br = centre + r * extent
        quad(np.array([bl, br, br + [0, 0, sz], bl + [0, 0, sz]]), boxes[tile], side, n)
    # top: seen from above with the front (-y) side at the bottom of the tile
    quad(np.array([[-sx / 2, -sy / 2, sz], [sx / 2, -sy / 2, sz], [sx / 2, sy / 2, sz],
                   [-sx / 2, sy / 2, sz]]), boxes[2], "top", np.array([0.0, 0.0, 1.0]))
    return Carton(np.array(verts), np.array(faces), np.array(uvs), atlas, sides, np.array(bright))


def render_carton(box: Carton, camera: Camera, shaded: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rgb (H, W, 3) float in [0, 1] on white, coverage (H, W) in [0, 1], side index (H, W) of
    the 2x render's top-left sample, -1 for none) of the carton in `camera`, antialiased."""
    big = camera.resized(camera.width * SUPERSAMPLE, camera.height * SUPERSAMPLE)
    v = torch.as_tensor(box.vertices, dtype=torch.float64)
    f = torch.as_tensor(box.faces, dtype=torch.int64)
    raster = rasterise(v, f, big)
    tex = torch.as_tensor(box.atlas).float() / 255.0
    rgb = shade(raster, f, (1.0, 1.0, 1.0), torch.as_tensor(box.uv, dtype=torch.float32), tex).numpy()
    face = raster.face.numpy()
    hit = face >= 0
    if shaded:
        rgb[hit] *= box.brightness[face[hit]][:, None]
    side = np.full(face.shape, -1)
    names = sorted(set(box.face_side))
    side[hit] = np.array([names.index(s) for s in box.face_side])[face[hit]]
    return (_downsample(rgb), _downsample(hit.astype(np.float64)),
            side[::SUPERSAMPLE, ::SUPERSAMPLE])


def box_cameras(count: int = 40, size: tuple[int, int] = (640, 480), seed: int = 0
                ) -> list[Camera]:
    """The doppelganger photos' cameras: a ring at ~20 degrees elevation, the carton filling about
    60% of the frame height."""
    height = BOX_SIZE[2] * np.cos(np.radians(20)) + BOX_SIZE[1] * np.sin(np.radians(20))
    target = np.array([0.0, 0.0, BOX_SIZE[2] / 2])
    return ring_cameras(count, size, target, _distance_for(height, 0.6, size), 20.0, seed + 1)


def doppelganger_box(out: str | Path, count: int = 40, size: tuple[int, int] = (640, 480),
                     seed: int = 0, only: Sequence[int] | None = None) -> Path:
    """The doppelganger carton on pure white, `count` photos of `size` (w, h) all round (only
    those at the ring's indices `only` when given, named by them); returns `out` (images/,
    masks/, transforms.json)."""
    box = carton(seed)
    ring = box_cameras(count, size, seed)
    picked = range(count) if only is None else only
    images, masks, cams = [], [], [ring[k] for k in picked]
    for cam in cams:
        rgb, cover, _ = render_carton(box, cam)
        images.append(_to_uint8(rgb))
        masks.append(cover >= 0.5)
    return write_capture(out, cams, images, masks, [f"box_{k:03d}" for k in picked])


# ----------------------------------------------------------------------------- figure on granite

FIGURE_PARTS = [  # (kind, centre or ends, radius, albedo): ~1 unit tall, standing on z = 0
    ("cylinder", ((0, 0, 0.0), (0, 0, 0.08)), 0.32, (0.15, 0.30, 0.80)),  # plinth
    ("capsule", ((0, 0, 0.30), (0, 0, 0.58)), 0.24, (0.95, 0.45, 0.08)),  # body
    ("sphere", (0, 0, 0.86), 0.17, (0.15, 0.30, 0.80)),  # head
    ("capsule", ((0.22, 0, 0.60), (0.36, 0.05, 0.36)), 0.06, (0.95, 0.45, 0.08)),  # arm
    ("capsule", ((-0.22, 0, 0.60), (-0.30, -0.10, 0.80)), 0.06, (0.95, 0.45, 0.08)),  # arm up
]
FIGURE_HEIGHT = 1.03


def figure_mesh(sink: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, vertex colours (V, 3) float with Lambert shading baked per vertex).
    `sink` > 0 extends the plinth that far below z = 0 (set into a sloping table, it then
    reaches into the ground on the downhill side instead of floating above it)."""
    import trimesh

    parts = []
    for kind, where, radius, albedo in FIGURE_PARTS:
        if sink > 0 and kind == "cylinder":
            where = ((0, 0, -sink), where[1])
        if kind == "sphere":
            m = trimesh.creation.icosphere(subdivisions=4, radius=radius)
            m.apply_translation(where)
        else:
            a, b = np.array(where, float)
            length = float(np.linalg.norm(b - a))
            m = (trimesh.creation.capsule(height=length, radius=radius, count=[48, 48])
                 if kind == "capsule" else trimesh.creation.cylinder(radius=radius, height=length,
                                                                      sections=96))
            if kind == "capsule":  # trimesh's capsule runs from z = 0 to `height`
                m.apply_translation([0, 0, -length / 2])
            m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], (b - a) / length))
            m.apply_translation((a + b) / 2)
        colour = np.asarray(albedo) * lambert(np.asarray(m.vertex_normals))[:, None]
        parts.append((np.asarray(m.vertices), np.asarray(m.faces), colour))
    verts, faces, cols, base = [], [], [], 0
    for v, f, c in parts:
        verts.append(v)
        faces.append(f + base)
        cols.append(c)
        base += len(v)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(cols)


def _hash(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
    """Uniform [0, 1) values of integer lattice points (i, j) (a 32-bit integer hash)."""
    h = (i.astype(np.int64) * 374761393 + j.astype(np.int64) * 668265263 + seed * 2246822519)
    h = (h & 0xFFFFFFFF).astype(np.uint64)
    h = ((h ^ (h >> np.uint64(13))) * np.uint64(1274126177)) & np.uint64(0xFFFFFFFF)
    h = h ^ (h >> np.uint64(16))
    return h.astype(np.float64) / 2.0**32


def value_noise(xy: np.ndarray, cell: float, seed: int) -> np.ndarray:
    """Smooth value noise (N,) in [0, 1] of world points `xy` (N, 2), lattice spacing `cell`."""
    p = xy / cell
    i, t = np.floor(p), p - np.floor(p)
    t = t * t * (3 - 2 * t)
    a, b = _hash(i[:, 0], i[:, 1], seed), _hash(i[:, 0] + 1, i[:, 1], seed)
    c, d = _hash(i[:, 0], i[:, 1] + 1, seed), _hash(i[:, 0] + 1, i[:, 1] + 1, seed)
    return (a * (1 - t[:, 0]) + b * t[:, 0]) * (1 - t[:, 1]) + (c * (1 - t[:, 0]) + d * t[:, 0]) * t[:, 1]


def granite(xy: np.ndarray, footprint: np.ndarray, seed: int = 0) -> np.ndarray:
    """(N, 3) granite colour at table points `xy` (N, 2): a mottled grey-pink ground with dense dark
    and light grains at several scales. Grains smaller than about two `footprint`s (N,) (the
    world size of a pixel there) fade to their mean, so distant table does not alias."""
    ground = value_noise(xy, 0.25, seed) * 0.6 + value_noise(xy, 0.07, seed + 1) * 0.4
    colour = (np.array([0.62, 0.60, 0.60]) + (ground[:, None] - 0.5) * np.array([0.25, 0.18, 0.16]))
    for k, cell in enumerate((0.045, 0.022, 0.011, 0.0055)):
        fade = np.clip((cell / np.maximum(footprint, 1e-9) - 2.0) / 2.0, 0.0, 1.0)
        dark = np.clip((value_noise(xy, cell, seed + 10 + k) - 0.66) / 0.08, 0, 1) * fade
        light = np.clip((value_noise(xy + 17.3, cell, seed + 20 + k) - 0.70) / 0.08, 0, 1) * fade
        whiten = 0.8 * light[:, None] * (np.array([0.97, 0.93, 0.9]) - colour)
        colour = colour * (1 - 0.75 * dark[:, None]) + whiten
    return colour


def table_tilt(slope_deg: float) -> np.ndarray:
    """(3, 3) the table's rotation for a slope of `slope_deg`: about the world x axis through the
    figure's foot (the origin), so the table rises towards +y; its normal is the third column."""
    return _rot_x(slope_deg)


def _plinth_sink(slope_deg: float) -> float:
    """How far below z = 0 the plinth must reach to meet a table sloping by `slope_deg`."""
    if slope_deg == 0:
        return 0.0
    radius = next(r for kind, _, r, _ in FIGURE_PARTS if kind == "cylinder")
    return radius * abs(np.tan(np.radians(slope_deg))) + 0.02


def granite_scene(slope_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(vertices, faces, vertex colours, figure face count): the figure, then the table (a square
    grid of 2 triangles per cell at z = 0, tilted by `table_tilt(slope_deg)` about the figure's
    foot, its colour computed per pixel by `granite`). The figure stays vertical; on a slope its
    plinth reaches down into the table."""
    fv, ff, fc = figure_mesh(_plinth_sink(slope_deg))
    n = 24
    g = np.linspace(-TABLE_HALF, TABLE_HALF, n + 1)
    gx, gy = np.meshgrid(g, g, indexing="xy")
    tv = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1)
    if slope_deg != 0:
        tv = tv @ table_tilt(slope_deg).T
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tf = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]) + len(fv)
    return (np.concatenate([fv, tv]), np.concatenate([ff, tf]),
            np.concatenate([fc, np.zeros((len(tv), 3))]), len(ff))


def render_granite(scene: tuple, camera: Camera, seed: int = 0, slope_deg: float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(rgb (H, W, 3) in [0, 1], figure coverage (H, W) in [0, 1]) of `granite_scene(slope_deg)`
    in `camera`, antialiased; the table is lit by the same light as the figure, with a soft
    contact shadow around the figure's base; light grey above the table's far edge. The granite
    and the shadow are laid out in the table's own coordinates, so a sloping table carries the
    same pattern."""
    verts, faces, colours, figure_faces = scene
    big = camera.resized(camera.width * SUPERSAMPLE, camera.height * SUPERSAMPLE)
    v = torch.as_tensor(verts, dtype=torch.float64)
    f = torch.as_tensor(faces, dtype=torch.int64)
    raster = rasterise(v, f, big)
    face = raster.face.numpy().ravel()
    bary = raster.bary.numpy().reshape(-1, 3)
    rgb = np.tile(np.asarray(GREY, float), (face.size, 1))
    fig = face >= 0
    fig &= face < figure_faces
    table = face >= figure_faces
    tri = faces[face[fig]]
    rgb[fig] = np.einsum("pk,pkc->pc", bary[fig], colours[tri])
    tri = faces[face[table]]
    points = np.einsum("pk,pkc->pc", bary[table], verts[tri])
    depth = np.linalg.norm(points - camera.center, axis=-1)
    if slope_deg == 0:
        slant = np.abs(camera.center[2]) / np.maximum(depth, 1e-9)  # cos of the incidence angle
        normal = np.array([0.0, 0.0, 1.0])
    else:  # the table's own frame: its points at local z = 0
        tilt = table_tilt(slope_deg)
        normal = tilt[:, 2]
        slant = np.abs((camera.center - points) @ normal) / np.maximum(depth, 1e-9)
        points = points @ tilt
    footprint = depth / big.fx / np.sqrt(np.maximum(slant, 0.05))
    r = np.linalg.norm(points[:, :2], axis=-1)
    shadow = 1.0 - 0.45 * np.exp(-((r / 0.42) ** 2))
    lit = lambert(normal[None])[0] * shadow
    rgb[table] = granite(points[:, :2], footprint, seed) * lit[:, None]
    h, w = big.height, big.width
    return _downsample(rgb.reshape(h, w, 3)), _downsample(fig.reshape(h, w).astype(np.float64))


def granite_cameras(count: int = 20, size: tuple[int, int] = (640, 480), seed: int = 0
                    ) -> list[Camera]:
    """The granite photos' cameras: a ring at ~30 degrees elevation, the figure filling about half
    the frame height."""
    target = np.array([0.0, 0.0, FIGURE_HEIGHT / 2])
    return ring_cameras(count, size, target, _distance_for(FIGURE_HEIGHT, 0.5, size), 30.0,
                        seed + 2)


def figure_on_granite(out: str | Path, count: int = 20, size: tuple[int, int] = (640, 480),
                      seed: int = 0, slope_deg: float = 0.0) -> Path:
    """An untextured orange and blue figure on a granite table, `count` photos of `size` (w, h)
    all round; masks are the figure only. Returns `out`.

    `slope_deg`: the table is tilted by that angle about a horizontal axis (world x) through the
    figure's foot (`table_tilt`), while the figure stays vertical and the cameras level: the
    true up is world +z (transforms.json's frame) whatever the slope, and the support plane's
    normal is `table_tilt(slope_deg)[:, 2]`."""
    scene = granite_scene(slope_deg)
    images, masks, cams = [], [], granite_cameras(count, size, seed)
    for cam in cams:
        rgb, cover = render_granite(scene, cam, seed, slope_deg)
        images.append(_to_uint8(rgb))
        masks.append(cover >= 0.5)
    return write_capture(out, cams, images, masks, [f"figure_{k:03d}" for k in range(count)])


# ----------------------------------------------------------------------------- turned captures

def _rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rot_x(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def turn_rotation(roll_deg: float, pitch_deg: float) -> np.ndarray:
    """(3, 3) the camera's turn in its own OpenGL axes (x right, y up, z back): first pitched by
    `pitch_deg` (positive: looking up), then rolled by `roll_deg` about its new optical axis
    (positive: the camera turns counter-clockwise as its user sees it, so the picture's content
    turns clockwise). The new c2w rotation is the old one times this."""
    return _rot_x(pitch_deg) @ _rot_z(roll_deg)


def homography(camera: Camera, roll_deg: float, pitch_deg: float) -> np.ndarray:
    """(3, 3) pixel map (pixel centres at +0.5, homogeneous) from the source photo to the turned
    one, for a pinhole: K R K^-1 with R the turn in OpenCV camera axes (transposed: the new
    camera's coordinates of a source ray)."""
    flip = np.diag([1.0, -1.0, -1.0])
    rot_cv = flip @ turn_rotation(roll_deg, pitch_deg) @ flip
    return camera.K @ rot_cv.T @ np.linalg.inv(camera.K)


def _undistort(xy: np.ndarray, d: Distortion, steps: int = 30) -> np.ndarray:
    """Ideal normalised coordinates (N, 2) whose distortion is `xy` (fixed-point iteration)."""
    x = xy.copy()
    for _ in range(steps):
        x = x + (xy - distort(x, d))
    return x


def turn_maps(camera: Camera, distortion: Distortion | None, roll_deg: float, pitch_deg: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps (H, W) float32: where each pixel of the turned photo lies in the source.
    Exact for a pinhole (the inverse of `homography`); with lens distortion each pixel is
    undistorted, turned and distorted again, so the turned photo keeps the same lens."""
    d = distortion or Distortion()
    flip = np.diag([1.0, -1.0, -1.0])
    rot_cv = flip @ turn_rotation(roll_deg, pitch_deg) @ flip  # new camera -> source camera
    j, i = np.meshgrid(np.arange(camera.height) + 0.5, np.arange(camera.width) + 0.5, indexing="ij")
    xy = np.stack([(i.ravel() - camera.cx) / camera.fx, (j.ravel() - camera.cy) / camera.fy], -1)
    if not d.is_identity:
        xy = _undistort(xy, d)
    ray = np.concatenate([xy, np.ones((len(xy), 1))], -1) @ rot_cv.T
    ahead = ray[:, 2] > 1e-6
    src = ray[:, :2] / np.where(ahead, ray[:, 2], 1.0)[:, None]
    if not d.is_identity:
        src = distort(src, d)
    u = np.where(ahead, camera.fx * src[:, 0] + camera.cx - 0.5, -1e6)  # cv2: pixel centres at 0
    v = np.where(ahead, camera.fy * src[:, 1] + camera.cy - 0.5, -1e6)
    shape = (camera.height, camera.width)
    return u.reshape(shape).astype(np.float32), v.reshape(shape).astype(np.float32)


def dtu_frames(folder: str | Path) -> list[SourceFrame]:
    """The frames of a DTU/IDR folder (images/NNN.jpg, masks/NNN.png, cameras_sphere.npz's
    world_mat_i), cameras rescaled to the stored images (the matrices are for 1600 x 1200)."""
    folder = Path(folder)
    cams = np.load(folder / "cameras_sphere.npz")
    frames = []
    for image in sorted((folder / "images").glob("*.jpg")):
        k_mat, rot, centre = cv2.decomposeProjectionMatrix(cams[f"world_mat_{int(image.stem)}"][:3])[:3]
        k_mat = k_mat / k_mat[2, 2]
        w, h = Image.open(image).size
        s = w / DTU_SIZE[0]
        c2w = np.eye(4)
        c2w[:3, :3] = rot.T @ np.diag([1.0, -1.0, -1.0])
        c2w[:3, 3] = centre[:3, 0] / centre[3, 0]
        cam = Camera(fx=k_mat[0, 0] * s, fy=k_mat[1, 1] * s, cx=k_mat[0, 2] * s, cy=k_mat[1, 2] * s,
                     width=w, height=h, c2w=c2w)
        mask = folder / "masks" / f"{image.stem}.png"
        frames.append(SourceFrame(camera=cam, image_path=image,
                                  mask_path=mask if mask.is_file() else None))
    return frames


def _frames(source: str | Path | list[SourceFrame]) -> list[SourceFrame]:
    if not isinstance(source, (str, Path)):
        return list(source)
    if (Path(source) / "cameras_sphere.npz").is_file():
        return dtu_frames(source)
    from windowshop.scene import read_source

    return read_source(source).frames


def turned(photos: str | Path | list[SourceFrame], out: str | Path,
           rolls_deg: float | list[float], pitch_deg: float | list[float] = 0.0,
           up: np.ndarray | None = None, border: str = "black") -> Path:
    """Copies of posed photos as the same cameras, turned about their centres, would have taken
    them: photo k rolled by `rolls_deg[k]` and pitched by `pitch_deg` (one value or one per photo;
    see `turn_rotation`). `photos` is a dataset folder (anything `read_source` reads, or a DTU
    folder with cameras_sphere.npz) or a list of SourceFrames. Same intrinsics, lens and size;
    the parts of the view the source never saw are `border`: "black" or "edge" (replicated).
    Masks, if the source has them, are turned too (outside: background).

    Each frame records `"gravity"`: the unit down direction in the turned camera's OpenGL axes,
    from `up` (the world's up, default: `up_vector(c2ws, "level")` of the source cameras)."""
    frames = _frames(photos)
    n = len(frames)
    rolls = np.broadcast_to(np.asarray(rolls_deg, float), (n,))
    pitches = np.broadcast_to(np.asarray(pitch_deg, float), (n,))
    c2ws = np.stack([f.camera.c2w for f in frames])
    up = up_vector(c2ws, "level") if up is None else np.asarray(up, float) / np.linalg.norm(up)
    mode = {"black": cv2.BORDER_CONSTANT, "edge": cv2.BORDER_REPLICATE}[border]
    cams, images, masks, extras, lenses = [], [], [], [], []
    has_masks = all(f.mask_path is not None for f in frames)
    for f, roll, pitch in zip(frames, rolls, pitches):
        cam = f.camera
        pixels = np.asarray(Image.open(f.image_path).convert("RGB"))
        if pixels.shape[:2] != (cam.height, cam.width):
            pixels = cv2.resize(pixels, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        mx, my = turn_maps(cam, f.distortion, roll, pitch)
        images.append(cv2.remap(pixels, mx, my, cv2.INTER_LINEAR, borderMode=mode))
        if has_masks:
            mask = np.asarray(Image.open(f.mask_path).convert("L"))
            mask = cv2.resize(mask, (cam.width, cam.height), interpolation=cv2.INTER_NEAREST)
            masks.append(cv2.remap(mask, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
                         > 127)
        c2w = cam.c2w.copy()
        c2w[:3, :3] = c2w[:3, :3] @ turn_rotation(roll, pitch)
        cams.append(replace(cam, c2w=c2w))
        gravity = c2w[:3, :3].T @ -up
        extras.append({"gravity": gravity.tolist(), "roll_deg": float(roll),
                       "pitch_deg": float(pitch)})
        lenses.append(f.distortion)
    names = [Path(f.image_path).stem for f in frames]
    return write_capture(out, cams, images, masks if has_masks else None, names, lenses, extras)


def on_turntable(photos: str | Path | list[SourceFrame], backdrop: str | Path, out: str | Path,
                 feather_px: float = 1.0, nudge_px: int = 0, seed: int = 0) -> Path:
    """Copies of masked posed photos as a phone that stood still would take them while the object
    turned in front of it (a turntable): each photo's object (its mask, edges feathered by
    `feather_px`) over the one photo `backdrop`, resized to the photo and shifted by up to
    `nudge_px` whole pixels either way, drawn from `seed` (a propped phone nudged when its shutter
    is tapped). The object's cameras stay its cameras (the object turns, not the phone), with
    masks, and each frame's "gravity" from the world's up (`up_vector(c2ws, "level")`), as
    `turned` writes them."""
    frames = _frames(photos)
    up = up_vector(np.stack([f.camera.c2w for f in frames]), "level")
    rng = np.random.default_rng(seed)
    with Image.open(backdrop) as image:
        room = image.convert("RGB")
    images, masks = [], []
    for f in frames:
        cam = f.camera
        size = (cam.width, cam.height)
        pixels = np.asarray(Image.open(f.image_path).convert("RGB").resize(size), np.float32)
        mask = np.asarray(Image.open(f.mask_path).convert("L").resize(size)) > 127
        alpha = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), feather_px)[..., None]
        larger = (size[0] + 2 * nudge_px, size[1] + 2 * nudge_px)
        dx, dy = rng.integers(0, 2 * nudge_px + 1, 2)
        behind = np.asarray(room.resize(larger, Image.LANCZOS), np.float32)[
            dy:dy + size[1], dx:dx + size[0]]
        images.append(np.clip(pixels * alpha + behind * (1 - alpha) + 0.5, 0, 255).astype(np.uint8))
        masks.append(mask)
    cameras = [f.camera for f in frames]
    return write_capture(out, cameras, images, masks, [Path(f.image_path).stem for f in frames],
                         [f.distortion for f in frames],
                         [{"gravity": (c.c2w[:3, :3].T @ -up).tolist()} for c in cameras])
