"""What `windowshop prepare` does with each capture: right, refused, or wrong and delivered, as
JSON, one line per case as it finishes and a table at the end.

    python bench/bench_verify.py [--sets dtu_skull,temple] [--no-full | --no-subsets]
        [--count 8] [--offsets 3] [--arcs COUNT:DEGREES ...] [--only SUBSTRING]
        [--extra NAME=PATH ...]
        [--prepare KEY=VALUE ...] [--sensors] [--out results.json]

Cases: each shared capture with all its photos ("<capture>/full"), and `--offsets` subsets of
`--count` photos ("<capture>/8@k"): k = 0 is bench_fewphoto's own subset (farthest-point sampling
on the published cameras' azimuth, from the photo of least azimuth; temple: every other photo of
the ring; kermit: evenly spaced file names), k > 0 starts the sampling at the photo nearest
k / offsets of the subset's spacing further round (temple: k = 1 the odd-indexed photos, k = 2
the azimuth sampling; kermit: the file names shifted by k). beer_can gives prepare all its
photos but scores, and draws subsets from, only the frames whose published pose is trustworthy
(bench_fewphoto.beer_can); its subsets, whose photos mostly lie past the published model's first
fold, are scored against beer_can/full as this run delivered it, when that is right (run first). `--extra NAME=PATH` adds a capture from a folder with images/ and a
ground-truth transforms.json (nerfstudio, OpenGL camera-to-world; a frame's file_path stem is its
photo's stem).

`--arcs 8:100 6:60 ...` adds captures shot from one side only, the brief's usual case: for each
capture with published poses, COUNT photos spread over DEGREES of its walk, from three start
azimuths ("<capture>/arc100x8@120", arc_cases). A hull carved from one side is barely carved
in depth, and focal length and depth trade off over a narrow arc: cases the all-round subsets
do not pose.

Each case runs the real windowshop.photos.prepare.prepare (PrepareOptions() defaults, overridden
by `--prepare KEY=VALUE`, the value read as JSON when it parses, else as text) on a temporary
folder of links to its photos. Outcome:
  refused          prepare raised UserError (its message is kept);
  right            delivered, the median error of every delivered pair's relative rotation is
                   <= RIGHT_DEG and at least RIGHT_SHARE of the delivered (scored) photos are
                   correct (bench_fewphoto.correct: the photo's pose within 10 degrees and 0.2 of
                   the capture radius under the similarity the most of them agree with), and
                   the delivered up (up_error_deg, below) within UP_RIGHT_DEG of the true one:
                   right poses of an object that leans are no right result;
  wrong-delivered  delivered, and not right;
  delivered-unscored  delivered, fewer than 3 of its photos with trustworthy published poses
                   (kermit has none; beer_can's are trustworthy only on frames 0000-0013);
  error            prepare raised anything else (a bug; type and message kept).
The delivered poses are transforms.json's frames, each mapped to its photo by report.json's
"views"; report.json's "attempts" and, when present, "verification" are kept verbatim.

`--sensors` gives each case the capture.json the page's capture mode would write on a phone
(windowshop.photos.sensors), made from the published poses of its scored photos and the true
up: each photo's up in its camera frame turned by a random 1.5 deg (a steady phone's
accelerometer), its heading (the azimuth of its view about the true up) with 5 deg of noise and
a compass drift growing to 15 deg over the walk, and its order (file names). Photos without a
trustworthy published pose get no entry, so prepare uses the priors only where they cover at
least half the photos; report.json's "priors" is kept.

up_error_deg (every delivered case with known poses and a known true up): degrees between the
delivered scene's up and the true up. prepare's normalised frame has up = +z; the delivered
cameras' rotations are turned onto the published ones (windowshop.photos.align.rotation_between:
camera centres on a narrow arc leave a similarity loose, 30 deg on 6 photos over 60 deg) by the
correctly placed photos (all scored photos when fewer than 3 are correct), and the delivered +z
is mapped through that turn. The true up is:
  shared captures  windowshop.scene.cameras.up_vector(c2ws, "level") of all the capture's
                   published cameras (photos are taken level; for beer_can, its trustworthy
                   frames). dtu_skull: 2.0 deg RMS roll about it, every camera 5-70 deg above
                   the skull, and the table level in its photos: sensible (it is 28 deg from the
                   published frame's -z; DTU's frame is the scanner's, not level). temple: not
                   used: its photos are turned 90 deg (the temple lies sideways in them, every
                   right axis along the published +y), so the right axes fix no horizontal
                   plane; its true up is the published frame's +y instead, the normal of its
                   ring of cameras (all at y = 0.14..0.18) and the temple's top in its photos;
  --extra          with per-frame "gravity" (windowshop.scene.products.turned: the down
                   direction in each camera's OpenGL axes): the opposite of the mean of each
                   frame's gravity rotated into the world by its c2w; without it, world +z (the
                   rendered windowshop.scene.products captures, whose world is z-up whatever
                   their table's slope).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import bench_fewphoto as fewphoto
import subprocess
from bench_fewphoto import (DATA, beer_can, correct, dtu_skull, fruit, kermit, relative_errors,
                            spread, temple)
from provenance import emit, machine

from windowshop.config import PrepareOptions
from windowshop.errors import UserError
from windowshop.photos.align import rotation_between
from windowshop.photos.ingest import IMAGE_SUFFIXES
from windowshop.photos.prepare import prepare
from windowshop.photos.sensors import CAPTURE_FILE, FORMAT
from windowshop.scene.cameras import up_vector

RIGHT_DEG = 5.0  # a delivered scene is right when the median relative rotation error is at most
RIGHT_SHARE = 0.9  # this, and at least this share of its scored photos are correct
UP_RIGHT_DEG = 10.0  # ... and its up within this of the true up (an object seen to lean)
ARC_STARTS = (0.0, 120.0, 240.0)  # --arcs: the azimuths each one-sided case starts from
OUTCOMES = ("right", "refused", "wrong-delivered", "delivered-unscored", "error")


@dataclass
class Capture:
    """A capture's photos, and the published poses of those that have trustworthy ones."""

    name: str
    photos: list[Path]  # every photo given to prepare for the full case
    truth: dict[Path, np.ndarray | None]  # photo -> OpenGL c2w (4, 4) (None: no poses known)
    subset: object = None  # (count, offset) -> list[Path], when the capture has its own rule
    up: np.ndarray | None = None  # the true up (3,) in the truth's world frame, when known
    scored: object = None  # (photo) -> bool: whose published pose scores a delivered one
    own_reference: bool = False  # subsets scored against this bench's full-set model (below)


