"""Masks on a busy background: seeded GrabCut and the visual hull, on a rendered ball on a
chequered floor (known silhouettes), and the optional rembg backend's error when absent."""

from __future__ import annotations

import numpy as np
import pytest

from windowshop.errors import UserError
from windowshop.photos import matting_rembg, objectbox, segment
from windowshop.rays import project
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

CENTRE, RADIUS = np.array([0.0, 0.0, 0.5]), 0.5  # a ball resting on the floor z = 0


def _hit_ball(origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(N,) distance along unit rays `dirs` (N, 3) from `origin` (3,) to the ball (inf: miss)."""
    oc = origin - CENTRE
    b = dirs @ oc
    disc = b**2 - (oc @ oc - RADIUS**2)
    t = -b - np.sqrt(np.maximum(disc, 0))
    return np.where((disc > 0) & (t > 0), t, np.inf)


def _render(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(pixels (H, W, 3) uint8, true mask (H, W) bool): a striped ball on a chequered floor
    before a dark room."""
    j, i = np.mgrid[0:cam.height, 0:cam.width] + 0.5
    local = np.stack([(i - cam.cx) / cam.fx, -(j - cam.cy) / cam.fy, -np.ones_like(i)], -1)
    dirs = local.reshape(-1, 3) @ cam.c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origin = cam.center
    t_ball = _hit_ball(origin, dirs)
    t_floor = np.where(dirs[:, 2] < 0, -origin[2] / np.minimum(dirs[:, 2], -1e-9), np.inf)
    ball = t_ball < t_floor
    sky = ~ball & ~np.isfinite(t_floor)
    p = origin + np.where(ball, t_ball, np.where(sky, 0.0, t_floor))[:, None] * dirs
    n = (p - CENTRE) / RADIUS
    stripes = np.stack([200 + 40 * np.sin(9 * n[:, 2]), 60 + 50 * np.sin(7 * np.arctan2(n[:, 1],
                        n[:, 0])), 50 + 0 * n[:, 0]], -1)
    tile = (np.floor(3 * p[:, 0]) + np.floor(3 * p[:, 1])) % 2
    floor = np.where(tile[:, None] > 0, [150, 110, 70], [110, 80, 55])
    floor = np.where((~sky & (np.hypot(p[:, 0], p[:, 1]) < 3))[:, None], floor, 25)
    colour = np.where(ball[:, None], stripes, floor)
    shape = (cam.height, cam.width)
    return colour.reshape(*shape, 3).astype(np.uint8), ball.reshape(shape)


def _views(rng: np.random.Generator, count: int = 10) -> tuple[list[segment.View], list]:
    """Views around the ball, each with the sparse points it sees (ball and floor)."""
    on_ball = rng.normal(size=(400, 3))
    on_ball = CENTRE + RADIUS * on_ball / np.linalg.norm(on_ball, axis=1, keepdims=True)
    angle, radius = rng.uniform(0, 2 * np.pi, 600), rng.uniform(0.7, 2.5, 600)
    on_floor = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros(600)])
    views, truths = [], []
    for a in np.linspace(0, 2 * np.pi, count, endpoint=False):
        eye = 3.5 * np.array([np.cos(a) * np.cos(0.5), np.sin(a) * np.cos(0.5), np.sin(0.5)])
        cam = Camera(fx=160, fy=160, cx=96, cy=72, width=192, height=144,
                     c2w=look_at(eye, CENTRE, np.array([0.0, 0.0, 1.0])))
        facing = np.sum((on_ball - CENTRE) * (eye - on_ball), axis=1) > 0
        to_floor = on_floor - eye
        length = np.linalg.norm(to_floor, axis=1)
        clear = _hit_ball(eye, to_floor / length[:, None]) > length
        pixels, truth = _render(cam)
        views.append(segment.View(f"v{len(views)}", pixels, cam, project(on_ball[facing], cam)[0],
                                  project(on_floor[clear], cam)[0]))
        truths.append(truth)
    return views, truths


def test_seeded_grabcut_and_the_hull_find_the_ball():
    views, truths = _views(np.random.default_rng(0))
    search = np.array([[-0.8, -0.8, 0.01], [0.8, 0.8, 1.3]])  # floor on the support plane
    masks, box = segment.consistent(segment.segment(views, search), [v.camera for v in views],
                                    search)
    ious = [(m & t).sum() / (m | t).sum() for m, t in zip(masks, truths)]
    assert np.mean(ious) > 0.9 and min(ious) > 0.8, ious
    np.testing.assert_allclose(box, [[-0.5, -0.5, 0.01], [0.5, 0.5, 1.0]], atol=0.1)


def test_hull_silhouette_covers_what_the_voxels_project_to():
    cam = _views(np.random.default_rng(1), count=1)[0][0].camera
    axis = np.linspace(-0.45, 0.45, 10)
    voxels = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3) + CENTRE
    silhouette = segment.hull_silhouette(voxels, 0.1, cam)
    uv = project(voxels, cam)[0].astype(int)
    assert silhouette[uv[:, 1], uv[:, 0]].all()
    corners = project(CENTRE + 0.5 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1)
                                               for z in (-1, 1)]), cam)[0]
    lo, hi = np.floor(corners.min(0)).astype(int), np.ceil(corners.max(0)).astype(int)
    pad = 7  # squares are drawn on a grid of half a voxel (~2 px here): a voxel and a cell
    outside = np.ones_like(silhouette)
    outside[max(lo[1] - pad, 0):hi[1] + pad, max(lo[0] - pad, 0):hi[0] + pad] = False
    assert not (silhouette & outside).any() and silhouette.sum() < 1.5 * (hi - lo).prod()


