"""Poses from 8 wide-baseline photos: how many of them structure from motion places, and how far
the recovered relative rotations are from the published ones, for each shared capture, as JSON.

    python bench/bench_fewphoto.py [--count 8] [--sets dtu_skull,temple] [--out results.json]

The photos are spread around the object by the published cameras' azimuth (farthest-point
sampling on the circle), so the set is the widest baseline the capture allows; kermit has no
poses and takes evenly spaced file names.

Scoring (all poses as OpenGL camera-to-world): the placed cameras are aligned to the reference
ones by the similarity that the most of them agree with (each triple of cameras proposes one,
Umeyama 1991, refitted on the ones that agree); a photo is correct when, so aligned, its rotation
is within CORRECT_DEG and its centre within CORRECT_SHARE of the capture radius of the reference.
Photos placed with the turntable prior's help (windowshop.photos.fill: "paired", "guessed") are
scored the same way but counted apart ("ring_correct"), never in "placed" or "correct". Rotation
errors compare every pair of measured photos' relative rotation with the truth (independent of
the world frame).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from itertools import combinations
from pathlib import Path

import numpy as np
from provenance import emit, machine

from windowshop.photos.align import rotation_angle, umeyama
from windowshop.photos.ingest import Dropped, read_photos
from windowshop.photos.output import posed_photos, write_image
from windowshop.photos.progress import Stages
from windowshop.photos.sfm import SfmSettings, reconstruct
from windowshop.scene import read_source
from windowshop.scene.cameras import nearest_point_to_axes, opencv_w2c_to_gl_c2w

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
Truth = dict[Path, np.ndarray | None]  # photo -> OpenGL camera-to-world (4, 4), None if unknown
CORRECT_DEG = 10.0  # a placed photo within this rotation error ...
CORRECT_SHARE = 0.2  # ... and this share of the capture radius of its reference pose is correct


def spread(centres: np.ndarray, count: int) -> list[int]:
    """Indices of `count` camera centres (N, 3) spread evenly in azimuth about their mean, in
    the plane that fits them best: farthest-point sampling on the circle."""
    offsets = centres - centres.mean(0)
    basis = np.linalg.svd(offsets, full_matrices=False)[2][:2]
    azimuth = np.arctan2(offsets @ basis[1], offsets @ basis[0])
    chosen = [int(np.argmin(azimuth))]
    while len(chosen) < count:
        gap = np.abs(np.angle(np.exp(1j * (azimuth[:, None] - azimuth[chosen][None]))))
        chosen.append(int(np.argmax(gap.min(1))))
    return sorted(chosen)


def _pick(paths: list[Path], c2ws: list[np.ndarray], count: int) -> Truth:
    picks = spread(np.stack([c[:3, 3] for c in c2ws]), count)
    return {paths[i]: c2ws[i] for i in picks}


def dtu_skull(count: int) -> Truth:
    import cv2

    cams = np.load(DATA / "dtu_skull" / "cameras_sphere.npz")
    paths, c2ws = [], []
    for i in range(49):
        _, rot, centre = cv2.decomposeProjectionMatrix(cams[f"world_mat_{i}"][:3])[:3]
        paths.append(DATA / "dtu_skull" / "images" / f"{i:03d}.jpg")
        c2ws.append(opencv_w2c_to_gl_c2w(rot, -rot @ (centre[:3, 0] / centre[3, 0]), "dtu"))
    return _pick(paths, c2ws, count)


def temple(count: int) -> Truth:
    rows = (DATA / "temple_sparse" / "templeSR_par.txt").read_text().split("\n")[1:]
    rows = [r.split() for r in rows if r.strip()]
    step = len(rows) // count  # a ring taken at equal angles: every `step`-th photo
    return {DATA / "temple_sparse" / r[0]: opencv_w2c_to_gl_c2w(
        np.array(r[10:19], float).reshape(3, 3), np.array(r[19:22], float), r[0])
        for r in rows[::step][:count]}


def fruit(count: int) -> Truth:
    meta = json.loads((DATA / "fruit" / "transforms.json").read_text())
    c2w = [np.array(f["transform_matrix"]) for f in meta["frames"]]
    paths = [DATA / "fruit" / f["file_path"] for f in meta["frames"]]
    return _pick(paths, c2w, count)


def beer_can(count: int) -> Truth:
    """Only the frames whose reference pose is trustworthy (tests/photos/test_prepare_poses.py)."""
    doubtful = {i for jump in (13, 34, 52) for i in range(jump - 1, jump + 7)} | {30, 44}
    frames = {f.image_path.stem: f.camera.c2w
              for f in read_source(DATA / "beer_can" / "sparse" / "0").frames}
    keep = sorted(n for n in frames if int(n) not in doubtful)
    paths = [DATA / "beer_can" / "images" / f"{n}.jpg" for n in keep]
    return _pick(paths, [frames[n] for n in keep], count)


def kermit(count: int) -> Truth:
    files = sorted((DATA / "kermit").glob("*.jpg"))
    picks = np.linspace(0, len(files) - 1, count).round().astype(int)
    return {files[i]: None for i in picks}


SETS = {"dtu_skull": dtu_skull, "temple": temple, "fruit": fruit, "beer_can": beer_can,
        "kermit": kermit}


def relative_errors(recovered: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> np.ndarray:
    """Degrees between recovered and true relative rotations of every pair of names in both
    (camera-to-world matrices (4, 4), the same camera axes in both)."""
    names = sorted(set(recovered) & set(truth))
    return np.array([rotation_angle((recovered[a][:3, :3].T @ recovered[b][:3, :3]).T
                                    @ (truth[a][:3, :3].T @ truth[b][:3, :3]))
                     for a, b in combinations(names, 2)])


def _errors(est: np.ndarray, ref: np.ndarray, fit: np.ndarray, radius: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """(rotation degrees (N,), centre error / radius (N,)) of c2ws `est` against `ref` (N, 4, 4)
    after the similarity that aligns the centres of the cameras `fit` (indices)."""
    scale, rot, t = umeyama(est[fit, :3, 3], ref[fit, :3, 3])
    centres = scale * est[:, :3, 3] @ rot.T + t
    degrees = np.array([rotation_angle(r.T @ rot @ e) for r, e in zip(ref[:, :3, :3],
                                                                   est[:, :3, :3])])
    return degrees, np.linalg.norm(centres - ref[:, :3, 3], axis=-1) / radius


def correct(recovered: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> set[str]:
    """The recovered photos (c2w (4, 4)) whose poses agree with the truth under the one
    similarity that the most of them agree with (see the module docstring)."""
    names = sorted(set(recovered) & set(truth))
    if len(names) == 2:  # no similarity to fit: the relative rotation alone
        return set(names) if relative_errors(recovered, truth)[0] <= CORRECT_DEG else set()
    if len(names) < 3:
        return set()
    est = np.stack([recovered[n] for n in names])
    ref = np.stack([truth[n] for n in names])
    every = np.stack(list(truth.values()))
    radius = float(np.median(np.linalg.norm(every[:, :3, 3] - nearest_point_to_axes(every),
                                            axis=-1)))
    best = np.zeros(len(names), bool)
    for triple in combinations(range(len(names)), 3):
        degrees, share = _errors(est, ref, np.array(triple), radius)
        agree = (degrees <= CORRECT_DEG) & (share <= CORRECT_SHARE)
        if agree.sum() >= 3 and agree.sum() > best.sum():
            degrees, share = _errors(est, ref, np.flatnonzero(agree), radius)  # refit
            refit = (degrees <= CORRECT_DEG) & (share <= CORRECT_SHARE)
            best = refit if refit.sum() >= agree.sum() else agree
    return {n for n, ok in zip(names, best) if ok}


def score(row: dict, recovered: dict[str, np.ndarray], guessed: list[str],
          truth: dict[str, np.ndarray]) -> None:
    """Add to `row` how many measured and ring-guessed photos are correct, and the measured
    photos' relative rotation errors."""
    right = correct(recovered, truth)
    measured = {n: c for n, c in recovered.items() if n not in guessed}
    row.update(correct=len(right - set(guessed)), ring_correct=len(right & set(guessed)),
               wrong=sorted(set(recovered) - right))
    errors = relative_errors(measured, truth)
    if len(errors):
        row.update(rotation_deg_median=round(float(np.median(errors)), 2),
                   rotation_deg_max=round(float(errors.max()), 2))