# beer_can's published model is folded: in azimuth about the can, its frames 0014-0034 and
# 0053-0070 lie 160-180 degrees from where a continuous walk puts them (this bench's full-set
# model: 1.5 turns, 8 degrees a frame; the backgrounds agree: a railing behind frames 0000-0011
# and 0046-0047, a wall corner behind 0020, a door behind 0026), so only the first run, before
# the published model's first jump, scores a delivered pose (bench/RESULTS.md, "Right or refused")
BEER_RELIABLE = 13  # frames 0000-0013
# ... so its subsets, whose photos mostly lie past frame 0013, are scored against this run's own
# model of all its photos instead, when that model is right on the trustworthy frames


@dataclass
class Case:
    name: str
    capture: str
    photos: list[Path]
    truth: dict[str, np.ndarray] = field(default_factory=dict)  # photo stem -> c2w
    up: np.ndarray | None = None  # the true up (3,) in the truth's world frame
    reference: str | None = None  # the full case whose delivered poses, when right, score it


def _all(reader) -> dict[Path, np.ndarray | None]:
    """Every photo a bench_fewphoto reader picks from (its `_pick` made to keep them all)."""
    pick = fewphoto._pick
    fewphoto._pick = lambda paths, c2ws, count: dict(zip(paths, c2ws))
    try:
        return reader(0)
    finally:
        fewphoto._pick = pick


