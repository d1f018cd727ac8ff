"""A study's results.csv and REPORT.md: the table in the layout of the seed's Table 2 beside the
published numbers, PSNR against images and against training time, and a contact sheet of one
held-out view rendered by every combination (the seed's Figure 5)."""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from windowshop.study.grids import Grid
from windowshop.study.records import TRUTH, VIEW, ResultRow, StudyInfo

RESULTS = "results.csv"
REPORT = "REPORT.md"
PLOT_IMAGES = "psnr_vs_images.png"
PLOT_TIME = "psnr_vs_time.png"
SHEET = "contact_sheet.png"
LABELS = {"model": "Model", "preset": "Preset", "views": "Images", "freqs": "L",
          "freqs_dir": "L_dir", "n_coarse": "N_c", "n_fine": "N_f", "view_dependent": "View dep.",
          "batch_rays": "Rays/step"}
SHEET_COLUMNS = 6
MIN_TILE = 96  # pixels: smaller renders are enlarged so their labels fit


def fmt(value, digits: int = 2) -> str:
    """A table cell: yes/no, a dash for missing, floats rounded."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def published_keys(rows: list[ResultRow]) -> list[str]:
    """The published metrics any row carries, PSNR first."""
    keys = sorted({key for row in rows for key in row.published})
    return sorted(keys, key=lambda k: (k != "psnr", k != "ssim", k))


def write_results_csv(path: Path, grid: Grid, rows: list[ResultRow]) -> Path:
    """One line per combination: its varied switches, metrics, timings, the published numbers."""
    extra = published_keys(rows)
    fields = (["index", "name", *grid.columns, "train_views", "test_views", "iterations",
               "train_seconds", "seconds_per_iter", "psnr", "ssim", "eval_seconds"]
              + [f"published_{k}" for k in extra] + ["status", "machine", "folder"])
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            record = {**{k: row.settings.get(k) for k in grid.columns},
                      **{k: v for k, v in dataclasses.asdict(row).items() if k in fields},
                      **{f"published_{k}": row.published.get(k) for k in extra}}
            writer.writerow(record)
    return path


def _group(row: ResultRow, grid: Grid) -> str:
    """The row's settings other than the number of images (one line per group in the plots)."""
    parts = [f"{LABELS.get(k, k)}={fmt(row.settings.get(k))}" for k in grid.columns if k != "views"]
    return ", ".join(parts) or "all"


