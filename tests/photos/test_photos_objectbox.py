"""Finding the object: its box from sparse points, masks on plain backgrounds, pose alignment."""

from __future__ import annotations


import numpy as np
import pytest
from PIL import Image

from windowshop.photos import objectbox
from windowshop.photos.align import pose_errors, rotation_angle, rotation_between, umeyama
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera
from shared_data import DATA

KERMIT = DATA / "kermit"


def _ring(n: int = 12, radius: float = 4.0, size: int = 64) -> list[Camera]:
    """Cameras on a ring 25 degrees above the origin, all looking at it (up = +z)."""
    cams = []
    for a in np.linspace(0, 2 * np.pi, n, endpoint=False):
        eye = radius * np.array([np.cos(a) * np.cos(0.44), np.sin(a) * np.cos(0.44), np.sin(0.44)])
        cams.append(Camera(fx=size, fy=size, cx=size / 2, cy=size / 2, width=size, height=size,
                           c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))))
    return cams


def test_object_box_keeps_the_object_and_drops_the_background():
    rng = np.random.default_rng(0)
    obj = rng.uniform([-0.4, -0.3, -0.5], [0.4, 0.3, 0.5], size=(400, 3))
    wall = np.column_stack([rng.uniform(-6, 6, 300), np.full(300, 7.0), rng.uniform(-1, 3, 300)])
    floor = np.column_stack([rng.uniform(-8, 8, (300, 2)), np.full(300, -0.5)])
    floor = floor[np.linalg.norm(floor[:, :2], axis=1) > 2.5]  # floor away from the object
    cams = _ring()
    points = np.concatenate([obj, wall, floor])
    chosen = points[objectbox.object_index(points, cams)]
    lo, hi = objectbox.object_box(chosen, cams, np.eye(3))
    assert len(chosen) == len(obj)
    assert np.all(lo <= obj.min(0)) and np.all(hi >= obj.max(0))
    assert np.all(lo > obj.min(0) - 0.1) and np.all(hi < obj.max(0) + 0.1)


def test_object_box_without_points_is_the_sphere_every_view_sees():
    cams = _ring()
    lo, hi = objectbox.object_box(np.zeros((0, 3)), cams, np.eye(3))
    half = 4.0 * np.sin(np.arctan(0.5))  # distance x sin(half field of view)
    np.testing.assert_allclose(lo, -half, atol=1e-6)
    np.testing.assert_allclose(hi, half, atol=1e-6)


def test_seen_counts_match_projection():
    cams = _ring(n=4)
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 30.0]])  # the centre; a point above every view
    np.testing.assert_array_equal(objectbox.seen_counts(points, cams), [4, 0])