def walk_azimuth(centres: np.ndarray) -> np.ndarray:
    """(N,) radians of each camera centre (N, 3) about the normal of their best-fit plane, 0 at
    its first principal axis."""
    rel = centres - centres.mean(0)
    basis = np.linalg.svd(rel, full_matrices=False)[2][:2]
    return np.arctan2(rel @ basis[1], rel @ basis[0])


def spread_from(centres: np.ndarray, count: int, offset: int, of: int) -> list[int]:
    """bench_fewphoto.spread, the farthest-point sampling started at the photo nearest
    offset / of of the subset's spacing (360 / count degrees) beyond the least azimuth
    (offset 0: spread itself)."""
    azimuth = walk_azimuth(centres)
    first = int(np.argmin(azimuth))
    target = azimuth[first] + offset * 2 * np.pi / count / of
    first = int(np.argmin(np.abs(np.angle(np.exp(1j * (azimuth - target))))))
    chosen = [first]
    while len(chosen) < count:
        gap = np.abs(np.angle(np.exp(1j * (azimuth[:, None] - azimuth[chosen][None]))))
        chosen.append(int(np.argmax(gap.min(1))))
    return sorted(chosen)


def _images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)


def _temple_subset(count: int, offset: int) -> list[Path]:
    if offset == 0:
        return sorted(temple(count))
    rows = sorted(temple(len(_images(DATA / "temple_sparse"))))  # by name: the file's order
    if offset == 1:
        return rows[1::len(rows) // count][:count]  # the odd-indexed photos of the ring
    truth = temple(len(rows))
    picks = spread(np.stack([truth[p][:3, 3] for p in rows]), count)
    return [rows[i] for i in picks]


def _kermit_subset(count: int, offset: int) -> list[Path]:
    files = sorted(kermit(len(sorted((DATA / "kermit").glob("*.jpg")))))
    base = np.linspace(0, len(files) - 1, count).round().astype(int)
    return sorted(files[(i + offset) % len(files)] for i in base)


def level_up(truth: dict[Path, np.ndarray | None]) -> np.ndarray | None:
    """up_vector(c2ws, "level") of every known camera in `truth` (module docstring)."""
    c2ws = [c for c in truth.values() if c is not None]
    return up_vector(np.stack(c2ws), "level") if len(c2ws) >= 3 else None


TEMPLE_UP = np.array([0.0, 1.0, 0.0])  # photos turned 90 deg: the ring's normal (docstring)


def shared_capture(name: str) -> Capture:
    if name == "dtu_skull":
        truth = _all(dtu_skull)
        return Capture(name, sorted(truth), truth, up=level_up(truth))
    if name == "temple":
        truth = temple(len(_images(DATA / "temple_sparse")))
        return Capture(name, sorted(truth), truth, _temple_subset, up=TEMPLE_UP)
    if name == "fruit":
        truth = _all(fruit)
        return Capture(name, sorted(truth), truth, up=level_up(truth))
    if name == "beer_can":  # all photos to prepare; subsets from the trustworthy frames
        truth = _all(beer_can)
        return Capture(name, _images(DATA / "beer_can" / "images"), truth, up=level_up(truth),
                       scored=lambda p: int(p.stem) <= BEER_RELIABLE, own_reference=True)
    if name == "kermit":
        truth = kermit(len(sorted((DATA / "kermit").glob("*.jpg"))))
        return Capture(name, sorted(truth), truth, _kermit_subset)
    raise SystemExit(f"unknown capture {name!r}; use {', '.join(fewphoto.SETS)}")


def gravity_up(frames: list[dict]) -> np.ndarray | None:
    """The true up of frames that record "gravity" (the down direction in the camera's OpenGL
    axes, windowshop.scene.products.turned): the opposite of their mean gravity in the world;
    None unless every frame has one."""
    if not frames or not all("gravity" in f for f in frames):
        return None
    down = np.mean([np.array(f["transform_matrix"], float)[:3, :3] @ np.array(f["gravity"], float)
                    for f in frames], axis=0)
    return -down / np.linalg.norm(down)


def extra_capture(name: str, folder: Path) -> Capture:
    """A folder with images/ and a ground-truth nerfstudio transforms.json; its true up from
    the frames' "gravity" when they have it, else world +z (module docstring)."""
    meta = json.loads((folder / "transforms.json").read_text())
    poses = {Path(f["file_path"]).stem: np.array(f["transform_matrix"], float)
             for f in meta["frames"]}
    photos = _images(folder / "images")
    up = gravity_up(meta["frames"])
    return Capture(name, photos, {p: poses[p.stem] for p in photos if p.stem in poses},
                   up=np.array([0.0, 0.0, 1.0]) if up is None else up)


def subset(capture: Capture, count: int, offset: int, of: int) -> list[Path]:
    if capture.subset is not None:
        return capture.subset(count, offset)
    pool = list(capture.truth)  # the reader's order, as bench_fewphoto samples it
    picks = spread_from(np.stack([capture.truth[p][:3, 3] for p in pool]), count, offset, of)
    return [pool[i] for i in picks]


def cases(capture: Capture, full: bool, subsets: bool, count: int, offsets: int) -> list[Case]:
    def case(name: str, photos: list[Path]) -> Case:
        truth = {p.stem: c for p, c in capture.truth.items() if c is not None and p in photos
                 and (capture.scored is None or capture.scored(p))}
        reference = f"{capture.name}/full" if capture.own_reference and name != "full" else None
        return Case(f"{capture.name}/{name}", capture.name, sorted(photos), truth, capture.up,
                    reference)

    out = []
    seen = set()
    for k in range(offsets if subsets else 0):
        photos = subset(capture, count, k, offsets)
        if tuple(photos) in seen:  # a start that samples the same photos again adds nothing
            print(f"{capture.name}/{count}@{k}: the same photos as an earlier subset; skipped",
                  flush=True)
            continue
        seen.add(tuple(photos))
        out.append(case(f"{count}@{k}", photos))
    if full:
        out.append(case("full", capture.photos))
    return out


def arc_cases(capture: Capture, count: int, arc: float, starts: tuple[float, ...] = ARC_STARTS
              ) -> list[Case]:
    """One side only: for each start azimuth, `count` photos spread over `arc` degrees of the
    capture's published cameras (walk_azimuth), each the photo nearest its target azimuth (none
    where the nearest unused photo lies more than two of the capture's mean steps plus 5 degrees
    off: a gap in the walk), as "<capture>/arc<arc>x<count>@<start>"; only photos with
    trustworthy poses."""
    pool = [p for p, c in capture.truth.items()
            if c is not None and (capture.scored is None or capture.scored(p))]
    if len(pool) < count:
        return []
    azimuth = np.degrees(walk_azimuth(np.stack([capture.truth[p][:3, 3] for p in pool])))
    reach = 2 * 360 / len(pool) + 5
    out = []
    for start in starts:
        chosen: list[int] = []
        for target in np.linspace(start, start + arc, count):
            off = np.abs((azimuth - target + 180) % 360 - 180)
            off[chosen] = np.inf
            if off.min() < reach:
                chosen.append(int(np.argmin(off)))
        photos = sorted(pool[i] for i in set(chosen))
        out.append(Case(f"{capture.name}/arc{arc:g}x{count}@{start:g}", capture.name, photos,
                        {p.stem: capture.truth[p] for p in photos}, capture.up))
    return out


def up_error(recovered: dict[str, np.ndarray], truth: dict[str, np.ndarray], right: set[str],
             up: np.ndarray) -> float | None:
    """Degrees between the delivered up (+z of prepare's normalised frame, where `recovered`'s
    c2ws are) and the true `up`, through the rotation turning the correctly placed photos'
    cameras (`right`; all of `recovered` when fewer than 3) onto the true ones; None when fewer
    than 3 photos can be aligned."""
    names = sorted(right) if len(right) >= 3 else sorted(recovered)
    if len(names) < 3:
        return None
    rot = rotation_between(np.stack([recovered[n][:3, :3] for n in names]),
                           np.stack([truth[n][:3, :3] for n in names]))
    mapped = rot @ np.array([0.0, 0.0, 1.0])
    cosine = mapped @ up / np.linalg.norm(up)
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def score(row: dict, delivered: dict[str, np.ndarray], truth: dict[str, np.ndarray],
          up: np.ndarray | None = None) -> None:
    """Add to `row` the delivered photos' rotation errors, the wrong ones, the outcome and,
    with the true `up`, up_error_deg."""
    recovered = {n: c for n, c in delivered.items() if n in truth}
    errors = relative_errors(recovered, truth)
    right = correct(recovered, truth)
    if up is not None:
        error = up_error(recovered, truth, right, up)
        row["up_error_deg"] = None if error is None else round(error, 2)
    median = float(np.median(errors)) if len(errors) else None
    row.update(scored=len(recovered), correct=len(right), wrong=sorted(set(recovered) - right),
               rotation_deg_median=None if median is None else round(median, 2),
               rotation_deg_max=round(float(errors.max()), 2) if len(errors) else None)
    good = (median is not None and median <= RIGHT_DEG
            and len(right) >= RIGHT_SHARE * len(recovered)
            and (row.get("up_error_deg") or 0.0) <= UP_RIGHT_DEG)
    row["outcome"] = "right" if good else "wrong-delivered"


GRAVITY_NOISE_DEG = 1.5  # --sensors: a steady phone's accelerometer ...
HEADING_NOISE_DEG = 5.0  # ... its heading's noise ...
HEADING_DRIFT_DEG = 15.0  # ... and drift over the walk


def _turned(vector: np.ndarray, degrees: float, rng: np.random.Generator) -> np.ndarray:
    """`vector` (3,) unit, turned by `degrees` about a random axis perpendicular to it."""
    axis = np.cross(vector, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    angle = np.radians(degrees)
    return vector * np.cos(angle) + np.cross(axis, vector) * np.sin(angle)


def sensor_capture(case: Case, folder: Path, seed: int = 0) -> int:
    """capture.json in `folder` as a phone would have written it for the case (module
    docstring); returns how many photos it covers."""
    if case.up is None:
        return 0
    rng = np.random.default_rng(seed)
    up = case.up / np.linalg.norm(case.up)
    east = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    entries = []
    for order, photo in enumerate(case.photos):
        c2w = case.truth.get(photo.stem)
        if c2w is None:
            continue
        seen = c2w[:3, :3].T @ up * np.array([1.0, -1.0, -1.0])  # OpenCV camera axes
        view = -c2w[:3, 2]
        heading = np.degrees(np.arctan2(view @ east, view @ north))
        heading += rng.normal(0, HEADING_NOISE_DEG) + HEADING_DRIFT_DEG * order / len(case.photos)
        entries.append({"file": photo.name, "order": order,
                        "up": _turned(seen, abs(rng.normal(0, GRAVITY_NOISE_DEG)), rng).tolist(),
                        "heading_deg": float(heading % 360.0)})
    (folder / CAPTURE_FILE).write_text(json.dumps(
        {"format": FORMAT, "version": 1, "sensors": "simulated", "photos": entries}))
    return len(entries)


def run_case(case: Case, options: PrepareOptions, sensors: bool = False,
             references: dict[str, dict[str, np.ndarray]] | None = None
             ) -> tuple[dict, dict[str, np.ndarray]]:
    """(row, delivered c2ws by photo stem): prepare on the case's photos (links in a folder of
    their own), classified and scored (against `references`[case.reference] when the case has
    one and it was delivered right); with `sensors`, the phone's capture.json beside them
    (sensor_capture)."""
    row: dict = {"case": case.name, "given": len(case.photos)}
    if not case.name.endswith("/full"):
        row["photos"] = [p.name for p in case.photos]
    with tempfile.TemporaryDirectory(prefix="bench-verify-") as tmp:
        source, out = Path(tmp) / "photos", Path(tmp) / "scene"
        source.mkdir()
        for photo in case.photos:
            (source / photo.name).symlink_to(photo.resolve())
        if sensors:
            row["sensor_photos"] = sensor_capture(case, source)
        start = time.perf_counter()
        try:
            prepare(source, out, options, show=False)
        except UserError as err:
            row.update(outcome="refused", message=str(err))
        except Exception as err:  # a bug: kept, and the next case runs
            row.update(outcome="error", message=f"{type(err).__name__}: {err}",
                       traceback=traceback.format_exc(limit=-4))
        row["seconds"] = round(time.perf_counter() - start, 1)
        if "outcome" in row:
            return row, {}
        report = json.loads((out / "report.json").read_text())
        meta = json.loads((out / "transforms.json").read_text())
    stem = {v["name"]: Path(v["photo"]).stem for v in report["views"]}
    delivered = {stem[Path(f["file_path"]).stem]: np.array(f["transform_matrix"], float)
                 for f in meta["frames"]}
    given = {p.stem for p in case.photos}
    row.update(used=report.get("used"), placed=report.get("placed"), delivered=len(delivered),
               not_delivered=sorted(given - set(delivered)),
               ring=sorted(report.get("estimated_from_ring", {})),
               dropped=report.get("dropped", {}), attempts=report.get("attempts"),
               stage_seconds=report.get("seconds"))
    truth = case.truth
    if case.reference in (references or {}):
        truth = {n: c for n, c in references[case.reference].items() if n in given}
        row["scored_against"] = f"{case.reference} as delivered (right on its published poses)"
    if len(set(delivered) & set(truth)) >= 3:
        score(row, delivered, truth, None if case.reference in (references or {}) else case.up)
    else:  # no published poses, or too few of the delivered photos have trustworthy ones
        row["outcome"] = "delivered-unscored"
    if "verification" in report:
        row["verification"] = report["verification"]
    if "priors" in report:
        row["priors"] = report["priors"]
    return row, delivered


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def options_from(pairs: list[str]) -> PrepareOptions:
    overrides = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep:
            raise SystemExit(f"--prepare {pair}: give KEY=VALUE")
        value = _value(value)
        overrides[key.replace("-", "_")] = tuple(value) if isinstance(value, list) else value
    known = {f.name for f in dataclasses.fields(PrepareOptions)}
    if unknown := set(overrides) - known:
        raise SystemExit(f"--prepare: PrepareOptions has no {', '.join(sorted(unknown))} "
                         f"(it has {', '.join(sorted(known))})")
    return PrepareOptions(**overrides)


def _arc(spec: str) -> tuple[int, float]:
    """--arcs COUNT:DEGREES as (count, degrees)."""
    count, sep, degrees = spec.partition(":")
    try:
        return int(count), float(degrees)
    except ValueError:
        raise SystemExit(f"--arcs {spec}: give COUNT:DEGREES, e.g. 8:100") from None


def worktree() -> list[str]:
    """`git status --short` of the checkout: the changes beyond the commit that ran."""
    try:
        return subprocess.run(["git", "status", "--short"], cwd=Path(__file__).parents[1],
                              capture_output=True, text=True, check=True).stdout.splitlines()
    except (OSError, subprocess.CalledProcessError):
        return []


def _verified(row: dict) -> str:
    found = row.get("verification")
    if not isinstance(found, dict):
        return "-"
    return "forced" if found.get("forced") else "yes" if found.get("verified") else "no"


def table(rows: dict[str, dict]) -> str:
    lines = [f"{'case':<24} {'outcome':<19} {'deliv/used':>10} {'correct':>7} {'med rot':>8} "
             f"{'up err':>7} {'verif':>6} {'sec':>6}  wrong / message"]
    for name, r in rows.items():
        shown = f"{r.get('delivered', 0)}/{r.get('used', r['given'])}"
        median = r.get("rotation_deg_median")
        note = (", ".join(r.get("wrong", [])) if "message" not in r
                else r["message"].split("\n")[0][:90])
        right = f"{r['correct']}/{r['scored']}" if "scored" in r else "-"
        up = r.get("up_error_deg")
        lines.append(f"{name:<24} {r['outcome']:<19} {shown:>10} {right:>7} "
                     f"{'-' if median is None else f'{median:.2f}':>8} "
                     f"{'-' if up is None else f'{up:.2f}':>7} {_verified(r):>6} "
                     f"{r['seconds']:>6.1f}  "
                     f"{note}")
    counts = Counter(r["outcome"] for r in rows.values())
    lines.append("totals: " + " / ".join(f"{o} {counts.get(o, 0)}" for o in OUTCOMES))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", default=",".join(fewphoto.SETS),
                        help="comma list of shared captures (empty: none)")
    parser.add_argument("--extra", action="append", default=[], metavar="NAME=PATH",
                        help="a folder with images/ and a ground-truth transforms.json")
    parser.add_argument("--full", action=argparse.BooleanOptionalAction, default=True,
                        help="run each capture with all its photos")
    parser.add_argument("--subsets", action=argparse.BooleanOptionalAction, default=True,
                        help="run each capture's subsets of --count photos")
    parser.add_argument("--count", type=int, default=8, help="photos in a subset")
    parser.add_argument("--offsets", type=int, default=3, help="subsets per capture")
    parser.add_argument("--arcs", nargs="*", default=[], metavar="COUNT:DEGREES",
                        help="also one side only: COUNT photos over DEGREES of each capture's "
                             "walk, from three starts (arc_cases), e.g. 8:100 6:60")
    parser.add_argument("--only", default=None, help="run only cases whose name holds this")
    parser.add_argument("--prepare", action="append", default=[], metavar="KEY=VALUE",
                        help="PrepareOptions override, e.g. masks=false")
    parser.add_argument("--sensors", action="store_true",
                        help="give each case the phone's capture.json (module docstring)")
    parser.add_argument("--out", default=None, help="also write the JSON here")
    parser.add_argument("--table", default=None, metavar="JSON",
                        help="only print the table of an earlier run's JSON")
    args = parser.parse_args()
    if args.table:
        print(table(json.loads(Path(args.table).read_text())["cases"]))
        return
    options = options_from(args.prepare)
    captures = [shared_capture(n) for n in args.sets.split(",") if n]
    for extra in args.extra:
        name, sep, path = extra.partition("=")
        if not sep:
            raise SystemExit(f"--extra {extra}: give NAME=PATH")
        captures.append(extra_capture(name, Path(path)))
    todo = [c for capture in captures
            for c in cases(capture, args.full, args.subsets, args.count, args.offsets)]
    todo += [c for spec in args.arcs for capture in captures
             for c in arc_cases(capture, *_arc(spec))]
    referenced = {c.reference for c in todo if args.only is None or args.only in c.name}
    # the quick subsets first, after any full case that scores them
    todo = sorted((c for c in todo if args.only is None or args.only in c.name
                   or c.name in referenced),
                  key=lambda c: 0 if c.name in referenced else 1 + c.name.endswith("/full"))
    results = {**machine(), "worktree": worktree(), "options": dataclasses.asdict(options),
               "right_deg": RIGHT_DEG, "right_share": RIGHT_SHARE, "sensors": args.sensors,
               "cases": {}}
    references: dict[str, dict[str, np.ndarray]] = {}
    for case in todo:
        row, delivered = run_case(case, options, args.sensors, references)
        if case.name in referenced and row["outcome"] == "right":
            references[case.name] = delivered
        results["cases"][case.name] = row
        print(json.dumps(row), flush=True)
        if args.out:  # kept as it grows, for a run that is stopped
            Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
    results["totals"] = dict(Counter(r["outcome"] for r in results["cases"].values()))
    emit(results, args.out)
    print(table(results["cases"]), flush=True)


if __name__ == "__main__":
    main()
