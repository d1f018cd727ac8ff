"""A backdrop that stays still (windowshop.photos.still): the object turned in front of a phone
that did not move, told from a walk round by the raw matches, and its backdrop told from the
object by what every photo shows at a pixel."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np
import pycolmap
import pytest
from PIL import Image

from windowshop.config import PrepareOptions
from windowshop.errors import UserError
from windowshop.photos import align, still
from windowshop.photos.prepare import prepare
from windowshop.photos.report import summary_lines
from windowshop.scene import products

from shared_data import DATA

SKULL = DATA / "dtu_skull"
ROOM = DATA / "kermit" / "kermit000.jpg"
TILES = DATA / "beer_can" / "images" / "0030.jpg"
needs_data = pytest.mark.skipif(
    not (SKULL / "cameras_sphere.npz").is_file() or not ROOM.is_file() or not TILES.is_file(),
    reason="needs dtu_skull, kermit and beer_can")


def _turning_over_texture(count: int, rng: np.random.Generator, nudge: int = 0):
    """`count` photos (120, 160, 3) uint8 of a textured object turning in front of one textured
    backdrop (an ellipse whose width and face change from photo to photo, with a plain grey hub
    that stays put, as a round part of an object does), each photo at its own exposure
    (0.8-1.2), the backdrop shifted by up to `nudge` px either way (a nudged phone), and the
    object's (120, 160) bool per photo, and each photo's move (2,) against the first."""
    backdrop = rng.uniform(40, 200, (120 + 2 * nudge, 160 + 2 * nudge, 3))
    face = rng.uniform(40, 200, (120, 160, 3))
    rows, cols = np.mgrid[:120, :160]
    photos, objects, offsets = [], [], []
    for k in range(count):
        width = 20 + 20 * abs(np.sin(np.pi * k / count))
        inside = ((cols - 80) / width) ** 2 + ((rows - 60) / 40) ** 2 < 1
        turned = np.roll(face, 7 * k, axis=1)  # the object turns: another face each photo
        turned[np.hypot(rows - 60, cols - 80) < 12] = 120.0
        dx, dy = rng.integers(0, 2 * nudge + 1, 2)
        behind = backdrop[dy:dy + 120, dx:dx + 160]
        pixels = np.where(inside[..., None], turned, behind) * rng.uniform(0.8, 1.2)
        photos.append(np.clip(pixels, 0, 255).astype(np.uint8))
        objects.append(inside)
        offsets.append(np.array([dx, dy], float))
    return photos, objects, [offsets[0] - o for o in offsets]


@pytest.mark.parametrize("nudge", [0, 3])
def test_the_backdrop_is_what_stays_put_whatever_each_photos_exposure(nudge):
    photos, objects, moved = _turning_over_texture(8, np.random.default_rng(0), nudge)
    shown, stands = still.backdrop(photos, moved)
    assert len(shown) == len(stands) == len(photos)
    # where most photos show the backdrop, the median is the backdrop's (but at the edges a
    # nudged photo shows what the others do not)
    margin = np.zeros((120, 160), bool)
    margin[2 * nudge:120 - 2 * nudge, 2 * nudge:160 - 2 * nudge] = True
    mostly_behind = (np.mean(objects, axis=0) < 0.5) & margin
    for backdrop, out, inside in zip(shown, stands, objects):
        assert backdrop.shape == out.shape == inside.shape
        assert backdrop[~inside & mostly_behind].mean() >= 0.95  # however bright the photo
        assert backdrop[inside].mean() <= 0.05  # the object is not taken for it
        assert out[~inside].mean() <= 0.01  # nor does the backdrop stand out from itself


def _dark_object_and_its_shadow(count: int, rng: np.random.Generator):
    """`count` photos (120, 160, 3) uint8 of a black object (a disk that moves about as it
    turns, as a dark side does) over a dim textured backdrop, the backdrop beside it darkened
    to half (the shadow it casts, keeping the backdrop's colour), and the object's and the
    shadow's (120, 160) bool per photo."""
    backdrop = rng.uniform(60, 160, (120, 160, 3))
    rows, cols = np.mgrid[:120, :160]
    photos, objects, shadows = [], [], []
    for k in range(count):
        centre = 40 + 80 * k / (count - 1)
        inside = np.hypot(rows - 60, cols - centre) < 18
        shadow = (np.abs(rows - 90) < 6) & (np.abs(cols - centre - 25) < 15)
        pixels = np.where(inside[..., None], 4.0, backdrop * np.where(shadow, 0.5, 1.0)[..., None])
        photos.append(np.clip(pixels + rng.normal(0, 1, pixels.shape), 0, 255).astype(np.uint8))
        objects.append(inside)
        shadows.append(shadow)
    return photos, objects, shadows


def test_a_dark_side_stands_out_from_a_still_backdrop_and_a_shadow_does_not(monkeypatch):
    """Colour alone cannot tell a black side from a dim room (GrabCut gave the skull's dark
    side to kermit's room: masks IoU 0.47 at worst); a still backdrop can, where most photos
    agree on it. A shadow is the backdrop darker, its colour kept: not the object."""
    photos, objects, shadows = _dark_object_and_its_shadow(9, np.random.default_rng(2))
    _, stands = still.backdrop(photos)
    for out, inside, shadow in zip(stands, objects, shadows):
        assert out[inside].mean() >= 0.9
        assert out[~inside].mean() <= 0.01 and not out[shadow].any()
    monkeypatch.setattr(still, "SHADOW", 1.0)  # every darkening taken for the object
    _, stands = still.backdrop(photos)
    assert np.mean([out[shadow].mean() for out, shadow in zip(stands, shadows)]) >= 0.9


def test_no_backdrop_from_photos_of_two_sizes_or_too_few():
    photos, _, _ = _turning_over_texture(8, np.random.default_rng(1))
    assert still.backdrop(photos[:still.MIN_PHOTOS - 1]) is None
    assert still.backdrop(photos[:-1] + [photos[-1][:100]]) is None


def _matched(folder, tmp_path) -> tuple[bool, bool]:
    """(still.fixed_camera, still.hand_held) on the photos in `folder`, matched every pair with
    pycolmap."""
    database = tmp_path / f"{folder.parent.name}_{folder.name}.db"
    pycolmap.extract_features(database, folder, device=pycolmap.Device.cpu)
    pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
    return still.fixed_camera(database), still.hand_held(database)


@needs_data
def test_a_still_phone_is_told_from_a_held_one_and_from_a_walk_round_by_its_raw_matches(
        tmp_path):
    frames = products.dtu_frames(SKULL)[::8]
    products.on_turntable(frames, ROOM, tmp_path / "turntable")
    # the room moved by up to 20 px either way in each photo: a phone held in the hand
    products.on_turntable(frames, ROOM, tmp_path / "held", nudge_px=20)
    walk = tmp_path / "walk"
    walk.mkdir()
    for frame in frames:  # the same cameras, the room really behind the skull
        Image.open(frame.image_path).save(walk / frame.image_path.name)
    assert _matched(tmp_path / "turntable" / "images", tmp_path) == (True, False)
    assert _matched(tmp_path / "held" / "images", tmp_path) == (False, True)
    assert _matched(walk, tmp_path) == (False, False)


def _nudges(count: int, nudge: int, seed: int = 0) -> list[np.ndarray]:
    """The (dx, dy) by which products.on_turntable shifted the room in each of `count` photos."""
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 2 * nudge + 1, 2).astype(float) for _ in range(count)]


