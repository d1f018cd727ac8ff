"""Rendered product captures: the cameras written are the ones rendered with, the doppelganger's
opposite sides carry one print, and turned photos move as K R K^-1 predicts."""

import json
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from windowshop.rays import project
from windowshop.scene import read_source
from windowshop.scene.cameras import box_corners, look_at
from windowshop.scene.products import (BOX_SIZE, _rot_z, box_cameras, carton, doppelganger_box,
                                       figure_on_granite, granite_cameras, homography,
                                       render_carton, turn_rotation, turned, write_capture)
from windowshop.scene.types import Camera

SIZE = (160, 120)
COUNT = 6
BOX = np.array([[-BOX_SIZE[0] / 2, -BOX_SIZE[1] / 2, 0.0], [BOX_SIZE[0] / 2, BOX_SIZE[1] / 2, BOX_SIZE[2]]])


@pytest.fixture(scope="module")
def box_dir(tmp_path_factory):
    return doppelganger_box(tmp_path_factory.mktemp("box") / "out", count=COUNT, size=SIZE, seed=0)


@pytest.fixture(scope="module")
def granite_dir(tmp_path_factory):
    return figure_on_granite(tmp_path_factory.mktemp("granite") / "out", count=4, size=SIZE, seed=0)


def _read(path) -> np.ndarray:
    return np.asarray(Image.open(path))


def test_written_cameras_read_back_as_rendered(box_dir, granite_dir):
    for folder, cams in ((box_dir, box_cameras(COUNT, SIZE, 0)), (granite_dir, granite_cameras(4, SIZE, 0))):
        source = read_source(folder)
        assert source.format == "nerfstudio" and len(source.frames) == len(cams)
        for frame, cam in zip(source.frames, cams):
            assert (frame.camera.fx, frame.camera.cx, frame.camera.width) == (cam.fx, cam.cx, cam.width)
            np.testing.assert_allclose(frame.camera.c2w, cam.c2w, atol=1e-9)
            assert frame.mask_path is not None and frame.mask_path.is_file()
            assert frame.image_path.parent.name == "images"


def test_box_corners_project_onto_the_mask_and_image_edges(box_dir):
    frames = read_source(box_dir).frames
    corners = box_corners(BOX)
    for frame in frames[:3]:
        uv, depth = project(corners, frame.camera)
        assert np.all(depth > 0)
        mask = _read(frame.mask_path) > 127
        image = _read(frame.image_path).astype(int)
        rows, cols = np.nonzero(mask)
        # the silhouette of a convex box is the hull of its corners: same extent
        expected = [uv[:, 0].min(), uv[:, 0].max(), uv[:, 1].min(), uv[:, 1].max()]
        got = [cols.min(), cols.max() + 1, rows.min(), rows.max() + 1]
        np.testing.assert_allclose(got, expected, atol=1.0)
        inked = (255 - image.min(-1)) > 40
        rows, cols = np.nonzero(inked)
        np.testing.assert_allclose([cols.min(), cols.max() + 1, rows.min(), rows.max() + 1],
                                   expected, atol=1.5)
        # the lowest corner: object just inside it, white just below it
        u, v = uv[np.argmax(uv[:, 1])]
        assert mask[int(v) - 2, int(u)] and not mask[int(v) + 2, int(u)]
        assert image[int(v) + 2, int(u)].min() > 245


def test_mask_matches_the_non_white_pixels(box_dir):
    for frame in read_source(box_dir).frames:
        mask = _read(frame.mask_path) > 127
        inked = (255 - _read(frame.image_path).astype(int).min(-1)) > 40
        iou = (mask & inked).sum() / (mask | inked).sum()
        assert iou > 0.95, (frame.image_path.name, iou)


def test_front_and_back_carry_one_print_and_left_and_right_another():
    box = carton(0)
    names = sorted(set(box.face_side))
    target = np.array([0.0, 0.0, BOX_SIZE[2] / 2])
    eye = target + np.array([1.2, -3.0, 1.4])
    cam = Camera(fx=150, fy=150, cx=80, cy=60, width=160, height=120,
                 c2w=look_at(eye, target, np.array([0.0, 0.0, 1.0])))
    half_turn = np.eye(4)
    half_turn[:3, :3] = _rot_z(180)  # the camera carried half way round the box
    opposite = replace(cam, c2w=half_turn @ cam.c2w)
    a, _, side_a = render_carton(box, cam, shaded=False)
    b, _, side_b = render_carton(box, opposite, shaded=False)
    seen = {names[s] for s in np.unique(side_a) if s >= 0}
    assert seen == {"front", "right", "top"}
    swap = {"front": "back", "right": "left", "top": "top"}
    assert np.array_equal(np.vectorize(lambda s: names.index(swap[names[s]]) if s >= 0 else -1)(side_a), side_b)
    np.testing.assert_allclose(a, b, atol=1e-4)  # the same pixels from the opposite side
    sa, _, _ = render_carton(box, cam)
    sb, _, _ = render_carton(box, opposite)
    assert np.abs(sa - sb).mean() > 0.01  # but lit differently
    for tile in (box.atlas[4:-4, 4:424], box.atlas[4:-4, 432:432 + 280]):  # each print not symmetric
        assert np.abs(tile.astype(int) - tile[:, ::-1]).mean() > 20
        assert np.abs(tile.astype(int) - tile[::-1]).mean() > 20


def test_granite_mask_is_the_figure_and_the_table_is_textured(granite_dir):
    for frame in read_source(granite_dir).frames:
        mask = _read(frame.mask_path) > 127
        image = _read(frame.image_path).astype(float)
        assert 0.03 < mask.mean() < 0.4
        assert mask[60, 80]  # the figure in the middle
        table = image[-30:][~mask[-30:]]
        assert table.std() > 25  # speckled table at the bottom edge
        figure = image[mask]
        assert figure[:, 0].mean() > figure[:, 2].mean() or figure[:, 2].mean() > figure[:, 0].mean()


