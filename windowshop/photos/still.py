"""A backdrop that stays still: the object turned in front of a phone that does not move (on a
turntable or a lazy Susan, or turned by hand between shots).

Structure from motion places such photos right. COLMAP's verification drops the matches that
stay at one pixel (`filter_stationary_matches`), so only the object's matches place the cameras,
as if the phone had walked round it. But the room behind, the same in every photo, then holds no
sparse point, and GrabCut, seeded by the points, takes the parts of it beside the object for the
object: dtu_skull's skull composited over one photo of a room (the photos of a turntable) gave
masks of IoU 0.71 against the hand-made ones, and the room's toy came out baked into the skull's
side.

The photos say so themselves. Where the phone stood still, nearly every raw match of a pair stays
within a few pixels (STILL_SHARE), and a photo's backdrop is where it shows what most photos show
at that pixel (the photos' per-pixel median, each photo first moved onto the first by the median
move of the backdrop's matches, and their exposures evened) and that has texture: a turning
object moves its texture, while a plain part of it can match the median as a plain wall does.
Those pixels start GrabCut as probable background (windowshop.photos.segment): a part of the
object that matches the median all the same (the rim of a round mug keeps its place as it
turns) is given back by its colour. The other way round, where most photos agree with the median
(so that it is the backdrop there), a photo that stands out from it shows the object, however
alike their colours: a dark side against a dim room, which GrabCut's colours gave to the room.
Those pixels start GrabCut as sure object, but for a shadow (the backdrop darker, its colour
kept).

A phone propped up moves a few pixels when its shutter is tapped, and one held in the hand
while the object turns moves further (a hand's wobble of a degree or two is 10-30 px). Its
backdrop's matches then move past COLMAP's stationary 4 px, are kept, hold every photo at about
one spot, and the object is not found. `hand_held` tells such photos by their backdrop (a
share of the median pair's raw matches, WOBBLE_SHARE, fits one homography that moves the photo
by little, HELD_SHARE, and they do not stay within STILL_PX), and `steadying` gives each photo
the homography that moves it onto the photo most tied to the others. Prepare moves the photos so, cuts them to what
all of them show (steady_box), and poses them again as a still phone's (windowshop.photos.
prepare); what the homographies leave (a pixel or two) is taken as stationary by verifying the
pairs again with STATIONARY_PX as the bound (windowshop.photos.sfm.match). Verifying the pairs so
without moving the photos did for a shift of up to 3 px, not beyond: the room shifted by up to
10 px, or turned by up to a degree, still held every photo at one spot.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pycolmap

MIN_MATCHES = 15  # a pair with fewer raw matches says nothing about the phone's motion
# A raw match that moves less than this stays put: a phone propped up moves a few pixels when
# its shutter is tapped (the room behind shifted by up to 3 px either way: 10 of 25 photos
# placed, refused after 84 s, with COLMAP's own 4 px; 24 of 25 in 24 s verified again with this)
STATIONARY_PX = 12.0
STILL_PX = 2.0  # ... and one that moves less than this stayed at its very pixel (a tripod)
# The phone stood still when the median pair has over this share of its raw matches stationary.
# SIFT at 640 px, exhaustive pairs of up to 20 photos: dtu_skull composited over one room photo
# 0.98, shifted by up to 3 px 0.97; every walk round 0.000 (kermit, fruit, beer_can, temple, the
# granite figure, the doppelganger carton; 20 neighbouring frames of beer_can's and of fruit's
# walks) but skull_up's 0.18 (DTU's close viewpoints), their 90th percentile pairs at most 0.45
STILL_SHARE = 0.5
# A homography moving no corner of the photo by more than this share of its longer side is a
# hand's wobble (a turn of 3 degrees at a phone's focal length), not a step of a walk round.
# Measured at 640 px on the pairs prepare matches, the share of each pair's raw matches that such
# a homography explains (RANSAC, 3 px): dtu_skull's photos over one room photo shifted by up to
# 20 px, median pair 0.96; every walk round 0.00 at the median (kermit, fruit's 20 neighbouring
# and 20 spread photos, beer_can's likewise, temple, dtu_skull, the granite figure, the
# doppelganger carton; their 90th percentile 0.00 but temple's 0.46), their median pair's
# corners moving 131-1670 px
HELD_SHARE = 0.08
# The phone moved while the object turned when the median pair's wobble share is over this:
# with few matches on its backdrop the object's own take a larger share (the skull over beer_can's
# tiles shifted by up to 20 px, 16 photos: median pair 0.44, 8 of them placed unsteadied, 16
# steadied), while every walk round's median pair is 0.000 (its best homography moves too far)
WOBBLE_SHARE = 0.3
# Pairs whose wobble is measured: the check runs on every capture (RANSAC on fruit's 319 pairs
# took 0.56 s), and the median of this many spread over them tells a hand-held capture
HELD_SAMPLE = 40
TOLERANCE = 0.05  # a pixel this close to the median (of full scale, every channel): backdrop
# ... where the median has texture: Sobel |dx| + |dy| of its grey (0-1), averaged over 5 x 5
# pixels, over this. dtu_skull turned over six backdrops (kermit's room, beer_can's tiles,
# fruit's paper towel), masks IoU against the hand-made ones: 0.920 on average against 0.913
# without it (0.808 with no backdrop at all), fruit's 0.862 -> 0.898; 0.07 the same, 0.1 and
# 0.2 worse on kermit's
TEXTURE = 0.05
WORK_SIDE = 320  # compared at this many pixels on the longer side
# Where over this share of the photos that see a pixel lie within TOLERANCE of their median, the
# median is the backdrop there, and a photo this far from it (of full scale, any channel) shows
# the object, which GrabCut then keeps whatever its colour (segment): the skull's dark side
# against kermit's dim room, which colour alone gave to the room. A share of 0.6 instead found a
# third fewer such pixels, and bench_isolation's masks scored 0.877 / 0.813 against 0.886 / 0.824
# (turntable / held, measured before the texture, shadow and opening rules below)
AGREED = 0.5
STANDS_OUT = 0.15
# ... unless it is the backdrop darkened by a factor between this and 1, its colour kept: a
# shadow the object casts. dtu_skull turned over kermit's room, beer_can's tiles and fruit's
# paper towel, 13 and 16 photos each: it sets aside 2-10% of the pixels that stand out, and the
# share of them that the hand-made masks hold rises from 94.4-99.0% to 97.9-99.9%
SHADOW = 0.3
# ... and only where this square (working pixels) fits inside what stands out: a few pixels of
# the room that stand out by chance grew, as sure object, into whole parts of it (kermit's
# room, 13 photos: masks IoU 0.948 -> 0.928 with a 3-pixel square). With 5 the share above is
# 99.75-99.93%, and no photo set's masks score under what they did before
STANDS_OPEN = 5
MIN_PHOTOS = 5  # fewer photos give no median to trust
MIN_KEPT = 0.8  # steadied photos that keep less of their width or height than this: not steadied


def _raw_pairs(database: Path):
    """(first image's name, second's, the first's (width, height), (N, 2) pixels in the first,
    (N, 2) pixels in the second) of every pair of MIN_MATCHES raw matches or more in the COLMAP
    `database`."""
    with pycolmap.Database.open(database) as db:
        cameras = {c.camera_id: (c.width, c.height) for c in db.read_all_cameras()}
        images = {im.image_id: (im.name, cameras[im.camera_id]) for im in db.read_all_images()}
        keypoints = {i: db.read_keypoints(i)[:, :2] for i in images}
        for pair_id, matches in zip(*db.read_all_matches()):
            if len(matches) >= MIN_MATCHES:
                first, second = pycolmap.pair_id_to_image_pair(pair_id)
                yield (images[first][0], images[second][0], images[first][1],
                       keypoints[first][matches[:, 0]], keypoints[second][matches[:, 1]])


def _stationary(database: Path, within: float) -> list[tuple[str, str, np.ndarray, float]]:
    """(image name, image name, median move (2,) of the raw matches that move less than
    `within` pixels from the first to the second image, their share of the pair's raw matches)
    for every pair of _raw_pairs."""
    out = []
    for first, second, _, here, there in _raw_pairs(database):
        moves = there - here
        kept = np.linalg.norm(moves, axis=1) < within
        median = np.median(moves[kept], axis=0) if kept.any() else np.zeros(2)
        out.append((first, second, median, float(kept.mean())))
    return out


def fixed_camera(database: Path, within: float = STATIONARY_PX) -> bool:
    """Whether the photos matched in the COLMAP `database` were taken from one place (module
    docstring), their backdrop moving by less than `within` pixels."""
    shares = [share for *_, share in _stationary(database, within)]
    return bool(shares) and float(np.median(shares)) > STILL_SHARE


def _wobble(here: np.ndarray, there: np.ndarray, size: tuple[int, int]
            ) -> tuple[np.ndarray | None, float]:
    """(the homography of the raw matches `here` -> `there` (N, 2), the share of them it
    explains) when it moves no corner of a photo of `size` (width, height) by more than
    HELD_SHARE of its longer side, else (None, 0)."""
    homography, inliers = cv2.findHomography(here, there, cv2.RANSAC, 3.0)
    if homography is None:
        return None, 0.0
    width, height = size
    corners = np.float32([[0, 0], [width, 0], [width, height], [0, height]]).reshape(-1, 1, 2)
    moved = np.abs(cv2.perspectiveTransform(corners, homography) - corners).max()
    if moved > HELD_SHARE * max(width, height):
        return None, 0.0
    return homography, float(inliers.mean())


def _wobbles(database: Path) -> list[float]:
    """For HELD_SAMPLE pairs of _raw_pairs spread over them (or all when fewer), the share of
    its raw matches that one homography moving no corner by more than HELD_SHARE explains (0
    when the pair's best homography moves further)."""
    pairs = list(_raw_pairs(database))
    return [_wobble(here, there, size)[1]
            for *_, size, here, there in pairs[::max(1, len(pairs) // HELD_SAMPLE)]]


def hand_held(database: Path) -> bool:
    """Whether the photos matched in the COLMAP `database` keep their backdrop nearly in place,
    as a phone held in the hand while the object turns does, without its staying at its very
    pixel (a tripod's, fixed_camera within STILL_PX): module docstring."""
    shares = _wobbles(database)
    return (bool(shares) and float(np.median(shares)) > WOBBLE_SHARE
            and not fixed_camera(database, STILL_PX))


@dataclass(frozen=True)
class Steadying:
    """How to steady a moving phone's photos (module docstring): the (3, 3) homography moving
    each one's pixels (by image name; a photo tied to no other has none) onto the reference
    photo's, and the part all of them show once moved, (left, top, right, bottom) pixels
    (steady_box)."""

    moves: dict[str, np.ndarray]
    box: tuple[int, int, int, int]


def steadying(database: Path) -> Steadying | None:
    """How to steady the photos matched in the COLMAP `database` so that their backdrop stays
    still, onto the photo most tied to the others; None when the photos tied to it are not most
    of them, or when the moves add up to more than a hand's wobble (steady_box: a walk's
    neighbouring frames are each a wobble apart, but not all of them). A pair is a tie when a
    wobble (_wobble) explains over STILL_SHARE of its raw matches, and each photo joins by the
    strongest tie it has to those already joined (a maximum spanning tree): a pair the object
    fills is a weaker tie than one of the room. A photo tied to none (the phone swung further
    for it, or it is blurred) is left out of `moves`, and unplaced: left as it is, its room's
    matches would hold it at the others' spot."""
    with pycolmap.Database.open(database) as db:
        names = [image.name for image in db.read_all_images()]
        sizes = {(c.width, c.height) for c in db.read_all_cameras()}
    ties = {}
    for first, second, size, here, there in _raw_pairs(database):
        homography, share = _wobble(here, there, size)
        if share > STILL_SHARE:
            ties[first, second] = (share, homography)  # moves first's pixels onto second's
    if not names or len(sizes) != 1:
        return None
    strength = {n: sum(share for pair, (share, _) in ties.items() if n in pair) for n in names}
    onto = {max(names, key=strength.get): np.eye(3)}
    while joining := [pair for pair in ties if (pair[0] in onto) != (pair[1] in onto)]:
        first, second = max(joining, key=lambda pair: ties[pair][0])
        homography = ties[first, second][1]
        if first in onto:
            onto[second] = onto[first] @ np.linalg.inv(homography)
        else:
            onto[first] = onto[second] @ homography
    if 2 * len(onto) <= len(names):
        return None
    box = steady_box(onto, sizes.pop())
    return None if box is None else Steadying(onto, box)


def steady_box(moves: dict[str, np.ndarray], size: tuple[int, int]
               ) -> tuple[int, int, int, int] | None:
    """(left, top, right, bottom) pixels that every photo of `size` (width, height) still covers
    once moved by its homography in `moves` (steadying), cut evenly from both sides so that the
    photos' centre stays their centre (where structure from motion puts the principal point);
    None when that keeps less than MIN_KEPT of the width or the height."""
    width, height = size
    corners = np.float32([[0, 0], [width, 0], [width, height], [0, height]]).reshape(-1, 1, 2)
    cut = np.zeros(2)  # pixels lost at each side, across and down
    for homography in moves.values():
        (x0, y0), (x1, y1), (x2, y2), (x3, y3) = cv2.perspectiveTransform(
            corners, homography).reshape(4, 2)
        cut = np.maximum(cut, [max(x0, x3, width - x1, width - x2),
                               max(y0, y1, height - y2, height - y3)])
    across, down = (int(np.ceil(c)) for c in cut)
    if width - 2 * across < MIN_KEPT * width or height - 2 * down < MIN_KEPT * height:
        return None
    return across, down, width - across, height - down


def steadied(image: np.ndarray, homography: np.ndarray, box: tuple[int, int, int, int]
             ) -> np.ndarray:
    """`image` moved by `homography` (steadying) and cut to `box` (steady_box)."""
    if not np.allclose(homography, np.eye(3)):  # the reference photo is not resampled
        image = cv2.warpPerspective(image, homography, image.shape[1::-1], flags=cv2.INTER_LINEAR)
    left, top, right, bottom = box
    return np.ascontiguousarray(image[top:bottom, left:right])


def shifts(database: Path, names: list[str]) -> list[np.ndarray]:
    """(2,) pixels each image of `names` is moved by against the first, from the median move of
    the backdrop's matches in every pair that stood still (least squares over the pairs: a
    video's are neighbours only); 0 for an image no such pair links."""
    index = {name: i for i, name in enumerate(names)}
    rows, moves = [], []
    for first, second, move, share in _stationary(database, STATIONARY_PX):
        if share > STILL_SHARE and first in index and second in index:
            row = np.zeros(len(names))
            row[index[second]], row[index[first]] = 1.0, -1.0
            rows.append(row)
            moves.append(move)
    if not rows:
        return [np.zeros(2) for _ in names]
    anchor = np.eye(len(names))[:1]  # the first image stays where it is
    solved = np.linalg.lstsq(np.vstack([anchor] + rows), np.vstack([np.zeros((1, 2))] + moves),
                             rcond=None)[0]
    return list(solved)


def backdrop(images: list[np.ndarray], moved: list[np.ndarray] | None = None
             ) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
    """((H, W) bool per photo of `images` ((H, W, 3) uint8, one size): the pixels showing what
    most photos show there, once each photo is moved back by its entry of `moved` ((2,) pixels
    against the first, see shifts; none when not given) and its exposure evened to the others';
    (H, W) bool per photo: the pixels that stand out from a backdrop most photos agree on there,
    the object's), or None when the photos differ in size or are too few."""
    if len(images) < MIN_PHOTOS or len({im.shape for im in images}) != 1:
        return None
    height, width = images[0].shape[:2]
    scale = min(1.0, WORK_SIDE / max(height, width))
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    small = np.stack([cv2.resize(im, size, interpolation=cv2.INTER_AREA) for im in images]
                     ).astype(np.float32) / 255
    # each photo moved onto the first (a nudged phone); one that moved under half a pixel here is
    # left as it is: resampling it would blur its texture off the median
    moves = [np.zeros(2) if m is None or np.abs(m * scale).max() < 0.5 else m * scale
             for m in (moved or [None] * len(images))]
    small = np.stack([_shifted(im, -dx, -dy, cv2.INTER_LINEAR) if dx or dy else im
                      for im, (dx, dy) in zip(small, moves)])
    seen = np.stack([_shifted(np.ones(im.shape[:2], np.float32), -dx, -dy) > 0.5
                     for im, (dx, dy) in zip(small, moves)])
    for _ in range(2):  # the median, then each photo's exposure against it, then again
        median = np.median(small, axis=0)
        grey = small.mean(-1) / np.maximum(median.mean(-1), 1e-3)
        exposure = np.median(grey.reshape(len(small), -1), axis=1)
        small = small / np.maximum(exposure, 1e-3)[:, None, None, None]  # a black photo stays
    median = np.median(small, axis=0)
    off = np.abs(small - median).max(-1)
    still = (off < TOLERANCE) & seen
    agreed = still.sum(0) >= AGREED * seen.sum(0)
    stands = (off > STANDS_OUT) & seen & agreed & ~_shadow(small, median)
    # only where the median has texture: a turning object moves its texture, while a plain
    # part of it can match the median as well as a plain backdrop does (and the backdrop
    # there would stand out from it)
    grey = median.mean(-1)
    detail = np.abs(cv2.Sobel(grey, cv2.CV_32F, 1, 0)) + np.abs(cv2.Sobel(grey, cv2.CV_32F, 0, 1))
    textured = cv2.blur(detail, (5, 5)) > TEXTURE
    still &= textured
    stands &= textured
    return (_back(still, moves, (width, height), 3),  # lone pixels matching by chance away
            _back(stands, moves, (width, height), STANDS_OPEN))


def _shadow(images: np.ndarray, backdrop: np.ndarray) -> np.ndarray:
    """(N, h, w) bool: the pixels of `images` (N, h, w, 3) that are the `backdrop` (h, w, 3)
    darkened by a factor between SHADOW and 1, its colour kept (Horprasert et al. 1999's
    brightness and colour distortions): a shadow the object casts, not the object."""
    factor = (images * backdrop).sum(-1) / np.maximum((backdrop ** 2).sum(-1), 1e-6)
    kept = np.abs(images - factor[..., None] * backdrop).max(-1) < TOLERANCE
    return kept & (factor > SHADOW) & (factor < 1)


def _back(found: np.ndarray, moves: list[np.ndarray], size: tuple[int, int], side: int
          ) -> list[np.ndarray]:
    """Each of `found` (N, h, w) bool, opened by a `side` x `side` square (chance matches
    away), moved back to where its photo has it and brought to `size` (W, H)."""
    opened = [_shifted(cv2.morphologyEx(f.astype(np.uint8), cv2.MORPH_OPEN,
                                        np.ones((side, side), np.uint8)), dx, dy)
              for f, (dx, dy) in zip(found, moves)]
    return [cv2.resize(f, size, interpolation=cv2.INTER_NEAREST) > 0 for f in opened]


def _shifted(image: np.ndarray, dx: float, dy: float, interpolation: int = cv2.INTER_NEAREST
             ) -> np.ndarray:
    """`image` moved by (dx, dy) pixels, zeros where nothing moved in."""
    move = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(image, move, image.shape[1::-1], flags=interpolation,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
