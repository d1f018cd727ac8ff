"""Object isolation on real backgrounds: `windowshop prepare`'s masks against hand-made ones.

    python bench/bench_isolation.py [--views 16] [--max-side 640]
                                    [--only skull|turntable|held|granite|beer|fruit]
                                    [--keep DIR]

dtu_skull (a skull on a cardboard table, hand-made masks): mean and worst IoU of each written
mask (resized to the hand mask's size) with the hand mask. turntable: the same skull, its
hand-made mask laid over one still photo of a room, a tiled floor and a paper towel in turn
(scene.products.on_turntable: a phone that stood still while the object turned), scored alike.
held: the same, each backdrop shifted by up to 20 px either way in each photo (a phone held in
the hand), the hand-made masks moved and cut as prepare steadied the photos.
granite: a plain figure on a granite table, rendered with its true masks
(scene.products.figure_on_granite, seeds 0 to GRANITE_SEEDS - 1, 640 x 480): every sparse point
lies on the table, so the object is found where the photos look.
beer_can (a can on a tiled floor, no hand masks; the frames of bench_prepare.py) and fruit (an
apple and a banana on a white cloth): the masks' share of the image. Prints JSON; `--keep`
leaves the scenes there.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

from windowshop.config import PrepareOptions
from windowshop.photos import still
from windowshop.photos.prepare import prepare
from windowshop.scene import products
from bench_prepare import beer_photos  # bench/ is on the path when run as a script

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def spread(files: list[Path], count: int) -> list[Path]:
    """`count` of `files`, evenly spread."""
    picks = np.linspace(0, len(files) - 1, min(count, len(files))).round().astype(int)
    return [files[i] for i in picks]


def linked(files: list[Path], folder: Path) -> Path:
    """A folder of symbolic links to `files` (prepare only reads them)."""
    folder.mkdir(parents=True)
    for f in files:
        (folder / f.name).symlink_to(f)
    return folder


def iou(mask: np.ndarray, truth: np.ndarray) -> float:
    return float((mask & truth).sum() / max((mask | truth).sum(), 1))


def run(photos: Path, out: Path, options: PrepareOptions) -> tuple[dict, dict[Path, np.ndarray]]:
    """(report, source photo -> written mask (H, W) bool) of one prepare."""
    start = time.perf_counter()
    report = prepare(photos, out, options, show=False).report
    report["total_seconds"] = round(time.perf_counter() - start, 2)
    masks = {}
    for view in report["views"]:
        path = out / "masks" / f"{view['name']}.png"
        if path.is_file():
            masks[Path(view["photo"])] = np.asarray(Image.open(path).convert("L")) > 127
    return report, masks


def summary(report: dict) -> dict:
    return {"placed": report["placed"], "masks": report["masks"], "plane": report["plane"],
            "seconds": report["total_seconds"], "stages": report["seconds"]}


def skull_ious(masks: dict[Path, np.ndarray], steadied: dict | None = None) -> dict:
    """mean_iou, worst_iou and each iou of `masks` (by dtu_skull photo, or a copy named alike)
    with the hand-made ones; those moved and cut first as report.json's `steadied` says, by
    photo name, when given."""
    scores = {}
    for photo, mask in masks.items():
        truth = Image.open(DATA / "dtu_skull" / "masks" / f"{photo.stem}.png").convert("L")
        if steadied is not None:  # at the photo's size: the box is cut evenly from both sides
            left, top, right, bottom = steadied["box"]
            truth = Image.fromarray(still.steadied(
                np.asarray(truth.resize((left + right, top + bottom))),
                np.array(steadied["moves"][photo.stem]), steadied["box"]))
        truth = np.asarray(truth) > 127
        resized = Image.fromarray(mask).resize(truth.shape[::-1], Image.NEAREST)
        scores[photo.stem] = round(iou(np.asarray(resized), truth), 3)
    values = list(scores.values()) or [0.0]
    return {"mean_iou": round(float(np.mean(values)), 3), "worst_iou": min(values),
            "iou": scores}


def skull(work: Path, views: int, options: PrepareOptions) -> dict:
    files = spread(sorted((DATA / "dtu_skull" / "images").glob("*.jpg")), views)
    report, masks = run(linked(files, work / "skull"), work / "skull-scene", options)
    return {**summary(report), **skull_ious(masks)}


TURNTABLE_BACKDROPS = {"room": DATA / "kermit" / "kermit000.jpg",
                       "tiles": DATA / "beer_can" / "images" / "0030.jpg",
                       "towel": DATA / "fruit" / "newfruit_small" / "IMG_3630.jpg"}


HELD_PX = 20  # held: the room shifted by up to this many pixels either way in each photo


def turntable(work: Path, views: int, options: PrepareOptions, nudge_px: int = 0) -> dict:
    """dtu_skull's skull turned in front of each still backdrop in TURNTABLE_BACKDROPS, each
    shifted by up to `nudge_px` either way in each photo."""
    frames = products.dtu_frames(DATA / "dtu_skull")
    frames = [frames[i] for i in np.linspace(0, len(frames) - 1, min(views, len(frames)))
              .round().astype(int)]
    rows = {}
    for name, backdrop in TURNTABLE_BACKDROPS.items():
        capture = products.on_turntable(frames, backdrop, work / f"turntable{nudge_px}-{name}",
                                        nudge_px=nudge_px)
        report, masks = run(capture / "images", work / f"turntable{nudge_px}-{name}-scene",
                            options)
        steadied = report.get("steadied")
        rows[name] = {**summary(report), "steadied": steadied is not None,
                      **skull_ious(masks, steadied)}
    return {"mean_iou": round(float(np.mean([r["mean_iou"] for r in rows.values()])), 3),
            "worst_iou": min(r["worst_iou"] for r in rows.values()), **rows}


def held(work: Path, views: int, options: PrepareOptions) -> dict:
    """turntable's, the phone held in the hand: each backdrop shifted by up to HELD_PX."""
    return turntable(work, views, options, HELD_PX)