@needs_data
def test_a_held_phones_photos_are_moved_back_by_their_rooms_known_shift(tmp_path):
    """Photo i shows the room's point at its pixel p + d_i (d_i its shift), so its pixel p is
    the reference's p + d_i - d_ref: the homography steadying finds must say so."""
    frames = products.dtu_frames(SKULL)[::8]
    products.on_turntable(frames, ROOM, tmp_path / "held", nudge_px=20)
    folder = tmp_path / "held" / "images"
    database = tmp_path / "held.db"
    pycolmap.extract_features(database, folder, device=pycolmap.Device.cpu)
    pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
    names = sorted(p.name for p in folder.iterdir())
    steadying = still.steadying(database)
    assert steadying is not None and set(steadying.moves) == set(names)
    moves = steadying.moves
    reference = [n for n, h in moves.items() if np.allclose(h, np.eye(3))]
    assert len(reference) == 1
    shift = dict(zip(names, _nudges(len(names), 20)))
    width, height = Image.open(folder / names[0]).size
    points = np.float32([[width / 2, height / 2], [60, 60], [width - 60, height - 60]])
    for name, homography in moves.items():
        moved = cv2.perspectiveTransform(points.reshape(-1, 1, 2), homography).reshape(-1, 2)
        expected = points + shift[name] - shift[reference[0]]
        assert np.abs(moved - expected).max() < 1.5, (name, moved - expected)