def place(truth: Truth, max_side: int, work: Path) -> dict:
    """Structure from motion on the photos of `truth` at working size `max_side`."""
    photos = read_photos(sorted(truth), max_side, Dropped())
    (work / "images").mkdir(parents=True)
    for photo in photos:
        write_image(work, photo.name, photo.pixels)
    start = time.perf_counter()
    sfm = reconstruct(work / "images", [f"{p.name}.jpg" for p in photos], work, SfmSettings(),
                      Stages(show=False))
    ring = {n.rsplit(".", 1)[0]: how for n, how in getattr(sfm, "ring_method", {}).items()}
    guessed = sorted(ring)  # placed with the ring's help (none before it)
    row = {"placed": len(sfm.placed), "total": len(truth),
           "ring_paired": sorted(n for n, how in ring.items() if how == "paired"),
           "ring_guessed": sorted(n for n, how in ring.items() if how == "guessed"),
           "unplaced": sfm.unplaced, "seconds": round(time.perf_counter() - start, 1),
           "attempts": [(a.label, a.placed) for a in sfm.attempts]}
    if sfm.reconstruction is not None and all(r is not None for r in truth.values()):
        recovered = {p.name: p.camera.c2w for p in posed_photos(sfm.reconstruction)}
        score(row, recovered, guessed, {p.stem: r for p, r in truth.items()})
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=8)
    parser.add_argument("--max-side", type=int, default=640)
    parser.add_argument("--sets", default=",".join(SETS))
    parser.add_argument("--out", default=None, help="also write the JSON here")
    args = parser.parse_args()
    results = {**machine(), "count": args.count}
    for name in args.sets.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            results[name] = place(SETS[name](args.count), args.max_side, Path(tmp))
        print(name, results[name], flush=True)
    emit(results, args.out)


if __name__ == "__main__":
    main()