def test_rembg_missing_is_a_user_error(monkeypatch, tmp_path):
    monkeypatch.setenv("U2NET_HOME", str(tmp_path))
    with pytest.raises(UserError, match="rembg"):
        matting_rembg.masks([np.zeros((8, 8, 3), dtype=np.uint8)])


def _boxes_image(cam: Camera, boxes: list[np.ndarray], label: bool) -> np.ndarray:
    """(H, W, 3) uint8: textured boxes (each (2, 3)) on white; with `label`, a white square on
    the +x face of the first box."""
    j, i = np.mgrid[0:cam.height, 0:cam.width] + 0.5
    local = np.stack([(i - cam.cx) / cam.fx, -(j - cam.cy) / cam.fy, -np.ones_like(i)], -1)
    dirs = local.reshape(-1, 3) @ cam.c2w[:3, :3].T
    inv = 1.0 / np.where(np.abs(dirs) < 1e-12, 1e-12, dirs)
    nearest = np.full(len(dirs), np.inf)
    for box in boxes:  # slab test
        t0, t1 = (box[0] - cam.center) * inv, (box[1] - cam.center) * inv
        enter, leave = np.minimum(t0, t1).max(1), np.maximum(t0, t1).min(1)
        nearest = np.where((enter <= leave) & (enter > 0), np.minimum(nearest, enter), nearest)
    hit = np.isfinite(nearest)
    p = cam.center + np.where(hit, nearest, 0)[:, None] * dirs
    colour = np.where(hit[:, None], np.stack([120 + 60 * np.sin(9 * p[:, 1]),
                      90 + 60 * np.sin(7 * p[:, 2]), 60 + 40 * np.sin(5 * p[:, 0])], -1), 255)
    if label:
        on = hit & (np.abs(p[:, 0] - boxes[0][1, 0]) < 1e-6) & (np.abs(p[:, 1]) < 0.25) \
            & (np.abs(p[:, 2]) < 0.25)
        colour[on] = 255
    return colour.reshape(cam.height, cam.width, 3).astype(np.uint8)


@pytest.mark.parametrize("thing", ["frame", "labelled box"])
def test_holes_stay_the_objects_unless_the_views_see_through(thing):
    """A picture frame's hole is seen through from most directions: background. A white label
    on a box is seen from one side only: the box's, though it looks like the background."""
    cube = np.array([[-0.4, -0.4, -0.4], [0.4, 0.4, 0.4]])
    bars = [np.array([[-0.1, -0.5, lo], [0.1, 0.5, lo + 0.25]]) for lo in (-0.5, 0.25)] + \
        [np.array([[-0.1, lo, -0.25], [0.1, lo + 0.25, 0.25]]) for lo in (-0.5, 0.25)]
    boxes = bars if thing == "frame" else [cube]
    cameras, silhouettes, raws = [], [], []
    for a in np.linspace(0, 2 * np.pi, 16, endpoint=False):
        eye = 4 * np.array([np.cos(a) * np.cos(0.3), np.sin(a) * np.cos(0.3), np.sin(0.3)])
        cam = Camera(fx=128, fy=128, cx=64, cy=64, width=128, height=128,
                     c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])))
        pixels = _boxes_image(cam, boxes, label=thing != "frame")
        silhouette, raw = objectbox.foreground_mask(pixels, objectbox.plain_colour(pixels))
        cameras.append(cam)
        silhouettes.append(silhouette)
        raws.append(raw)
    final = segment.see_through(silhouettes, raws, cameras, np.array([[-0.6] * 3, [0.6] * 3]))
    u, v = project(np.array([[0.1, 0.0, 0.0], [0.4, 0.0, 0.0]]), cameras[0])[0].astype(int)[
        0 if thing == "frame" else 1]
    assert silhouettes[0][v, u] and not raws[0][v, u]  # a hole in the front view either way
    assert final[0][v, u] == (thing != "frame")
    assert all(f.sum() >= 0.9 * r.sum() for f, r in zip(final, raws))  # the rest is kept


def test_photos_beyond_the_hulls_subset_are_cut_within_it(monkeypatch):
    # the first round cuts 4 of the 10 photos; the other 6 start from the hull's outline alone
    monkeypatch.setattr(segment, "HULL_VIEWS", 4)
    views, truths = _views(np.random.default_rng(0))
    cut = []
    monkeypatch.setattr(segment, "grabcut_mask",
                        lambda v, aabb, real=segment.grabcut_mask: cut.append(v.name) or real(v, aabb))
    masks = segment.segment(views, np.array([[-0.8, -0.8, 0.01], [0.8, 0.8, 1.3]]))
    ious = [(m & t).sum() / (m | t).sum() for m, t in zip(masks, truths)]
    assert len(cut) == 4 and len(masks) == len(views)
    assert np.mean(ious) > 0.9 and min(ious) > 0.8, ious
