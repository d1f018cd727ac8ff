"""Seconds per `prepare` stage for kermit (11 photos), 14 beer_can photos and 80 frames of the
beer_can video (given as the video, then as a folder of photos: the matcher is picked by count and
order), all 78 of fruit's photos, and with `--figure N` N rendered 800x800 photos of a plain
figure on a granite table (windowshop.scene.products.figure_on_granite; every photo rich in the
table's features, the issue 35 case; rendered once, about 4 minutes for 88, and kept under
~/.cache/windowshop/bench), with `--phone jpg heic` kermit's photos enlarged to a 12-megapixel
phone's 4032x3024 in those formats (EXIF kept; the reading stage is what a phone's photos cost),
as JSON.

    python bench/bench_prepare.py [--max-side 640] [--frames 80] [--figure 88] [--phone jpg heic]
                                  [--video] [--out results.json]
    python bench/cpu_profile.py ordinary python bench/bench_prepare.py --figure 88

`--video` also times `windowshop video` end to end (prepare, fit, render) on the 14 photos with
its default settings. Pose errors against beer_can's COLMAP model are included for reference.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from provenance import emit, machine

from windowshop.config import PrepareOptions
from windowshop.photos.align import pose_errors
from windowshop.photos.prepare import prepare
from windowshop.scene import read_source

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def beer_photos() -> list[Path]:
    """The beer_can photos of tests/photos/test_prepare_poses.py: frames 0000-0013, whose
    published poses are trustworthy (after them the published model is folded, and a sample over
    the whole walk is folded and refused: bench/RESULTS.md, "Quarter-turn rolls ...")."""
    return [DATA / "beer_can" / "images" / f"{i:04d}.jpg" for i in range(14)]


def figure_photos(count: int) -> Path:
    """The folder of `count` 800x800 photos of the figure on granite, rendered on first use."""
    from windowshop.scene.products import figure_on_granite

    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "windowshop" / "bench"
    folder = root / f"figure_on_granite_{count}"
    if not (folder / "transforms.json").is_file():
        figure_on_granite(folder, count=count, size=(800, 800))
    return folder / "images"


def phone_photos(folder: Path, suffix: str) -> Path:
    """kermit's 11 photos as a 12-megapixel phone would save them (4032x3024, EXIF kept), as
    JPEG or HEIC (`suffix`)."""
    from PIL import Image

    import windowshop.media  # noqa: F401  (registers pillow-heif's HEIC writer)

    folder.mkdir()
    for path in sorted((DATA / "kermit").glob("*.jpg")):
        with Image.open(path) as image:
            big = image.resize((4032, 3024), Image.Resampling.BICUBIC)
            big.save(folder / f"{path.stem}.{suffix}", quality=90, exif=image.getexif())
    return folder


def timed_prepare(source: Path, out: Path, options: PrepareOptions) -> dict:
    start = time.perf_counter()
    result = prepare(source, out, options, show=False)
    report = result.report
    return {"seconds": report["seconds"], "total_seconds": round(time.perf_counter() - start, 2),
            "used": report["used"], "placed": report["placed"], "matcher": report["matcher"],
            "pairs": report["pairs"], "load": round(os.getloadavg()[0], 2),
            "attempts": [a["label"] for a in report["attempts"]],
            "reprojection_error_px": round(report["reprojection_error_px"], 3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-side", type=int, default=640)
    parser.add_argument("--frames", type=int, default=80,
                        help="frames sampled from beer_can's video (0: no video row)")
    parser.add_argument("--figure", type=int, default=0,
                        help="photos of the rendered figure on granite (0: no such row)")
    parser.add_argument("--phone", nargs="*", default=[], choices=["jpg", "heic"],
                        help="also kermit's photos at a phone's 12 megapixels, in these formats")
    parser.add_argument("--video", action="store_true",
                        help="also time `windowshop video` on the 20 photos")
    parser.add_argument("--out", default=None, help="also write the JSON here")
    args = parser.parse_args()
    options = PrepareOptions(max_side=args.max_side)
    results = {**machine(), "max_side": args.max_side}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.frames:
            frames = PrepareOptions(max_side=args.max_side, video_frames=args.frames)
            results[f"beer_can_video_{args.frames}"] = timed_prepare(
                DATA / "beer_can" / "Beer.mp4", tmp / "beer_video", frames)
            results[f"beer_can_photos_{args.frames}"] = timed_prepare(
                tmp / "beer_video" / "images", tmp / "beer_photos", frames)
        results["kermit"] = timed_prepare(DATA / "kermit", tmp / "kermit", options)
        for suffix in args.phone:
            results[f"kermit_12mp_{suffix}"] = timed_prepare(
                phone_photos(tmp / f"kermit_{suffix}", suffix), tmp / f"kermit_big_{suffix}", options)
        results["fruit_78"] = timed_prepare(DATA / "fruit" / "newfruit_small", tmp / "fruit", options)
        if args.figure:
            results[f"figure_on_granite_{args.figure}"] = timed_prepare(
                figure_photos(args.figure), tmp / "figure", options)
        photos = tmp / "beer14"
        photos.mkdir()
        for path in beer_photos():
            (photos / path.name).symlink_to(path)
        results["beer_can_14"] = timed_prepare(photos, tmp / "beer", options)
        meta = json.loads((tmp / "beer" / "transforms.json").read_text())
        recovered = {Path(f["file_path"]).stem: np.array(f["transform_matrix"])
                     for f in meta["frames"]}
        reference = {f.image_path.stem: f.camera.c2w
                     for f in read_source(DATA / "beer_can" / "sparse" / "0").frames}
        errors = pose_errors(recovered, reference)
        results["beer_can_14"].update(max_rotation_deg=round(float(errors.rotation_deg.max()), 3),
                                      max_centre_share=round(float(errors.centre_share.max()), 4))
        if args.video:
            from windowshop.device import pick_device
            from windowshop.config import PipelineConfig
            from windowshop.pipeline import make_video

            settings = PipelineConfig(prepare=options)
            start = time.perf_counter()
            video = make_video(photos, tmp / "spin.mp4", settings, device=pick_device(), show=False)
            results["video_beer_can_14"] = {
                "seconds": {k: round(v, 2) for k, v in video.seconds.items()},
                "total_seconds": round(time.perf_counter() - start, 2),
                "device": str(pick_device()),
                "model": settings.model, "train_seconds": settings.fit.seconds,
                "frames": settings.render.frames, "frame_size": settings.render.width,
                "held_out_psnr": video.metrics.get("psnr")}
    emit(results, args.out)


if __name__ == "__main__":
    main()