def _scatter(rows: list[ResultRow], grid: Grid, x_of, xlabel: str, path: Path,
             log_x: bool = False, lines: bool = False) -> Path:
    """PSNR of `rows` against `x_of(row)`, one colour per group, labelled by index. With `lines`
    (for an x the paper shares, the number of images) each group's points are joined and the
    published PSNR is drawn hollow at the same x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.8), dpi=80)
    groups = list(dict.fromkeys(_group(r, grid) for r in rows))
    colours = plt.get_cmap("tab10")
    for g, name in enumerate(groups):
        members = sorted((r for r in rows if _group(r, grid) == name and r.psnr is not None), key=x_of)
        xs, ys = [x_of(r) for r in members], [r.psnr for r in members]
        ax.plot(xs, ys, "o-" if lines else "o", color=colours(g % 10), label=name, markersize=5)
        for r, x, y in zip(members, xs, ys):
            ax.annotate(str(r.index), (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
        if lines:
            pub = [(x_of(r), r.published["psnr"]) for r in members if "psnr" in r.published]
            if pub:
                ax.plot(*zip(*pub), "o--", mfc="none", color=colours(g % 10), alpha=0.6, markersize=6)
    if lines and any("psnr" in r.published for r in rows):
        ax.plot([], [], "o--", mfc="none", color="grey", label=f"published ({grid.reference})")
    if log_x:
        ax.set_xscale("log")
        ticks = sorted({x_of(r) for r in rows})
        ax.set_xticks(ticks, [str(t) for t in ticks])
        ax.minorticks_off()
    ax.set_xlabel(xlabel)
    ax.set_ylabel("held-out PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_psnr_vs_images(rows: list[ResultRow], grid: Grid, path: Path) -> Path:
    return _scatter(rows, grid, lambda r: r.train_views, "training images", path, log_x=True,
                    lines=True)


def plot_psnr_vs_time(rows: list[ResultRow], grid: Grid, path: Path) -> Path:
    return _scatter(rows, grid, lambda r: r.train_seconds, "training seconds", path)


def _tile(image: Image.Image, label: str, size: int) -> Image.Image:
    """`image` enlarged to `size` pixels wide with `label` written under it."""
    image = image.convert("RGB").resize((size, round(image.height * size / image.width)), Image.NEAREST)
    tile = Image.new("RGB", (size, image.height + 14), "white")
    tile.paste(image, (0, 0))
    ImageDraw.Draw(tile).text((2, image.height + 2), label, fill="black", font=ImageFont.load_default())
    return tile


def contact_sheet(out_dir: Path, rows: list[ResultRow], path: Path) -> Path | None:
    """The true held-out view, then every combination's render of it, in a labelled grid."""
    items = [(out_dir / TRUTH, "truth")] + [
        (out_dir / row.folder / VIEW, f"#{row.index} {fmt(row.psnr, 1)} dB") for row in rows]
    items = [(p, label) for p, label in items if p.is_file()]
    if len(items) < 2:
        return None
    images = [(Image.open(p), label) for p, label in items]
    size = max(MIN_TILE, images[0][0].width)
    tiles = [_tile(image, label, size) for image, label in images]
    columns = min(SHEET_COLUMNS, len(tiles))
    height = max(t.height for t in tiles)
    sheet = Image.new("RGB", (columns * size, math.ceil(len(tiles) / columns) * height), "white")
    for i, tile in enumerate(tiles):
        sheet.paste(tile, ((i % columns) * size, (i // columns) * height))
    sheet.save(path, optimize=True)
    return path


def rank_correlation(a: list[float], b: list[float]) -> float | None:
    """Spearman's rank correlation of two equal-length lists (None for fewer than 3 pairs)."""
    if len(a) < 3:
        return None
    ranks = [np.argsort(np.argsort(v)).astype(float) for v in (a, b)]
    if ranks[0].std() == 0 or ranks[1].std() == 0:
        return None
    return float(np.corrcoef(*ranks)[0, 1])


def machines_of(rows: list[ResultRow]) -> list[str]:
    """The distinct machines the rows were finished on, in order of first appearance."""
    return list(dict.fromkeys(row.machine or "unknown" for row in rows))


def results_table(grid: Grid, rows: list[ResultRow]) -> list[str]:
    """The Markdown table: the combination's switches, our measurements, the published numbers."""
    extra = [k for k in published_keys(rows) if k in ("psnr", "ssim")]
    machines = machines_of(rows)
    head = (["#", *[LABELS.get(k, k) for k in grid.columns], "Iterations", "PSNR", "SSIM",
             "Train s", "s / iter"] + [f"{grid.reference or 'published'} {k.upper()}" for k in extra]
            + (["Machine"] if len(machines) > 1 else []))
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = ([str(row.index), *[fmt(row.settings.get(k)) for k in grid.columns],
                  str(row.iterations), fmt(row.psnr), fmt(row.ssim, 3), fmt(row.train_seconds, 1),
                  fmt(row.seconds_per_iter, 3)]
                 + [fmt(row.published.get(k), 2 if k == "psnr" else 3) for k in extra]
                 + ([f"M{machines.index(row.machine or 'unknown') + 1}"] if len(machines) > 1 else []))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _findings(rows: list[ResultRow], grid: Grid) -> list[str]:
    """A few facts read off the table (no judgement)."""
    measured = [r for r in rows if r.psnr is not None]
    if not measured:
        return []
    best = max(measured, key=lambda r: r.psnr)
    fastest = min(measured, key=lambda r: r.seconds_per_iter)
    lines = [f"- Highest PSNR: #{best.index} `{best.name}`, {best.psnr:.2f} dB.",
             f"- Fastest steps: #{fastest.index} `{fastest.name}`, {fastest.seconds_per_iter:.3f} s per "
             f"iteration."]
    pairs = [(r.psnr, r.published["psnr"]) for r in measured if "psnr" in r.published]
    rho = rank_correlation(*zip(*pairs)) if len(pairs) >= 3 else None
    if rho is not None:
        lines.append(f"- Rank correlation (Spearman) of our PSNR with {grid.reference}'s over "
                     f"{len(pairs)} rows: {rho:+.2f} (+1: the same order).")
    return lines


def _span(values: list) -> str:
    """'a' or 'a to b' of the smallest and largest of `values`."""
    if not values:
        return "—"
    low, high = min(values), max(values)
    return fmt(low, 1) if low == high else f"{fmt(low, 1)} to {fmt(high, 1)}"


def _load_line(rows: list[ResultRow]) -> list[str]:
    """The CPU's load average when the runs started, if they ran on a CPU (timings depend on it)."""
    loads = [r.load for r in rows if r.load is not None and r.machine.startswith("CPU")]
    if not loads:
        return []
    return [f"- Load average of the machine when the runs started: {_span(loads)} (other work "
            f"on the machine slows the timings)"]


def report_markdown(grid: Grid, rows: list[ResultRow], info: StudyInfo, files: dict[str, Path | None]) -> str:
    """The text of REPORT.md; `files` maps plot names to the images written (None: none)."""
    overrides = {k: v for k, v in info.overrides.items() if k not in ("iters", "seconds")}
    test_views = sorted({r.test_views for r in rows})
    machines = machines_of(rows)
    if len(machines) > 1:  # a study resumed elsewhere: say so, never mix timings silently
        machine = "runs from several machines, see the table's last column: " + "; ".join(
            f"M{i + 1} = {m}" for i, m in enumerate(machines))
    else:
        machine = machines[0] if machines else info.machine
    lines = [f"# Study `{grid.name}` on `{Path(info.scene).name}`", "", grid.description, "",
             f"- Machine: {machine}; device `{info.device}`; torch {info.torch}",
             *_load_line(rows),
             f"- Budget: {info.budget}",
             f"- Set on every run: {', '.join(f'{k}={v}' for k, v in overrides.items()) or 'nothing'}",
             f"- Scene: `{info.scene}`; PSNR and SSIM are means over "
             f"{'/'.join(map(str, test_views)) or '—'} held-out view{'' if test_views == [1] else 's'}",
             f"- Runs finished {_span([r.finished for r in rows if r.finished])}; {len(rows)} of "
             f"{len(grid.combinations)} combinations done; this report written by a call started "
             f"{info.started}",
             *( [f"- Command: `{info.command}`"] if info.command else []), "",
             "Training seconds count only the optimisation steps (not loading, evaluation or "
             "rendering). Published numbers come from other machines, budgets and code: compare "
             "trends, not values.", "", "## Results (the layout of the seed's Table 2)", "",
             *results_table(grid, rows), "", *_findings(rows, grid), ""]
    for key, title in [("images", "PSNR against the number of training images"),
                       ("time", "PSNR against training time")]:
        if files.get(key):
            lines += [f"## {title}", "", f"![{title}]({files[key].name})", ""]
    if files.get("sheet"):
        lines += ["## One held-out view rendered by every combination (the seed's Figure 5)", "",
                  f"![contact sheet]({files['sheet'].name})", "",
                  "The first tile is the true image; each other is labelled with its combination "
                  "and its mean held-out PSNR.", ""]
    lines += ["## Runs", "", "Each combination is an ordinary run folder (`windowshop eval RUN`, "
              "`windowshop render RUN --out turntable.mp4` work on it):", ""]
    lines += [f"- #{r.index}: `{r.folder}` ({r.status})" for r in rows]
    return "\n".join(lines) + "\n"


def write_report(out_dir: str | Path, grid: Grid, rows: list[ResultRow], info: StudyInfo) -> Path:
    """Write results.csv, the plots, the contact sheet and REPORT.md into `out_dir`."""
    out_dir = Path(out_dir)
    write_results_csv(out_dir / RESULTS, grid, rows)
    measured = [r for r in rows if r.psnr is not None]
    files = {"images": plot_psnr_vs_images(measured, grid, out_dir / PLOT_IMAGES) if measured else None,
             "time": plot_psnr_vs_time(measured, grid, out_dir / PLOT_TIME) if measured else None,
             "sheet": contact_sheet(out_dir, rows, out_dir / SHEET)}
    path = out_dir / REPORT
    path.write_text(report_markdown(grid, rows, info, files))
    return path