def _ring_object(background: int, size: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """(pixels (H, W, 3) uint8, true mask (H, W)): a textured ring (a big hole showing the
    background) with a small dark spot, on a plain `background` with sensor noise."""
    rng = np.random.default_rng(2)
    y, x = np.mgrid[0:size, 0:size] - size / 2
    r = np.hypot(x, y)
    truth = (r < 0.4 * size) & (r > 0.15 * size)
    texture = np.stack([128 + 60 * np.sin(x / 3), 128 + 60 * np.cos(y / 4),
                        128 + 40 * np.sin((x + y) / 5)], -1)
    pixels = np.where(truth[..., None], texture, background) + rng.normal(0, 4, (size, size, 3))
    spot = np.hypot(x - 0.27 * size, y) < 3  # a dark spot on the object, like a shadow
    pixels[spot] = background
    return np.clip(pixels, 0, 255).astype(np.uint8), truth


@pytest.mark.parametrize("background", [255, 0])
def test_foreground_mask_matches_the_true_silhouette(background):
    pixels, truth = _ring_object(background)
    colour = objectbox.plain_colour(pixels)
    np.testing.assert_allclose(colour, background, atol=6)
    silhouette, raw = objectbox.foreground_mask(pixels, colour)
    assert (raw & truth).sum() / (raw | truth).sum() > 0.95
    assert not raw[80, 80] and not raw[80, 80 + int(0.27 * 160)]  # the hole and the spot
    # One view cannot tell the ring's hole from a background-coloured part of the object: the
    # silhouette keeps every hole (segment.see_through reopens those other views see through).
    assert silhouette[80, 80] and silhouette[80, 80 + int(0.27 * 160)]
    assert silhouette.sum() == pytest.approx(np.pi * (0.4 * 160) ** 2, rel=0.05)


def test_foreground_mask_keeps_a_white_part_of_the_object():
    """A textured object with a large white label on a white background: the label is the
    object's (before, holes over 0.2% of the image were taken for background)."""
    pixels, _ = _ring_object(255)
    y, x = np.mgrid[0:160, 0:160] - 80
    pixels[np.hypot(x, y) < 0.15 * 160] = 128  # the ring's hole is now a grey part of the object
    label = (np.abs(x - 30) < 12) & (np.abs(y) < 20)
    pixels[label] = 255
    silhouette, raw = objectbox.foreground_mask(pixels, objectbox.plain_colour(pixels))
    assert label.sum() > 0.002 * label.size and raw[label].mean() < 0.2  # raw: a hole
    assert silhouette[label].all()


def test_foreground_mask_stays_in_the_region():
    pixels, truth = _ring_object(255)
    region = np.zeros_like(truth)
    region[:, :80] = True
    mask, _ = objectbox.foreground_mask(pixels, objectbox.plain_colour(pixels), region)
    assert not mask[:, 82:].any() and mask[:, :78].sum() > 0.9 * truth[:, :78].sum()


def test_a_busy_background_gets_no_masks():
    kermit = [np.asarray(Image.open(p)) for p in sorted(KERMIT.glob("*.jpg"))[:3]]
    assert objectbox.plain_colour(kermit[0]) is None
    assert objectbox.background_colour(kermit) is None


def test_a_photo_too_dark_for_anything_to_stand_out_has_no_plain_background():
    """kermit's busy desk at a quarter of its light: the border is plain (every pixel near
    black), but nothing stands out from it, so it is no backdrop to cut the object from (its
    masks came out empty, and a right capture was refused for its outlines); a dark object on a
    black cloth still is."""
    rng = np.random.default_rng(0)
    photo = np.asarray(Image.open(KERMIT / "kermit000.jpg")).astype(np.float32)
    dark = np.clip(0.25 * photo + rng.normal(0, 4, photo.shape), 0, 255).astype(np.uint8)
    band = max(1, round(objectbox.BORDER * min(dark.shape[:2])))
    border = np.concatenate([dark[:band].reshape(-1, 3), dark[-band:].reshape(-1, 3)])
    assert np.mean(np.abs(border - np.median(border, 0)).max(-1) <= objectbox.PLAIN_SPREAD) > 0.9
    assert objectbox.plain_colour(dark) is None
    pixels, _ = _ring_object(0)
    assert objectbox.plain_colour((pixels * 0.6).astype(np.uint8)) is not None


def test_umeyama_recovers_a_similarity():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(20, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot = q * np.sign(np.linalg.det(q))
    dst = 2.5 * src @ rot.T + np.array([1.0, -2.0, 0.5])
    scale, r, t = umeyama(src, dst)
    assert scale == pytest.approx(2.5)
    np.testing.assert_allclose(r, rot, atol=1e-9)
    np.testing.assert_allclose(t, [1.0, -2.0, 0.5], atol=1e-9)


def test_rotation_between_reads_the_world_turn_from_the_cameras_alone():
    # six cameras on a 60-degree arc, every one turned by 2 degrees of its own on top of the
    # world's turn: the turn comes back within those degrees, whatever the centres do
    rng = np.random.default_rng(3)
    world = _rot_x(70.0) @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    truth = np.stack([c.c2w[:3, :3] for c in _ring(n=36)[:6]])
    noisy = np.stack([r @ _rot_x(2.0 * rng.choice([-1, 1])) for r in truth])
    found = rotation_between(noisy, world @ truth)
    assert rotation_angle(found.T @ world) < 2.0
    np.testing.assert_allclose(rotation_between(truth, world @ truth), world, atol=1e-9)


def test_pose_errors_see_only_real_differences():
    cams = _ring(n=8)
    reference = {f"v{i}": c.c2w for i, c in enumerate(cams)}
    world = np.eye(4)
    world[:3, :3] = 0.3 * np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])  # rotate and shrink ...
    world[:3, 3] = [5.0, 1.0, -2.0]  # ... and move the whole world: no error
    estimated = {k: c.transformed(world).c2w for k, c in zip(reference, cams)}
    errors = pose_errors(estimated, reference)
    assert errors.rotation_deg.max() < 1e-6 and errors.centre_share.max() < 1e-9
    assert errors.radius == pytest.approx(4.0)
    tilted = dict(estimated)
    tilted["v3"] = estimated["v3"].copy()
    tilted["v3"][:3, :3] = estimated["v3"][:3, :3] @ _rot_x(3.0)  # one camera turned 3 degrees
    assert pose_errors(tilted, reference).rotation_deg[3] == pytest.approx(3.0, abs=1e-6)
    assert rotation_angle(_rot_x(30.0)) == pytest.approx(30.0)


def _rot_x(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