def _jerked(path: Path, dx: int) -> None:
    """The photo at `path` moved `dx` px across, whole (the phone swung further for it)."""
    image = np.asarray(Image.open(path).convert("RGB"))
    moved = cv2.warpAffine(image, np.float32([[1, 0, dx], [0, 1, 0]]), image.shape[1::-1],
                           borderMode=cv2.BORDER_REFLECT)
    Image.fromarray(moved).save(path, quality=95)


@needs_data
def test_a_photo_the_phone_swung_too_far_for_is_left_out_of_the_steadying(tmp_path):
    """One of 7 held photos moved 110 px more (14% of its width: past a wobble against any
    other): the other six are still steadied onto one another, and that one is left out."""
    products.on_turntable(products.dtu_frames(SKULL)[::8], ROOM, tmp_path / "held", nudge_px=20)
    folder = tmp_path / "held" / "images"
    names = sorted(p.name for p in folder.iterdir())
    _jerked(folder / names[3], 110)
    database = tmp_path / "held.db"
    pycolmap.extract_features(database, folder, device=pycolmap.Device.cpu)
    pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
    steadying = still.steadying(database)
    assert steadying is not None and set(steadying.moves) == set(names) - {names[3]}
    left, top, right, bottom = steadying.box
    assert 0 < left <= 40 and 0 < top <= 40  # cut by the others' shifts only


def test_steadied_photos_keep_what_all_of_them_show_about_their_centre():
    image = np.random.default_rng(0).integers(0, 255, (80, 100, 3), dtype=np.uint8)
    def moving(dx, dy):
        return np.array([[1.0, 0, dx], [0, 1, dy], [0, 0, 1]])
    moves = {"a": np.eye(3), "b": moving(5, -3), "c": moving(-8, 2)}
    box = still.steady_box(moves, (100, 80))
    assert box == (8, 3, 92, 77)  # the widest cut on either side, from both sides
    shown = still.steadied(image, moves["b"], box)
    assert shown.shape == (74, 84, 3)
    # b's pixel (x, y) lands at (x + 5, y - 3): the cut's (0, 0) is b's (8 - 5, 3 + 3)
    assert np.array_equal(shown, image[6:80, 3:87])
    assert np.array_equal(still.steadied(image, moves["a"], box), image[3:77, 8:92])
    # moved further than MIN_KEPT allows: not steadied
    assert still.steady_box({"a": np.eye(3), "b": moving(11, 0)}, (100, 80)) is None


def _scene_ious(scene, frames, steadied=None) -> list[float]:
    """Mask IoU of each of the `scene`'s photos against the hand-made mask of its frame of
    `frames`, moved and cut as report.json's `steadied` says when given."""
    report = json.loads((scene / "report.json").read_text())
    stems = {v["name"]: v["photo"].rsplit("/", 1)[-1].rsplit(".", 1)[0] for v in report["views"]}
    truth = {f.image_path.stem: f.mask_path for f in frames}
    ious = []
    for mask in (scene / "masks").glob("*.png"):
        ours = np.asarray(Image.open(mask)) > 127
        hand = np.asarray(Image.open(truth[stems[mask.stem]]).convert("L"))
        if steadied is not None:  # at the photos' size (the box is cut evenly from both sides)
            left, top, right, bottom = steadied["box"]
            hand = np.asarray(Image.fromarray(hand).resize((left + right, top + bottom)))
            hand = still.steadied(hand, np.array(steadied["moves"][mask.stem]), steadied["box"])
        hand = np.asarray(Image.fromarray(hand).resize(ours.shape[::-1])) > 127
        ious.append((ours & hand).sum() / (ours | hand).sum())
    return ious


