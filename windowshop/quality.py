"""The quality report of one capture: what was used, how well it came out, and what to reshoot.

`quality_report` gathers the prepare report (photos used, dropped and unplaced, with reasons), the
fit's held-out PSNR (every 8th photo is held out), where the cameras stood around the object
(azimuth and elevation about its centre and the scene's up, +z) and what the turntable could show
(the covered arc), and turns them into concrete advice. `coverage_plot` draws the cameras'
azimuth and elevation with the unphotographed arcs marked. `windowshop video` prints the advice and
writes both beside the video; the service shows them on the job's page.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from windowshop.scene.types import Camera, Scene
from windowshop.video.coverage import FULL_TURN_SPAN, azimuths_about, gaps_between, unbroken_arc

GAP_DEGREES = 60.0  # an empty arc of azimuth at least this wide is worth walking again
FEW_PHOTOS = 12  # placed photos under this: advise more
LOW_PSNR = 20.0  # held-out PSNR (dB) under this: the model does not reproduce the photos
HIGH_ENOUGH = 20.0  # degrees of elevation: without a photo above this the top is a guess
FLAT = 10.0  # degrees: elevations all within this band came from one height


def camera_angles(cameras: list[Camera], centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(azimuths, elevations) in degrees (N,) of the cameras about `centre` (3,), up = +z; azimuth 0
    is the first camera's direction, growing counter-clockwise seen from above."""
    centres = np.stack([c.center for c in cameras]) - centre
    up = np.array([0.0, 0.0, 1.0])
    flat = centres[0] - (centres[0] @ up) * up
    reference = flat / np.linalg.norm(flat) if np.linalg.norm(flat) > 1e-9 else np.array([1.0, 0, 0])
    azimuths = azimuths_about(centres, np.zeros(3), up, reference)
    elevations = np.degrees(np.arcsin(np.clip(centres @ up / np.linalg.norm(centres, axis=1), -1, 1)))
    return azimuths, elevations


def empty_arcs(azimuths: np.ndarray, min_gap: float = GAP_DEGREES) -> list[tuple[float, float]]:
    """(from, to) degrees of every arc of azimuth at least `min_gap` wide with no camera, in order."""
    a, gaps = gaps_between(azimuths)
    return [(float(a[i]), float((a[i] + gaps[i]) % 360.0)) for i in range(len(a)) if gaps[i] >= min_gap]


def advice(report: dict) -> list[str]:
    """Concrete things to do better, from a quality report's facts (most important first)."""
    tips = []
    turned = report.get("masks") == "still"  # the phone stood still, the object turned
    swung = report.get("swung", [])
    apart = [name for name in report.get("apart", {}) if name not in swung]
    unplaced = [name for name in report.get("unplaced", []) if name not in swung + apart]
    if apart:
        share, it, shows = (("shares", "it", "it shows") if len(apart) == 1
                            else ("share", "them", "they show"))
        tips.append(f"{_names(apart)} {share} no details with the placed photos: leave {it} out "
                    f"if {shows} something else; if {shows} the object, add photos between {it} "
                    "and the others")
    if unplaced:
        tips.append(f"{_names(unplaced)} could not be placed: retake so each photo shares "
                    "most of its view with the photo before it"
                    + (" (turn the object in smaller steps)" if turned else ""))
    if swung:
        tips.append(f"{_names(swung)} could not be placed: the phone moved too far for "
                    f"{'it' if len(swung) == 1 else 'them'} while the others kept the room still: "
                    "retake holding the phone where it was for the others")
    blurred = [name for name, why in report.get("dropped", {}).items() if "blur" in why]
    if blurred:
        tips.append(f"{_names(blurred)} {'is' if len(blurred) == 1 else 'are'} blurred: hold the "
                    "phone still or use more light")
    dark = report.get("dark", [])
    if dark:  # most of them: the light, not a photo
        which = ("the photos are" if len(dark) > report.get("photos", 0) / 2
                 else f"{_names(dark)} {'is' if len(dark) == 1 else 'are'}")
        tips.append(f"{which} dark: more light, or tap the object on the phone's screen so that "
                    "it sets the exposure by it")
    if report.get("cropped"):
        tips.append("the cut-outs are cropped to the object, so where each photo was aimed is lost "
                    "and the cameras are placed less precisely: save them at the photos' full "
                    "size, or give the photos themselves")
    for start, end in report.get("empty_arcs", []):
        tips.append(f"no photos between {start:.0f}° and {end:.0f}° around the object: "
                    + ("turn that side of it to the phone" if turned else "walk that side again"))
    if report.get("placed", FEW_PHOTOS) < FEW_PHOTOS:
        tips.append(f"only {report['placed']} photos were placed: 20-40 all round give a sharper model")
    elevations = report.get("elevations")
    if elevations and max(elevations) < HIGH_ENOUGH:
        tips.append("no photo looks down on the object: add a few from higher up")
    elif elevations and np.ptp(elevations) < FLAT:
        tips.append("every photo is from the same height: add a ring from higher or lower")
    if report.get("masks") == "none":
        tips.append("the object could not be told from its surroundings: shoot it on a plain, "
                    "uncluttered surface with space around it")
    psnr = report.get("held_out_psnr")
    if psnr is not None and psnr < LOW_PSNR:
        tips.append(f"held-out photos are reproduced at only {psnr:.1f} dB: more photos, sharper "
                    "photos and even light help")
    return tips