GRANITE_SEEDS = 8


def granite(work: Path, views: int, options: PrepareOptions) -> dict:
    """The rendered figure on granite, one capture per seed, against its true masks."""
    rows = {}
    for seed in range(GRANITE_SEEDS):
        capture = products.figure_on_granite(work / f"granite{seed}", count=views, seed=seed)
        report, masks = run(capture / "images", work / f"granite{seed}-scene", options)
        scores = [iou(mask, np.asarray(Image.open(capture / "masks" / f"{photo.stem}.png")) > 127)
                  for photo, mask in masks.items()] or [0.0]
        rows[f"seed{seed}"] = {**summary(report), "mean_iou": round(float(np.mean(scores)), 3),
                               "worst_iou": round(min(scores), 3)}
    return {"mean_iou": round(float(np.mean([r["mean_iou"] for r in rows.values()])), 3),
            "worst_iou": min(r["worst_iou"] for r in rows.values()), **rows}


def area(name: str, files: list[Path], work: Path, options: PrepareOptions) -> dict:
    """Prepare `files` (no hand masks): how much of each photo the masks take."""
    report, masks = run(linked(files, work / name), work / f"{name}-scene", options)
    shares = [float(m.mean()) for m in masks.values()] or [0.0]
    return {**summary(report), "area_share": {"min": round(min(shares), 3),
            "median": round(float(np.median(shares)), 3), "max": round(max(shares), 3)}}


def beer(work: Path, views: int, options: PrepareOptions) -> dict:
    """bench_prepare's 14 frames, whatever `views` says: a sample over the whole walk is folded
    and refused."""
    return area("beer", beer_photos(), work, options)


def fruit(work: Path, views: int, options: PrepareOptions) -> dict:
    files = spread(sorted((DATA / "fruit" / "newfruit_small").glob("*.jpg")), views)
    return area("fruit", files, work, options)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=16)
    parser.add_argument("--max-side", type=int, default=640)
    parser.add_argument("--only", choices=["skull", "turntable", "held", "granite", "beer",
                                           "fruit"],
                        default=None)
    parser.add_argument("--keep", default=None, help="write the scenes under this folder")
    args = parser.parse_args()
    options = PrepareOptions(max_side=args.max_side)
    results = {"machine": platform.platform(), "cpus": os.cpu_count(), "views": args.views,
               "max_side": args.max_side}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        for key, name, bench in (("skull", "dtu_skull", skull),
                                 ("turntable", "turntable", turntable),
                                 ("held", "held", held), ("granite", "granite", granite),
                                 ("beer", "beer_can", beer), ("fruit", "fruit", fruit)):
            if args.only in (None, key):
                results[name] = bench(work, args.views, options)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
