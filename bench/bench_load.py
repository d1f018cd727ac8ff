"""Seconds to load the 400 lego views (Blender, 400x400 RGBA) at full size into a Scene.

Prints one JSON object: python bench/bench_load.py [--path ../shared/data/lego] [--repeat 2]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

from provenance import commit
from windowshop.config import SceneOptions
from windowshop.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--path", default=str(ROOT.parent / "shared" / "data" / "lego"))
    parser.add_argument("--repeat", type=int, default=2, help="timed loads (the first warms the file cache)")
    args = parser.parse_args()
    times, cpu = [], []
    for _ in range(args.repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        scene = load_scene(args.path, SceneOptions())
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)  # all threads: what it costs on an idle machine
    pixels = sum(v.image.shape[0] * v.image.shape[1] for v in scene.views)
    print(json.dumps({
        "bench": "load", "path": args.path, "format": scene.format, "views": len(scene.views),
        "megapixels": round(pixels / 1e6, 2), "seconds": [round(t, 3) for t in times],
        "best_seconds": round(min(times), 3), "ms_per_view": round(1000 * min(times) / len(scene.views), 2),
        "cpu_seconds": round(min(cpu), 3), "load_average": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(), "machine": platform.machine(), "commit": commit(),
    }))


if __name__ == "__main__":
    main()