def _names(names: list[str]) -> str:
    names = [Path(n).name for n in names]
    head = ", ".join(names[:-1])
    return f"photo {names[0]}" if len(names) == 1 else f"photos {head} and {names[-1]}"


def _swung(prepared: dict) -> list[str]:
    """The unplaced photos of prepare's report that steadying left out (a held phone that moved
    too far for them; `steadied` names them by stem)."""
    left_out = set((prepared.get("steadied") or {}).get("left_out", []))
    return [name for name in prepared.get("unplaced", []) if Path(name).stem in left_out]


def quality_report(scene: Scene, metrics: dict, render: dict, prepared: dict | None,
                   held_out: dict | None = None) -> dict:
    """The report of a capture: `prepared` is prepare's report.json (None for a posed scene),
    `metrics` the fit's held-out metrics, `render` the turntable's summary (its path plan),
    `held_out` the held-out check (windowshop.photos.verify.heldout; None when not made).
    "verified" is False when prepare's checks or the held-out one failed and --force delivered
    it all the same (None for a posed scene, which nothing here verified)."""
    train = scene.split("train")
    centre = np.asarray(scene.aabb, dtype=float).mean(axis=0)
    azimuths, elevations = camera_angles([v.camera for v in scene.views], centre)
    report = {
        "photos": (prepared or {}).get("used", len(scene.views)),
        "placed": (prepared or {}).get("placed", len(scene.views)),
        "unplaced": (prepared or {}).get("unplaced", []),
        "swung": _swung(prepared or {}),
        "apart": (prepared or {}).get("apart", {}),
        "dropped": (prepared or {}).get("dropped", {}),
        "dark": (prepared or {}).get("dark", []),
        "cropped": (prepared or {}).get("cropped", []),
        "masks": (prepared or {}).get("masks", "alpha" if scene.background == "alpha" else "none"),
        "train_photos": len(train),
        "held_out_photos": metrics.get("test_views", 0),
        "held_out_psnr": metrics.get("psnr"), "held_out_ssim": metrics.get("ssim"),
        "held_out_psnr_refined": metrics.get("psnr_refined"),
        "verified": _verified(prepared, held_out), "held_out_check": held_out,
        "azimuths": [round(float(a), 1) for a in azimuths],
        "elevations": [round(float(e), 1) for e in elevations],
        "empty_arcs": [(round(s, 1), round(e, 1)) for s, e in empty_arcs(azimuths)],
        "covered_degrees": render.get("covered_span_degrees"),
        "turntable": render,
        "priors": (prepared or {}).get("priors"),  # what the phone's sensors gave, up's source
    }
    # the photos by the names their user knows them by, not prepare's working names
    shown = {v["name"]: v["shown"] for v in (prepared or {}).get("views", []) if "shown" in v}
    names = [shown.get(Path(v.name).stem, Path(v.name).name) for v in scene.views]
    doubtful = {shown.get(Path(n).stem, n): c for n, c in _doubtful(prepared, metrics).items()}
    report["trust"] = trust(names, azimuths, elevations, doubtful, report["verified"])
    if render.get("swing"):
        report["note"] = (f"the photos cover {render['covered_span_degrees']:.0f}° of the circle "
                          f"(under {FULL_TURN_SPAN:.0f}°): the turntable swings across that arc and "
                          "back instead of showing a side nobody photographed")
    report["advice"] = advice(report)
    return report