def test_same_seed_same_bytes(tmp_path):
    a = doppelganger_box(tmp_path / "a", count=2, size=(64, 48), seed=3)
    b = doppelganger_box(tmp_path / "b", count=2, size=(64, 48), seed=3)
    c = doppelganger_box(tmp_path / "c", count=2, size=(64, 48), seed=4)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert len(files) == 5
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    assert (a / "images/box_000.jpg").read_bytes() != (c / "images/box_000.jpg").read_bytes()


def _source(tmp_path, pixels: np.ndarray, c2w: np.ndarray):
    h, w = pixels.shape[:2]
    cam = Camera(fx=140.0, fy=140.0, cx=78.0, cy=61.0, width=w, height=h, c2w=c2w)
    mask = pixels.max(-1) > 0
    return write_capture(tmp_path / "src", [cam], [pixels], [mask], ["p0"]), cam


def _centroid(image: np.ndarray) -> np.ndarray:
    weight = image.astype(float).sum(-1)
    j, i = np.nonzero(weight > 0)
    w = weight[j, i]
    return np.array([(i + 0.5) @ w / w.sum(), (j + 0.5) @ w / w.sum()])


def test_turned_point_lands_where_the_homography_says(tmp_path):
    pixels = np.zeros((120, 160, 3), np.uint8)
    pixels[38:43, 108:113] = 255  # a dot centred at pixel (110.5, 40.5)
    c2w = look_at(np.array([0.0, -3.0, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    src, cam = _source(tmp_path, pixels, c2w)
    out = turned(src, tmp_path / "out", rolls_deg=[25.0], pitch_deg=8.0)
    image = np.asarray(Image.open(out / "images" / "p0.jpg"))
    image = np.where(image > 60, image, 0)
    h = homography(cam, 25.0, 8.0)
    p = h @ np.array([110.5, 40.5, 1.0])
    np.testing.assert_allclose(_centroid(image), p[:2] / p[2], atol=0.6)
    assert np.linalg.norm(p[:2] / p[2] - [110.5, 40.5]) > 10  # it did move
    mask = np.asarray(Image.open(out / "masks" / "p0.png")) > 127
    np.testing.assert_allclose(_centroid(mask[..., None]), p[:2] / p[2], atol=0.8)
    frame = read_source(out).frames[0]
    np.testing.assert_allclose(frame.camera.c2w[:3, :3], c2w[:3, :3] @ turn_rotation(25.0, 8.0), atol=1e-12)
    np.testing.assert_allclose(frame.camera.c2w[:3, 3], c2w[:3, 3])
    # the turned camera sees a world point where the warped dot is
    ray_src = np.linalg.inv(cam.K) @ np.array([110.5, 40.5, 1.0])
    world = c2w[:3, :3] @ (np.diag([1.0, -1.0, -1.0]) @ ray_src) * 2.0 + c2w[:3, 3]
    uv, _ = project(world[None], frame.camera)
    np.testing.assert_allclose(uv[0], p[:2] / p[2], atol=1e-6)


def test_quarter_roll_turns_a_landscape_layout_and_gravity(tmp_path):
    pixels = np.zeros((120, 160, 3), np.uint8)
    pixels[:, :80, 0] = 255  # red left half
    pixels[:, 80:, 2] = 255  # blue right half
    c2w = look_at(np.array([0.0, -3.0, 0.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    src, _ = _source(tmp_path, pixels, c2w)
    out = turned(src, tmp_path / "out", rolls_deg=90.0, up=np.array([0.0, 0.0, 1.0]))
    image = np.asarray(Image.open(out / "images" / "p0.jpg")).astype(int)
    # the camera turned a quarter counter-clockwise: what was left is now at the top
    assert image[5:50, 60:100, 0].mean() > 200 and image[5:50, 60:100, 2].mean() < 50
    assert image[-50:-5, 60:100, 2].mean() > 200 and image[-50:-5, 60:100, 0].mean() < 50
    assert image[:, :5].max() < 40  # beyond the source's view: black
    meta = json.loads((out / "transforms.json").read_text())
    np.testing.assert_allclose(meta["frames"][0]["gravity"], [-1.0, 0.0, 0.0], atol=1e-9)
    level = turned(src, tmp_path / "level", rolls_deg=0.0, up=np.array([0.0, 0.0, 1.0]))
    meta0 = json.loads((level / "transforms.json").read_text())
    np.testing.assert_allclose(meta0["frames"][0]["gravity"], [0.0, -1.0, 0.0], atol=1e-9)


def test_gravity_turns_with_the_camera(box_dir, tmp_path):
    rolls = [0.0, 30.0, -90.0, 180.0, 10.0, 45.0]
    out = turned(box_dir, tmp_path / "t", rolls_deg=rolls, pitch_deg=20.0)
    src = json.loads((box_dir / "transforms.json").read_text())["frames"]
    meta = json.loads((out / "transforms.json").read_text())
    for roll, frame, before in zip(rolls, meta["frames"], src):
        c2w = np.array(frame["transform_matrix"])
        gravity = np.array(frame["gravity"])
        np.testing.assert_allclose(c2w[:3, :3] @ gravity, [0.0, 0.0, -1.0], atol=0.03)  # level ring
        old = np.array(before["transform_matrix"])[:3, :3].T @ c2w[:3, :3] @ gravity
        np.testing.assert_allclose(turn_rotation(roll, 20.0) @ gravity, old, atol=1e-9)
        assert frame["roll_deg"] == roll
