"""Plot bench_fast.py's PSNR-against-seconds curves: one panel per row, fast next to nerf tiny.

Usage: python bench/bench_fast.py --rows tiny lego100 > fast.jsonl
       python bench/plot_fast.py fast.jsonl --out fast.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the non-interactive backend)

MODELS = {"fast": "fast", "nerf_tiny": "nerf --preset tiny"}


def races(rows: list[dict]) -> list[tuple[str, dict, float | None]]:
    """(title, race, target PSNR) for every training race in the benchmark rows (fewer has one per
    view count, with the few-photo priors on and off)."""
    out = []
    for row in rows:
        if "fast" in row:
            out.append((f"{row['row']}, {row['seconds']:g} s", row, row.get("target_psnr")))
        runs = row.get("runs", [])
        views = list(dict.fromkeys(run["views"] for run in runs))  # the counts, in the row's order
        targets = dict(zip(views, row.get("target_psnr") or [])) if runs else {}
        for run in runs:
            priors = "priors on" if run["priors"] else "priors off"
            out.append((f"{row['row']}: {run['views']} views, {priors}", run,
                        targets.get(run["views"]) if run["priors"] else None))
    return out


def plot(rows: list[dict], path: Path) -> Path:
    """Draw every race's curves into `path` (PNG)."""
    panels = races(rows)
    if not panels:
        raise SystemExit("no training rows with curves in the input")
    columns = min(3, len(panels))
    rows_ = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows_, columns, figsize=(4.4 * columns, 3.4 * rows_), squeeze=False)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax, (title, race, target) in zip(axes.flat, panels):
        for key, label in MODELS.items():
            if key in race:
                curve = race[key]["curve"]
                ax.plot([p["seconds"] for p in curve], [p["psnr"] for p in curve], "o-", label=label)
        if target:
            ax.axhline(target, color="grey", linestyle="--", linewidth=1, label=f"target {target:g}")
        ax.set_title(title)
        ax.set_xlabel("training seconds")
        ax.set_ylabel("held-out PSNR (dB)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", help="bench_fast.py output: one JSON object per line")
    parser.add_argument("--out", default="fast_curves.png")
    args = parser.parse_args()
    rows = [json.loads(line) for line in Path(args.results).read_text().splitlines() if line.strip()]
    print(plot(rows, Path(args.out)))


if __name__ == "__main__":
    main()