@needs_data
def test_a_turntable_shot_with_the_phone_in_hand_is_steadied_and_delivered(tmp_path):
    """The room moved by up to 20 px in each of 13 photos: its matches are neither the object's
    nor stationary, held every photo at one spot, and the capture was refused. Each photo is
    now moved so that the room stays still, cut to what all show, and posed and masked as a
    propped phone's photos are. One photo the phone swung 110 px further for (past a wobble
    from any other) is left out and named, with what to do, where before it kept the others
    from being steadied and the capture was refused ("no object found")."""
    frames = products.dtu_frames(SKULL)[::4]
    products.on_turntable(frames, ROOM, tmp_path / "capture", nudge_px=20)
    _jerked(tmp_path / "capture" / "images" / "024.jpg", 110)
    result = prepare(tmp_path / "capture" / "images", tmp_path / "scene", PrepareOptions(),
                     show=False)
    steadied = result.report["steadied"]
    assert steadied is not None and result.report["masks"] == "still"
    assert steadied["left_out"] == ["024"] and "024.jpg" in result.report["unplaced"]
    assert result.report["reshoot"]["024.jpg"].startswith("the phone moved too far for it")
    assert any("held in the hand" in line for line in summary_lines(result.report))
    left, top, right, bottom = steadied["box"]
    assert 0 < left <= 40 and 0 < top <= 40  # cut by the room's widest shift, at most 2 x 20
    scene = json.loads((tmp_path / "scene" / "transforms.json").read_text())
    assert (scene["w"], scene["h"]) == (right - left, bottom - top)
    truth = json.loads((tmp_path / "capture" / "transforms.json").read_text())
    stems = {v["name"]: Path(v["photo"]).stem for v in result.report["views"]}
    true_c2w = {Path(f["file_path"]).stem: np.array(f["transform_matrix"]) for f in truth["frames"]}
    ours = {stems[Path(f["file_path"]).stem]: np.array(f["transform_matrix"])
            for f in scene["frames"]}
    errors = align.pose_errors(ours, true_c2w).rotation_deg
    assert len(errors) >= len(frames) - 2 and np.median(errors) <= 3.0, errors
    ious = _scene_ious(tmp_path / "scene", frames, steadied)
    assert len(ious) >= len(frames) - 2
    assert np.mean(ious) >= 0.9 and min(ious) >= 0.75, ious


@needs_data
def test_a_held_phones_photos_are_cut_from_their_steadied_backdrop_however_few_its_matches(
        tmp_path):
    """The skull over beer_can's tiles, 16 photos, the floor shifted by up to 20 px in each:
    once steadied, the floor stands still, but its few matches are outnumbered by the skull's,
    so the matches alone did not say the phone stood still, and the masks were cut without the
    backdrop (IoU 0.736 on average, 0.322 at worst; 0.773 and 0.458 with it)."""
    frames = products.dtu_frames(SKULL)
    frames = [frames[i] for i in np.linspace(0, len(frames) - 1, 16).round().astype(int)]
    products.on_turntable(frames, TILES, tmp_path / "capture", nudge_px=20)
    result = prepare(tmp_path / "capture" / "images", tmp_path / "scene", PrepareOptions(),
                     show=False)
    steadied = result.report["steadied"]
    assert steadied is not None and result.report["masks"] == "still"
    ious = _scene_ious(tmp_path / "scene", frames, steadied)
    assert len(ious) >= len(frames) - 2
    assert np.mean(ious) >= 0.75 and min(ious) >= 0.4, ious


