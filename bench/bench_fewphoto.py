"""Poses from 8 wide-baseline photos: how many of them structure from motion places, and how far
the recovered relative rotations are from the published ones, for each shared capture, as JSON.

    python bench/bench_fewphoto.py [--count 8] [--sets dtu_skull,temple] [--out results.json]

The photos are spread around the object by the published cameras' azimuth (farthest-point
sampling on the circle), so the set is the widest baseline the capture allows; kermit has no
poses and takes evenly spaced file names. Rotation errors compare every pair of placed photos'
relative rotation with the truth's (independent of the world frame and camera axes).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from itertools import combinations
from pathlib import Path

import numpy as np
from provenance import emit

from windowshop.photos.align import rotation_angle
from windowshop.photos.ingest import Dropped, read_photos
from windowshop.photos.output import write_image
from windowshop.photos.progress import Stages
from windowshop.photos.sfm import SfmSettings, reconstruct
from windowshop.scene import read_source

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
Truth = dict[Path, np.ndarray]  # photo -> world-to-camera rotation (3, 3)


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


def _pick(paths: list[Path], rotations: list[np.ndarray], centres: list[np.ndarray],
          count: int) -> Truth:
    picks = spread(np.stack(centres), count)
    return {paths[i]: rotations[i] for i in picks}


def dtu_skull(count: int) -> Truth:
    import cv2

    cams = np.load(DATA / "dtu_skull" / "cameras_sphere.npz")
    paths, rots, centres = [], [], []
    for i in range(49):
        _, rot, centre = cv2.decomposeProjectionMatrix(cams[f"world_mat_{i}"][:3])[:3]
        paths.append(DATA / "dtu_skull" / "images" / f"{i:03d}.jpg")
        rots.append(rot)
        centres.append(centre[:3, 0] / centre[3, 0])
    return _pick(paths, rots, centres, count)


def temple(count: int) -> Truth:
    rows = (DATA / "temple_sparse" / "templeSR_par.txt").read_text().split("\n")[1:]
    rows = [r.split() for r in rows if r.strip()]
    step = len(rows) // count  # a ring taken at equal angles: every `step`-th photo
    return {DATA / "temple_sparse" / r[0]: np.array(r[10:19], float).reshape(3, 3)
            for r in rows[::step][:count]}


def fruit(count: int) -> Truth:
    meta = json.loads((DATA / "fruit" / "transforms.json").read_text())
    c2w = [np.array(f["transform_matrix"]) for f in meta["frames"]]
    paths = [DATA / "fruit" / f["file_path"] for f in meta["frames"]]
    return _pick(paths, [m[:3, :3].T for m in c2w], [m[:3, 3] for m in c2w], count)


def beer_can(count: int) -> Truth:
    """Only the frames whose reference pose is trustworthy (tests/photos/test_prepare_poses.py)."""
    doubtful = {i for jump in (13, 34, 52) for i in range(jump - 1, jump + 7)} | {30, 44}
    frames = {f.image_path.stem: f.camera.c2w
              for f in read_source(DATA / "beer_can" / "sparse" / "0").frames}
    keep = sorted(n for n in frames if int(n) not in doubtful)
    paths = [DATA / "beer_can" / "images" / f"{n}.jpg" for n in keep]
    return _pick(paths, [frames[n][:3, :3].T for n in keep], [frames[n][:3, 3] for n in keep],
                 count)


def kermit(count: int) -> Truth:
    files = sorted((DATA / "kermit").glob("*.jpg"))
    picks = np.linspace(0, len(files) - 1, count).round().astype(int)
    return {files[i]: None for i in picks}


SETS = {"dtu_skull": dtu_skull, "temple": temple, "fruit": fruit, "beer_can": beer_can,
        "kermit": kermit}


def relative_errors(recovered: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> np.ndarray:
    """Degrees between recovered and true relative rotations R_i R_j^T of every pair of names
    in both (world-to-camera rotations (3, 3))."""
    names = sorted(set(recovered) & set(truth))
    return np.array([rotation_angle((recovered[a] @ recovered[b].T).T @ (truth[a] @ truth[b].T))
                     for a, b in combinations(names, 2)])


def place(truth: Truth, max_side: int, work: Path) -> dict:
    """Structure from motion on the photos of `truth` at working size `max_side`."""
    photos = read_photos(sorted(truth), max_side, Dropped())
    (work / "images").mkdir(parents=True)
    for photo in photos:
        write_image(work, photo.name, photo.pixels)
    start = time.perf_counter()
    sfm = reconstruct(work / "images", [f"{p.name}.jpg" for p in photos], work, SfmSettings(),
                      Stages(show=False))
    row = {"placed": len(sfm.placed), "total": len(truth), "unplaced": sfm.unplaced,
           "seconds": round(time.perf_counter() - start, 1),
           "attempts": [(a.label, a.placed) for a in sfm.attempts]}
    if sfm.reconstruction is not None and all(r is not None for r in truth.values()):
        recovered = {im.name.rsplit(".", 1)[0]: im.cam_from_world().rotation.matrix()
                     for im in sfm.reconstruction.images.values() if im.has_pose}
        errors = relative_errors(recovered, {p.stem: r for p, r in truth.items()})
        if len(errors):
            row.update(rotation_deg_median=round(float(np.median(errors)), 2),
                       rotation_deg_max=round(float(errors.max()), 2))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=8)
    parser.add_argument("--max-side", type=int, default=640)
    parser.add_argument("--sets", default=",".join(SETS))
    parser.add_argument("--out", default=None, help="also write the JSON here")
    args = parser.parse_args()
    results = {"machine": platform.platform(), "cpus": os.cpu_count(), "count": args.count,
               "load": os.getloadavg()[0]}
    for name in args.sets.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            results[name] = place(SETS[name](args.count), args.max_side, Path(tmp))
        print(name, results[name], flush=True)
    emit(results, args.out)


if __name__ == "__main__":
    main()