def trust(names: list[str], azimuths: np.ndarray, elevations: np.ndarray, doubtful: dict[str, str],
          verified: bool | None) -> dict:
    """Which part of the result to trust: the widest arc of azimuth its photos cover without an
    empty arc (GAP_DEGREES, which the advice asks to walk again) and the band of elevation the
    photos on it cover, the photos a check doubted (name -> check) left out of both. "level" is
    "none" when a check failed and it was delivered by --force, "part" when the trusted photos
    cover under FULL_TURN_SPAN degrees or some were doubted, else "whole"."""
    kept = [i for i, name in enumerate(names) if name not in doubtful] or list(range(len(names)))
    start, span = unbroken_arc(azimuths[kept], GAP_DEGREES)
    kept = [i for i in kept if (azimuths[i] - start) % 360.0 <= span + 1e-6]
    level = "none" if verified is False else (
        "part" if span < FULL_TURN_SPAN or doubtful else "whole")
    found = {"level": level, "checked": verified is not None,
             "arc": [round(start, 1), round((start + span) % 360.0, 1)], "arc_degrees": round(span, 1),
             "elevations": [round(float(elevations[kept].min()), 1),
                            round(float(elevations[kept].max()), 1)],
             "doubtful": dict(sorted(doubtful.items()))}
    return found | {"summary": trust_line(found)}


def _doubtful(prepared: dict | None, metrics: dict) -> dict[str, str]:
    """Photos a check of the delivered scene blamed (prepare's chosen hypothesis, the held-out
    check's views under its threshold), name -> the check."""
    from windowshop.photos.verify.heldout import MIN_PSNR

    checks = (prepared or {}).get("verification") or {}
    chosen = [t for t in checks.get("tried", []) if t["label"] == checks.get("chosen")]
    doubtful = {Path(name).name: check["name"] for t in chosen[:1] for check in t["checks"]
                for name in check["suspects"]}
    for view in metrics.get("per_view", []):
        if view.get("psnr_refined", MIN_PSNR) < MIN_PSNR:
            doubtful.setdefault(Path(view["name"]).name, "held-out")
    return doubtful


def trust_line(trust: dict) -> str:
    """The trust of a report in words, for a terminal and the page."""
    where = (f"{trust['arc'][0]:.0f}° to {trust['arc'][1]:.0f}° around the object "
             f"({trust['arc_degrees']:.0f}°), from {trust['elevations'][0]:.0f}° to "
             f"{trust['elevations'][1]:.0f}° of elevation")
    doubted = (f"; doubted: {', '.join(f'{n} ({c})' for n, c in trust['doubtful'].items())}"
               if trust["doubtful"] else "")
    if trust["level"] == "none":
        return f"UNVERIFIED: delivered by --force although its checks failed{doubted}"
    if not trust["checked"]:
        return f"not checked (the poses were given): the photos cover {where}"
    if trust["level"] == "part":
        return f"checked in part: trust the side the photos show, {where}{doubted}"
    return f"checked: trust it all round, {where}"


def _verified(prepared: dict | None, held_out: dict | None) -> bool | None:
    checks = (prepared or {}).get("verification")
    if checks is None and held_out is None:
        return None
    return bool((checks or {}).get("verified", True) and (held_out or {}).get("passed", True))


def summary_lines(report: dict) -> list[str]:
    """The report for a terminal: a line of facts, the note, then each piece of advice."""
    psnr = report["held_out_psnr"]
    lines = [f"{report['placed']} of {report['photos']} photos placed, "
             f"{report['covered_degrees'] or 0:.0f}° of the circle covered, held-out PSNR "
             + (f"{psnr:.1f} dB on {report['held_out_photos']} photos" if psnr is not None
                else "n/a (no photo held out)")]
    lines.append(f"  {report['trust']['summary']}")
    if (report.get("priors") or {}).get("capture"):
        lines.append(f"  {report['priors']['summary']}")
    if "note" in report:
        lines.append(f"  note: {report['note']}")
    lines += [f"  advice: {tip}" for tip in report["advice"]]
    return lines


def coverage_plot(out: Path, report: dict) -> Path:
    """Where the cameras stood: azimuth around a polar plot, elevation as the distance from its
    rim (the top of the object at the centre); the empty arcs shaded red. Written to PNG `out`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(4.2, 4.2))
    ax = fig.add_subplot(projection="polar")
    az = np.radians(report["azimuths"])
    ax.scatter(az, 90.0 - np.asarray(report["elevations"]), s=18, color="tab:blue", zorder=3)
    for start, end in report["empty_arcs"]:
        span = (end - start) % 360.0
        ax.bar(np.radians(start + span / 2), 90, width=np.radians(span), bottom=0, color="tab:red",
               alpha=0.15, zorder=1)
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90], labels=["60°", "30°", "0°"])  # elevations, away from the azimuths
    ax.set_rlabel_position(202.5)
    ax.set_title("cameras around the object (red: not photographed)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def write_quality_report(out: Path, report: dict) -> tuple[Path, Path]:
    """`out` (report JSON) and the coverage plot beside it (`<stem>_coverage.png`)."""
    out.write_text(json.dumps(report, indent=2) + "\n")
    plot = coverage_plot(out.with_name(f"{out.stem.removesuffix('_report')}_coverage.png"), report)
    return out, plot
