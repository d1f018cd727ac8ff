"""The prepare report: `report.json` (what was used, dropped and placed, how well, how long) and
`cameras.png` (the cameras around the object box, seen from the side and from above)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from windowshop.scene.plot import box_lines, frustum_lines
from windowshop.scene.types import Camera

# report.json's words for the photos the turntable prior placed (windowshop.photos.fill)
RING_NOTES = {
    "paired": "estimated from the ring, not measured: its rotation and direction from a "
              "neighbouring photo, its distance from the ring of the placed photos",
    "guessed": "estimated from the ring, not measured: put between its neighbours in file "
               "order on the ring of the placed photos, looking at the centre",
}


def write_report(out_dir: Path, report: dict) -> Path:
    """`report.json` in `out_dir`."""
    path = out_dir / "report.json"
    path.write_text(json.dumps(report, indent=2))
    return path


def summary_lines(report: dict) -> list[str]:
    """A few lines for the terminal."""
    lines = [(f"placed {report['placed']} of {report['used']} photos "
              f"(mean reprojection error {report['reprojection_error_px']:.2f} px)")]
    lines += [f"  dropped {name}: {why}" for name, why in report["dropped"].items()]
    if report.get("cropped"):
        lines.append(f"  cut-outs cropped to the object: {len(report['cropped'])} of "
                     f"{report['used']} photos")
    if report.get("dark"):
        lines.append(f"  dark (too little light): {len(report['dark'])} of {report['used']} photos")
    if report.get("exposures"):
        most = max(max(v, 1.0 / v) for e in report["exposures"].values() for v in e)
        lines.append(f"  exposure and white balance evened out on {len(report['exposures'])} of "
                     f"{report['placed']} photos (the furthest off by a factor of {most:.2f})")
    ring = report.get("estimated_from_ring", {})
    if ring:
        lines.append(f"  estimated from the ring of the others, not measured: {', '.join(ring)}")
    if report["unplaced"]:
        lines.append(f"  could not place: {', '.join(report['unplaced'])}")
    if report["unplaced"] or ring:
        lines += [f"    {name}: {advice}" for name, advice in report.get("reshoot", {}).items()]
    if report["masks"] != "none":
        how = {"given": "the photos' own transparency", "colour": "the plain background",
               "segmented": "colour, seeded by the object's points above the surface it stands on",
               "still": "colour, seeded by the object's points and by the backdrop that stays "
                        "put behind it (the phone stayed in one place while the object turned)",
               "rembg": "rembg's matting"}
        lines.append(f"  foreground masks made from {how[report['masks']]}")
    if report.get("steadied"):
        left, top = report["steadied"]["box"][:2]
        lines.append(f"  the phone moved a little between photos (held in the hand): each photo "
                     f"was moved to keep the room still, and cut by {left} px at each side and "
                     f"{top} px at the top and bottom")
    if report.get("priors", {}).get("capture"):
        lines.append(f"  {report['priors']['summary']}")
    return lines + _verification_lines(report.get("verification"))


def _verification_lines(verification: dict | None) -> list[str]:
    """What the verifier found (windowshop.photos.hypotheses): nothing when the first model
    passed, the hypothesis kept when another did, and every failed check when forced."""
    if not verification or len(verification["tried"]) == 1 and verification["verified"]:
        return []
    chosen = next(t for t in verification["tried"] if t["label"] == verification["chosen"])
    if verification["verified"]:
        return [f"  checked: kept {chosen['label']} (tried {len(verification['tried'])} ways)"]
    return ["  UNVERIFIED (delivered by --force): "
            + "; ".join(c["detail"] for c in chosen["checks"] if not c["passed"])]


# what to reshoot for a held phone's photo that steadying left out (windowshop.photos.still)
SWUNG = ("the phone moved too far for it while the others kept the room still: retake it "
         "holding the phone where it was for the others")


def reshoot(shown: list[str], unplaced: list[str], apart: dict[str, list[str]] | None = None
            ) -> dict[str, str]:
    """What to reshoot for each photo that could not be placed: `shown` are all photos' names in
    the order taken (file-name order), `unplaced` the ones without a pose. A photo is placed by
    what it shares with others, so the advice names its placed neighbours in that order. `apart`
    holds the unplaced photos that share nothing with any placed one, each with the photos it
    does match: a photo of something else, or of a side no photo links to the rest."""
    missing, apart = set(unplaced), apart or {}
    advice = {}
    for i, name in enumerate(shown):
        if name not in missing:
            continue
        if name in apart:
            advice[name] = _apart_advice(apart[name])
            continue
        before = next((n for n in reversed(shown[:i]) if n not in missing), None)
        after = next((n for n in shown[i + 1:] if n not in missing), None)
        between = " and ".join(n for n in (before, after) if n is not None)
        advice[name] = ("it shares too few details with the others: retake it, and add a photo "
                        f"or two between it and {between}" if between else
                        "it shares too few details with the others: retake it")
        advice[name] += " (steps of 10-15 degrees around the object, the whole object in view)"
    return advice


def _apart_advice(matches: list[str]) -> str:
    if not matches:
        return ("it shares no details with any other photo: leave it out if it shows something "
                "else; if it shows the object, retake it with the whole object in view, a step of "
                "10-15 degrees from another photo")
    return (f"it matches only {' and '.join(matches)}, none of the placed photos: leave them out "
            "if they show something else; if they show another side of the object, add photos "
            "between that side and the others (steps of 10-15 degrees)")


def plot_cameras(out: Path, cameras: list[Camera], aabb: np.ndarray, points: np.ndarray) -> Path:
    """Draw the cameras (normalised frame) as frusta around the box `aabb` (2, 3), with the
    object's sparse `points` (P, 3), from the side and from above, into the PNG `out`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    depth = 0.15 * float(np.median([np.linalg.norm(c.center) for c in cameras]))
    fig = plt.figure(figsize=(10, 5))
    for i, (elev, azim, title) in enumerate([(20, -60, "cameras around the object"),
                                             (90, -90, "from above")]):
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        # one collection for all frusta: a plot call a segment takes seconds for 100 cameras
        frusta = [seg for cam in cameras for seg in frustum_lines(cam, depth)]
        ax.add_collection3d(Line3DCollection(frusta, colors="tab:blue", linewidths=0.6))
        ax.add_collection3d(Line3DCollection(list(box_lines(aabb)), colors="tab:red",
                                             linewidths=1.0))
        if len(points):
            ax.scatter(*points.T, s=1, color="k", alpha=0.4)
        everything = np.concatenate([np.stack([c.center for c in cameras]), aabb])
        mid, half = everything.mean(0), 0.55 * np.ptp(everything, axis=0).max()
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)
        ax.set_zlim(mid[2] - half, mid[2] + half)
        ax.view_init(elev=elev, azim=azim)
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
