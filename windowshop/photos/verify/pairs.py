"""Poses against the matches: every strongly matched pair's own relative rotation (from its
verified two-view geometry, `TwoViewGeometryOptions.compute_relative_pose`) against the one the
model gives its two photos.

A model that folds a capture onto itself (the doppelganger failure of incremental SfM on an
object whose sides look alike) or drops a photo in the wrong place still agrees with most of
its pairs, but not with the pairs that tie a misplaced photo to its true neighbours: those
contradict it by tens of degrees (Heinly et al. 2014, "conflicting observations"). Weak pairs
are left out: between wide steps (45 degrees on fruit) a pair of 30-90 inliers gives a rotation
15-45 degrees off the truth while the model, which weighs every photo at once, is within 4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pycolmap

from windowshop.photos.align import rotation_angle
from windowshop.photos.verify import Check, Hypothesis

STRONG_INLIERS = 100  # a pair with this many verified inliers measures its rotation well
CONFLICT_DEG = 30.0  # the model and a strong pair disagree by more than this: a conflict
MIN_STRONG = 3  # fewer strong pairs between placed photos: nothing to check against
PASS_SHARE = 0.95  # share of the strong pairs that must agree
ADVICE = ("some photos were placed where their own matches do not put them, as happens when "
          "the object's sides look alike: add photos that show a corner and two sides at once, "
          "and walk round in small steps (10-15 degrees)")


@dataclass(frozen=True)
class Pair:
    """A verified pair: image names, inliers, and the rotation (3, 3) from the first image's
    camera to the second's (OpenCV axes, as COLMAP's cam2_from_cam1)."""

    first: str
    second: str
    inliers: int
    rotation: np.ndarray


def strong_pairs(database, min_inliers: int = STRONG_INLIERS) -> list[Pair]:
    """The database's verified pairs with at least `min_inliers` and a relative pose."""
    with pycolmap.Database.open(database) as db:
        names = {image.image_id: image.name for image in db.read_all_images()}
        ids, geometries = db.read_two_view_geometries()
    out = []
    for pair_id, geometry in zip(ids, geometries):
        if len(geometry.inlier_matches) < min_inliers:
            continue
        first, second = pycolmap.pair_id_to_image_pair(pair_id)
        rotation = geometry.cam2_from_cam1.rotation.matrix()
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6):
            continue  # no pose was computed (a planar or panoramic pair)
        out.append(Pair(names[first], names[second], len(geometry.inlier_matches), rotation))
    return out


def disagreements(model: pycolmap.Reconstruction, found: list[Pair]) -> list[tuple[Pair, float]]:
    """(pair, degrees between its rotation and the model's) for the pairs whose photos are
    both placed in `model`."""
    rotations = {image.name: image.cam_from_world().rotation.matrix()
                 for image in model.images.values() if image.has_pose}
    return [(p, rotation_angle(p.rotation.T @ rotations[p.second] @ rotations[p.first].T))
            for p in found if p.first in rotations and p.second in rotations]


def _blamed(measured: list[tuple[Pair, float]]) -> tuple[str, ...]:
    """The photos more of whose strong pairs contradict the model than agree with it."""
    votes: dict[str, int] = {}
    for pair, degrees in measured:
        for name in (pair.first, pair.second):
            votes[name] = votes.get(name, 0) + (1 if degrees > CONFLICT_DEG else -1)
    return tuple(sorted(n for n, v in votes.items() if v > 0))


def check(hypothesis: Hypothesis) -> Check | None:
    sfm = hypothesis.sfm
    if sfm.reconstruction is None or sfm.database is None:
        return None
    measured = disagreements(sfm.reconstruction, strong_pairs(sfm.database))
    if len(measured) < MIN_STRONG:
        return None
    conflicts = [(p, d) for p, d in measured if d > CONFLICT_DEG]
    share = 1.0 - len(conflicts) / len(measured)
    worst = ", ".join(f"{p.first}-{p.second} {d:.0f} deg ({p.inliers} matches)"
                      for p, d in sorted(conflicts, key=lambda c: -c[1])[:5])
    detail = (f"{len(measured) - len(conflicts)} of {len(measured)} strongly matched pairs "
              f"(>= {STRONG_INLIERS} matches) agree with the model within {CONFLICT_DEG:.0f} deg"
              + (f"; contradicted: {worst}" if conflicts else ""))
    return Check("pairs", share, PASS_SHARE, detail, ADVICE, _blamed(measured))