@needs_data
def test_a_held_phones_turntable_that_steadying_cannot_save_is_refused_with_what_to_do(tmp_path):
    """5 photos 10 frames apart, the phone held: steadied, 3 are placed; the refusal asks for
    the phone to be propped up and the object turned in smaller steps, not only for a walk
    round, and leaves no scene."""
    products.on_turntable(products.dtu_frames(SKULL)[::10], ROOM, tmp_path / "capture",
                          nudge_px=20)
    with pytest.raises(UserError, match="prop the phone up") as refused:
        prepare(tmp_path / "capture" / "images", tmp_path / "scene", PrepareOptions(),
                show=False)
    assert "turn the object in smaller steps" in str(refused.value)
    assert not (tmp_path / "scene" / "transforms.json").exists()


@needs_data
@pytest.mark.parametrize("nudge", [0, 3])
def test_a_turntable_capture_is_cut_from_its_still_backdrop(tmp_path, nudge):
    """dtu_skull's skull over one photo of a room, 13 photos: the room stays put behind a skull
    that turns. Without the still backdrop, GrabCut took the room's parts beside the skull for
    it: masks IoU 0.82 against the hand-made ones on average, 0.71 at worst (0.95 and 0.84
    with it). With the room shifted by up to 3 px in each photo (a propped phone nudged by the
    tap on its shutter), COLMAP's stationary filter (4 px) kept the room's matches and only 2
    photos were placed; verified again past the nudge, and each photo moved back by its
    backdrop's matches, 0.97 and 0.95."""
    frames = products.dtu_frames(SKULL)[::4]
    products.on_turntable(frames, ROOM, tmp_path / "capture", nudge_px=nudge)
    result = prepare(tmp_path / "capture" / "images", tmp_path / "scene", PrepareOptions(),
                     show=False)
    assert result.report["masks"] == "still"
    steadied = result.report["steadied"]
    assert (steadied is None) == (nudge == 0)  # a nudged phone's photos are steadied too
    ious = _scene_ious(tmp_path / "scene", frames, steadied)
    assert len(ious) >= len(frames) - 2
    assert np.mean(ious) >= 0.9 and min(ious) >= 0.75, ious


@needs_data
def test_a_turntables_dark_side_is_told_from_a_dim_room_by_the_still_backdrop(tmp_path):
    """16 photos spread over dtu_skull's, the skull over the room: its dark side is as dark as
    the room's shadows, so GrabCut gave it to the room (masks IoU 0.793 on average, 0.465 at
    worst). Where most photos show the room, the skull stands out from it, and is kept whatever
    its colour: 0.846 and 0.664."""
    frames = products.dtu_frames(SKULL)
    frames = [frames[i] for i in np.linspace(0, len(frames) - 1, 16).round().astype(int)]
    products.on_turntable(frames, ROOM, tmp_path / "capture")
    result = prepare(tmp_path / "capture" / "images", tmp_path / "scene", PrepareOptions(),
                     show=False)
    assert result.report["masks"] == "still"
    ious = _scene_ious(tmp_path / "scene", frames)
    assert len(ious) >= len(frames) - 2
    assert np.mean(ious) >= 0.82 and min(ious) >= 0.6, ious


@pytest.mark.skipif(not (DATA / "beer_can" / "Beer.mp4").is_file(), reason="needs beer_can")
def test_a_walks_neighbouring_video_frames_are_not_steadied(tmp_path):
    """Every third frame of the first two seconds of a walk round the can: each frame is a
    wobble away from the next, as a hand-held turntable's photos are (hand_held says yes), but
    the moves add up past what a hand does, so they are mapped as they are, not steadied."""
    folder = tmp_path / "frames"
    folder.mkdir()
    with imageio.get_reader(DATA / "beer_can" / "Beer.mp4") as video:
        for k, frame in enumerate(video):
            if k >= 60:
                break
            if k % 3 == 0:
                Image.fromarray(frame).resize((360, 640)).save(folder / f"{k:03d}.jpg")
    database = tmp_path / "walk.db"
    pycolmap.extract_features(database, folder, device=pycolmap.Device.cpu)
    pycolmap.match_sequential(database, device=pycolmap.Device.cpu)
    assert still.hand_held(database)
    assert still.steadying(database) is None
