"""Peak memory of whole jobs on 100x100 scenes: the seed study and `windowshop video` on lego_tiny.

    python bench/bench_memory.py [--only seed|video] [--rows 3,10] [--code DIR] [--keep DIR]

Each job runs in a child process through the real command line; the peak resident set size is
the child's own `ru_maxrss` (its process tree's largest, ffmpeg and workers included), read by a
small wrapper so nothing else counts. The seed study runs every row of the seed's Table 1 (or
`--rows`, 1-based) for one iteration with one held-out view: memory depends on a step's batch and
a frame's rays, not on how many there are. `video` runs the defaults (30 s of the fast model, a
60-frame 256x256 turntable) on the posed scene. `--code DIR` runs another checkout's code (e.g. an
export of an older commit, for a before/after figure). Prints JSON; the budget asked is 2 GB.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from windowshop.study.grids import SEED

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SCENE = DATA / "lego_tiny.npz"
LIMIT_MB = 2048
# runs argv[1:] and prints its peak RSS (kB on Linux) as the last line of stderr
WRAPPER = ("import resource, subprocess, sys; rc = subprocess.call(sys.argv[1:]); "
           "print('peak_kb', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr); "
           "sys.exit(rc)")


def measure(name: str, command: list[str], code: Path | None) -> dict:
    """Run `command` in a child and report its peak RSS in MB, wall seconds and exit status."""
    env = dict(os.environ, **({"PYTHONPATH": str(code)} if code else {}))
    start = time.perf_counter()
    # `python -m` puts the working folder first on the path: run in the code's own folder
    done = subprocess.run([sys.executable, "-c", WRAPPER, *command], capture_output=True, text=True,
                          env=env, cwd=code)
    seconds = time.perf_counter() - start
    peak_kb = int(done.stderr.strip().splitlines()[-1].split()[1])
    result = {"job": name, "peak_rss_mb": round(peak_kb / 1024), "under_2gb": peak_kb / 1024 < LIMIT_MB,
              "seconds": round(seconds, 1), "returncode": done.returncode,
              "command": " ".join(command[2:])}
    if done.returncode:
        result["stderr_tail"] = done.stderr[-2000:]
    return result


def seed_grid(rows: list[int] | None, folder: Path) -> Path:
    """The seed preset as a grid file, restricted to `rows` (1-based) when given."""
    grid = dict(SEED, rows=[SEED["rows"][i - 1] for i in rows] if rows else SEED["rows"])
    path = folder / "seed.json"
    path.write_text(json.dumps(grid))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=["seed", "video"])
    parser.add_argument("--rows", default=None, help="seed rows to run, 1-based (default: all ten)")
    parser.add_argument("--code", type=Path, default=None, help="checkout whose windowshop to run")
    parser.add_argument("--keep", type=Path, default=None, help="leave the outputs in this folder")
    args = parser.parse_args()
    rows = [int(r) for r in args.rows.split(",")] if args.rows else None
    cli = [sys.executable, "-m", "windowshop"]
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        results = []
        if args.only in (None, "seed"):
            grid = seed_grid(rows, out)
            results.append(measure("study seed", [*cli, "study", "--grid", str(grid), "--scene", str(SCENE),
                                                  "--out", str(out / "study"), "--iters", "1", "--set",
                                                  "test_views=1", "--device", "cpu", "--quiet"], args.code))
        if args.only in (None, "video"):
            results.append(measure("video", [*cli, "video", str(SCENE), "--out", str(out / "spin.mp4"),
                                             "--device", "cpu"], args.code))
    print(json.dumps({"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
                      "code": str(args.code or Path(__file__).resolve().parents[1]),
                      "rows": rows or "all", "limit_mb": LIMIT_MB, "results": results}, indent=1))


if __name__ == "__main__":
    main()
