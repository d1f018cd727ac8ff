"""Build the captures with known answers that the shared data lacks, for bench_verify's `--extra`,
each as a folder with images/ and a ground-truth transforms.json (one JSON line per case).

    python bench/cases.py OUT [--only doppelganger,granite,skull_up,fruit_rolled] [--seed 0]
    python bench/bench_verify.py --extra doppelganger=OUT/doppelganger --extra granite=OUT/granite \
        --extra skull_up=OUT/skull_up --extra fruit_rolled=OUT/fruit_rolled

  doppelganger  a carton whose opposite sides carry one print, on pure white, 40 photos all
                round (windowshop.scene.products.doppelganger_box): incremental structure from
                motion folds it;
  granite       a plain figure on a granite table, 20 photos all round (figure_on_granite):
                nearly every sparse point lies on the table;
  skull_up      every third dtu_skull photo (17) pitched up 5 degrees (products.turned): a
                capture looking up, with no support plane in view of most photos;
  fruit_rolled  every fruit photo (81) rolled by quarters in turn, 0/90/180/270 degrees (the
                phone held every way), with each frame's gravity: the up vector's case.
The same on every run; `--seed K` (K > 0) gives other captures of the same kind, to check that
an outcome is not one seed's: the rendered cases' cameras, jitter and prints drawn from K,
skull_up every third photo from photo K mod 3, fruit_rolled each photo's quarter drawn at random.
The turned cases read ../shared/data in place.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from windowshop.scene import products, read_source

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def skull_up(out: Path, seed: int) -> Path:
    frames = products.dtu_frames(DATA / "dtu_skull")[seed % 3::3]
    return products.turned(frames, out, 0.0, 5.0)


def fruit_rolled(out: Path, seed: int) -> Path:
    frames = read_source(DATA / "fruit").frames
    quarters = (np.arange(len(frames)) % 4 if seed == 0
                else np.random.default_rng(seed).integers(0, 4, len(frames)))
    return products.turned(frames, out, list(90.0 * quarters))


BUILDERS = {
    "doppelganger": lambda out, seed: products.doppelganger_box(out, 40, (640, 480), seed),
    "granite": lambda out, seed: products.figure_on_granite(out, 20, (640, 480), seed),
    "skull_up": skull_up,
    "fruit_rolled": fruit_rolled,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--only", default=",".join(BUILDERS),
                        help="comma list of " + ", ".join(BUILDERS))
    parser.add_argument("--seed", type=int, default=0, help="0: the documented cases")
    args = parser.parse_args()
    for name in args.only.split(","):
        if name not in BUILDERS:
            raise SystemExit(f"--only: no case {name!r}; the cases are {', '.join(BUILDERS)}")
        start = time.perf_counter()
        folder = BUILDERS[name](args.out / name, args.seed)
        frames = json.loads((folder / "transforms.json").read_text())["frames"]
        print(json.dumps({"case": name, "path": str(folder), "seed": args.seed,
                          "photos": len(frames),
                          "seconds": round(time.perf_counter() - start, 1)}), flush=True)


if __name__ == "__main__":
    main()
