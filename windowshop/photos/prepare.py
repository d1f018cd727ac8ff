"""`windowshop prepare`: photos (a folder or zip) or a video -> a posed scene folder.

    input ──gather──> photos (upright, working size; duplicates and blur dropped)
          ──pycolmap──> intrinsics and poses (retried with relaxed settings)
          ──object──> support plane (up = its normal) and the points above it that most views
                      see, masks (colour on a plain background, else GrabCut seeded by those
                      points; both cut to the views' visual hull), the box from that hull,
                      normalised frame (object at the origin, up = +z, box in [-1, 1]^3)
          ──write──> transforms.json, images/, masks/, colmap/, report.json, cameras.png

The user's files are only read; all scratch work happens in a temporary folder.
"""

from __future__ import annotations

import contextlib
import json
import math
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path, PurePosixPath

import numpy as np

from windowshop.config import PrepareOptions
from windowshop.errors import UserError
from windowshop.media import VIDEO_SUFFIXES
from windowshop.photos import (hypotheses, matting_rembg, objectbox, offplane, output, plane,
                               report, orient, segment, sensors, still)
from windowshop.photos.exposure import evened, negligible, photo_exposures
from windowshop.photos.frames import sample_frames
from windowshop.photos.ingest import (Dropped, Inputs, Photo, check_enough, gather_inputs,
                                     read_photos, underexposed)
from windowshop.photos.located import Located
from windowshop.photos.pairs import MATCHERS
from windowshop.photos.progress import StageCallback, Stages
from windowshop.photos.sfm import MIN_KEYPOINTS, SfmResult, SfmSettings, reconstruct
from windowshop.photos.verify.silhouettes import FIT_VIEWS
from windowshop.rays import project
from windowshop.scene import normalize
from windowshop.scene.cameras import agreed_level, nearest_point_to_axes
from windowshop.scene.nerfstudio import WRITER_KEY

SEARCH_GROW = 0.3  # masks are sought in the points' box grown by this share of its size ...
BACKGROUND_GROW = 0.2  # ... and sparse points this share of the box size outside that are not it
MIN_PLACED_SHARE = 0.5  # fewer photos placed than this share (or than 3, or FIT_VIEWS): fails
# Share of the "prepare" progress each stage covers (retries add time but no progress).
SHARES = {"reading photos": 0.1, "sampling video frames": 0.1, "finding features": 0.3,
          "matching": 0.2, "placing cameras": 0.25, "finding and checking the object": 0.05,
          "writing the scene": 0.1}
VIDEO_AMONG_PHOTOS = ("a video among photos: a folder is read as photos or as one video, not "
                      "both; give the video alone to use it")
STEADY = "steady"  # the scratch folder of steadied photos (prepare._steady)
OUTPUTS = ("transforms.json", "report.json", "cameras.png", "images", "masks", "colmap")


@dataclass
class PrepareResult:
    out_dir: Path
    transforms: Path
    report: dict


def check_out_dir(source: Path, out_dir: Path, overwrite: bool) -> None:
    """Refuse an output folder that would touch the input, or an earlier result not to replace."""
    src, out = source.resolve(), out_dir.resolve()
    if out == src or src in out.parents or out in src.parents:
        raise UserError(f"{out_dir}: the output folder must be outside the input {source} "
                        f"(the input is never modified); choose another --out")
    if not out.exists() or not any(out.iterdir()):
        return
    ours = out / "transforms.json"
    if overwrite and ours.is_file() and WRITER_KEY in json.loads(ours.read_text()):
        for name in OUTPUTS:
            target = out / name
            shutil.rmtree(target) if target.is_dir() else target.unlink(missing_ok=True)
        return
    raise UserError(f"{out_dir}: already exists and is not empty; choose a new --out folder"
                    + ("" if overwrite else " (or pass --overwrite to replace an earlier prepare)"))


def _read(inputs: Inputs, options: PrepareOptions, stages: Stages) -> tuple[list[Photo], Dropped]:
    """The usable photos (or video frames) at working size."""
    dropped = Dropped()
    if inputs.kind == "video":
        with stages.stage("sampling video frames", options.video_frames) as advance:
            photos = sample_frames(inputs.files[0], options.video_frames, options.max_side, advance)
        check_enough(photos, dropped, what="video frames")
        return photos, dropped
    videos = [n for n in inputs.ignored if PurePosixPath(n).suffix.lower() in VIDEO_SUFFIXES]
    if not inputs.files and videos:
        raise UserError(f"{len(videos)} videos found ({', '.join(videos)}): give one video at a "
                        f"time, or the photos")
    if not inputs.files:
        raise UserError("no photos found (JPEG, PNG, WebP or HEIC files); give a folder or zip "
                        "of photos, or a video")
    # named as a dropped photo is: with four photos beside it, "only 4 usable photos" alone left
    # the user wondering why the video did not count; but not a Live Photo's own clip, which
    # a phone exports beside its photo under the same name (IMG_0001.HEIC and IMG_0001.MOV)
    stems = {f.with_suffix("") for f in inputs.files}
    dropped.reasons.update({name: VIDEO_AMONG_PHOTOS for name in videos
                            if (inputs.root / name).with_suffix("") not in stems})
    with stages.stage("reading photos", len(inputs.files)) as advance:
        return read_photos(inputs.files, options.max_side, dropped, advance), dropped


def _priors(inputs: Inputs, photos: list[Photo]) -> sensors.Priors | None:
    """What the phone knew (capture.json beside the photos), by photo name; the photos are put
    in shooting order. None without a capture.json."""
    if inputs.capture is None:
        return None
    priors = sensors.read_capture(inputs.capture, {p.source.name: p.name for p in photos})
    order = {name: i for i, name in enumerate(p.name for p in photos)}
    photos.sort(key=lambda p: (priors.order.get(p.name, len(photos)), order[p.name]))
    return priors


def _cutouts(photos: list[Photo]) -> dict[str, np.ndarray] | None:
    """Each photo's own outline by image file name when every photo is a cut-out, else None
    (a few cut-outs among plain photos are masked as the others are)."""
    if not all(p.cutout is not None for p in photos):
        return None
    return {f"{p.name}.jpg": p.cutout for p in photos}


def _cropped(photos: list[Photo]) -> list[str]:
    """The cut-outs, when they come in more than one size: cropped to the object, each photo
    loses where its centre was, which the cameras' placing needs (dtu_skull's 12 photos cut out
    and cropped so: 5.4 deg median rotation error, against 0.7 at full size)."""
    cutouts = [p for p in photos if p.cutout is not None]
    return ([p.shown for p in cutouts] if len({p.pixels.shape for p in cutouts}) > 1
            else [])


def _gravity(priors: sensors.Priors | None, photos: list[Photo]) -> dict[str, np.ndarray] | None:
    """The phone's up of each photo by image file name, when enough photos carry it."""
    if priors is None or not priors.usable([p.name for p in photos], priors.up):
        return None
    return {f"{name}.jpg": up for name, up in priors.up.items()}


def _settings(inputs: Inputs, photos: list[Photo], options: PrepareOptions,
              priors: sensors.Priors | None = None) -> SfmSettings:
    """Matcher, shared camera, known intrinsics (scaled to working pixels) and the phone's
    headings for pycolmap."""
    matcher = options.matcher
    if matcher == "auto" and inputs.kind == "video":
        matcher = "sequential"  # photos: by count and order (windowshop.photos.pairs)
    if matcher not in ("auto",) + MATCHERS:
        raise UserError(f"unknown matcher {matcher!r}; use {', '.join(MATCHERS)} or auto")
    # one camera for the photos of one lens, those held the other way turned to match (a camera
    # per photo is a lottery on few photos: bench/RESULTS.md, stop 54)
    turned = orient.turned_names(photos)
    lenses: dict[tuple, set[str]] = {}
    for p in photos:
        lenses.setdefault(orient.sfm_key(p, f"{p.name}.jpg" in turned), set()).add(f"{p.name}.jpg")
    cameras = tuple(frozenset(names) for names in lenses.values()) if len(lenses) > 1 else ()
    intrinsics = None
    if options.intrinsics is not None:
        if len({(p.pixels.shape, round(p.scale, 6)) for p in photos}) != 1:
            raise UserError("--intrinsics applies to photos of one size, but these differ in size")
        intrinsics = tuple(float(v) * photos[0].scale for v in options.intrinsics)
        cameras = ()
    headings = None
    if priors is not None and priors.usable([p.name for p in photos], priors.heading):
        headings = tuple(priors.heading.get(p.name) for p in photos)
    return SfmSettings(matcher=matcher, intrinsics=intrinsics, cameras=cameras,
                       seed=options.seed, verbose=options.verbose, headings=headings,
                       turned=turned)


def check_placed(sfm: SfmResult, count: int, shown: dict[str, str]) -> None:
    """UserError when the photos lack texture, or too few of them could be placed; `shown` maps
    image file names to the names the user knows (their files)."""
    poor = sorted(shown[name] for name, k in sfm.keypoints.items() if k < MIN_KEYPOINTS)
    texture = (f"the background has too little texture: fewer than {MIN_KEYPOINTS} features in "
               f"{len(poor)} of {count} photos ({', '.join(poor[:10])}"
               f"{' ...' if len(poor) > 10 else ''}); "
               f"photograph the object on a patterned surface (a newspaper, a printed cloth) "
               f"with detail around it")
    if count - len(poor) < 3:
        raise UserError(texture)
    # below FIT_VIEWS the verifier's outlines cannot tell a right model from a wrong one (the
    # hull of three covers any mask: right 4-photo models fit 0.51-0.94, wrong ones 0.07-0.84)
    need = max(3, min(count, FIT_VIEWS), math.ceil(MIN_PLACED_SHARE * count))
    if len(sfm.placed) >= need:
        return
    missing = sorted(sfm.unplaced + sfm.guessed)  # posed by the ring alone is not enough
    names = ", ".join(shown[n] for n in missing[:20])
    names += " ..." if len(missing) > 20 else ""
    raise UserError(f"could only place {len(sfm.placed)} of {count} photos ({need} are needed to "
                    f"check the model); not placed: {names}. "
                    f"Take more photos with overlap: walk around the object in small steps "
                    f"(10-15 degrees) so that each photo shares most of its view with the next"
                    + (f". Also, {texture}" if len(poor) > count // 4 else ""))


def _views(sfm: SfmResult, photos: list[output.PosedPhoto], pixels: dict[str, np.ndarray],
           labels: dict[int, int]) -> list[segment.View]:
    """Each photo with the pixels of the sparse points it observes, by `labels` (point id ->
    1 for the object's, 0 for the background's; others are left out)."""
    views = []
    for p in photos:
        image = sfm.reconstruction.find_image_with_name(p.image_name)
        seen = [(labels.get(q.point3D_id, -1), q.xy) for q in image.points2D if q.has_point3D()]
        uv = {k: np.array([xy for label, xy in seen if label == k]).reshape(-1, 2) for k in (0, 1)}
        if p.image_name in sfm.turned:
            uv = {k: orient.photo_xy(xy, p.camera.width) for k, xy in uv.items()}
        views.append(segment.View(p.name, pixels[p.image_name], p.camera, uv[1], uv[0]))
    return views


def _labels(points: np.ndarray, ids: np.ndarray, isolated: plane.Isolated,
            transform: np.ndarray, aabb: np.ndarray) -> dict[int, int]:
    """Point id -> 1 for the object's points, 0 for points surely off it: on the support plane,
    or well outside the object box (normalised `aabb`); points (P, 3) in the COLMAP frame."""
    moved = points @ transform[:3, :3].T + transform[:3, 3]
    grow = BACKGROUND_GROW * (aabb[1] - aabb[0])
    off = np.any((moved < aabb[0] - grow) | (moved > aabb[1] + grow), axis=1)
    if isolated.plane is not None:
        off |= np.abs(isolated.plane.height(points)) <= isolated.plane.tolerance
    labels = {int(i): 0 for i in ids[off]}
    labels.update({int(i): 1 for i in ids[isolated.index]})
    return labels


def _looked_at(views: list[segment.View]) -> list[segment.View]:
    """The views with the point their axes meet as the object's one sure pixel."""
    target = nearest_point_to_axes(np.stack([v.camera.c2w for v in views]))
    return [replace(v, object_uv=project(target[None], v.camera)[0]) for v in views]


def find_masks(views: list[segment.View], search: np.ndarray, matting: str,
               given: list[np.ndarray] | None = None
               ) -> tuple[dict[str, np.ndarray], str, np.ndarray | None, dict[str, np.ndarray]]:
    """(photo name -> (H, W) bool mask, how they were made: "given", "rembg", "colour",
    "segmented" or "still" (segmented with the views' still backdrop), the object's box (2, 3)
    from the masks' visual hull, or None, the masks before that hull cut them) for an object in
    `search`.

    The photos' own cut-outs (`given`, one per view) when they are; else a learned matting
    backend when asked for; else colour on a plain background; else GrabCut seeded by the
    object's points. All are made consistent across views (segment.consistent), except the
    given ones: the user drew them, and one photo's bad cut must not cut every other photo's.
    """
    if given is not None:
        _, box = segment.consistent(given, [v.camera for v in views], search)
        masks = {v.name: m for v, m in zip(views, given)}
        return masks, "given", box, masks
    if matting == "rembg":
        masks, kind = matting_rembg.masks([v.pixels for v in views]), "rembg"
    elif (colour := objectbox.background_colour([v.pixels for v in views])) is not None:
        pairs = [objectbox.foreground_mask(v.pixels, colour, objectbox.box_region(search, v.camera))
                 for v in views]
        masks = segment.see_through([p[0] for p in pairs], [p[1] for p in pairs],
                                    [v.camera for v in views], search)
        kind = "colour"
    else:
        still_backdrop = any(v.backdrop is not None for v in views)
        masks, kind = segment.segment(views, search), "still" if still_backdrop else "segmented"
    final, box = segment.consistent(masks, [v.camera for v in views], search)
    return ({v.name: m for v, m in zip(views, final)}, kind, box,
            {v.name: m for v, m in zip(views, masks)})


def _search_box(aabb: np.ndarray, floor: bool) -> np.ndarray:
    """(2, 3) `aabb` grown by SEARCH_GROW of its size on each side (featureless parts of the
    object have no points), except a floor on the support plane."""
    grow = SEARCH_GROW * (aabb[1] - aabb[0])
    search = np.stack([aabb[0] - grow, aabb[1] + grow])
    if floor:
        search[0, 2] = aabb[0, 2]
    return search


def locate(sfm: SfmResult, pixels: dict[str, np.ndarray], options: PrepareOptions,
           up: str = "plane", by_points: bool = True,
           gravity: dict[str, np.ndarray] | None = None,
           cutouts: dict[str, np.ndarray] | None = None, steadied: bool = False) -> Located:
    """Support plane, up, object box, normalisation and masks for a reconstruction; `pixels` by
    image file name. `up`: "plane" (the support plane's normal, else the cameras'), "gravity"
    (the phone's: `gravity` holds each photo's up in its camera frame by image file name,
    windowshop.photos.sensors) or "photos" (the direction their level axes agree on; the
    plane then bounds nothing). Not `by_points`: the object is where the cameras look, found
    by its masks alone (plane.isolate). `cutouts`: every photo's own outline by image file
    name, used as its mask. `steadied`: the photos were moved so that their backdrop stands
    still (Steady). UserError when no object stands out, or the photos agree on no up when asked
    for it."""
    posed = output.posed_photos(sfm.reconstruction, sfm.turned)
    cameras = [p.camera for p in posed]
    ids = np.array(list(sfm.reconstruction.points3D.keys()), dtype=np.int64)
    points = np.array([sfm.reconstruction.points3D[i].xyz for i in ids]).reshape(-1, 3)
    measured = None
    if up == "gravity":
        measured = sensors.world_up({p.image_name: p.camera.c2w for p in posed}, gravity or {})
        if measured is None:
            raise UserError("none of the placed photos carries the phone's gravity")
    isolated = plane.isolate(points, cameras, options.seed, by_points,
                             None if measured is None else measured[0])
    floor = isolated.plane
    if up == "photos":
        level = agreed_level(np.stack([c.c2w for c in cameras]))
        if level is None:
            raise UserError("the photos do not agree on which way is up (taken at many rolls)")
        isolated, floor = plane.level_up(isolated, level, points, cameras), None
    rotation = normalize.rotation_to_z(isolated.up)
    # where the photos look, the points above the plane are the table's strays, not the object:
    # their box (3.2 x 0.44 on 88 granite photos at SIFT's coarser octave) cut the figure's top
    own = points[isolated.index] if by_points else points[:0]
    lo, hi = objectbox.object_box(own, cameras, rotation,
                                  None if floor is None else (floor.normal, floor.offset))
    if floor is not None:  # the object stands on the plane: the box's floor, under its middle,
        # at the plane itself, where the object's base touches it (a tolerance above it, the
        # base's bottom sliver was outside the box: held-out PSNR, 480 steps, fruit's and
        # dtu_skull's 20 photos, 21.55 -> 22.03 and 24.84 -> 25.20 dB; the masks keep the
        # table out)
        lo[2] = floor.z_at(rotation, (lo[:2] + hi[:2]) / 2)
    transform, aabb = normalize.similarity(rotation, lo, hi)
    posed = output.normalised(posed, transform)
    found, kind, raw = {}, "none", {}
    if options.masks:
        search = _search_box(aabb, floor=floor is not None)
        views = _views(sfm, posed, pixels, _labels(points, ids, isolated, transform, search))
        if not by_points:  # no points of its own: it is surely where every photo looks, and
            views = _looked_at(views)  # on a patterned table, what stands off it is the object
            if floor is not None:
                table = points[np.abs(floor.height(points)) <= floor.tolerance]
                off = offplane.stands_off(views, table @ transform[:3, :3].T + transform[:3, 3])
                views = [replace(v, stands_out=o) for v, o in zip(views, off)]
        # steadied, the backdrop stands still even where the object's matches outnumber its own
        # (bench_isolation's held skull over beer_can's tiles, 16 photos: masks IoU 0.736 on
        # average and 0.322 at worst without the backdrop, 0.773 and 0.458 with it)
        if sfm.database is not None and (steadied or still.fixed_camera(sfm.database)):
            moved = None if sfm.turned else still.shifts(sfm.database,
                                                         [p.image_name for p in posed])
            shown = still.backdrop([v.pixels for v in views], moved)
            views = views if shown is None else [replace(v, backdrop=b, stands_out=o)
                                                 for v, b, o in zip(views, *shown)]
        given = None if cutouts is None else [cutouts[p.image_name] for p in posed]
        found, kind, box, raw = find_masks(views, search, options.matting, given)
        if box is None and not by_points:
            raise UserError(f"no object found where the photos look: the outlines found in "
                            f"them do not agree on one; {plane.ADVICE}")
        if box is not None:  # the masks' hull bounds the object better than its points
            refit, aabb = normalize.similarity(np.eye(3), *box)
            posed, transform = output.normalised(posed, refit), refit @ transform
    chosen = points[isolated.index] @ transform[:3, :3].T + transform[:3, 3]
    # with masks the model learns the object alone, over random backgrounds (Scene "alpha")
    return Located(photos=posed, transform=transform, aabb=aabb, points=chosen, masks=found,
                   mask_kind=kind, background="alpha" if found else "white",
                   plane=isolated.plane, raw_masks=raw, up_source=isolated.up_source)


def _write(out_dir: Path, image_dir: Path, pixels: dict[str, np.ndarray], sfm: SfmResult,
           found: Located, source: Path, exposures: dict[str, np.ndarray], advance) -> Path:
    """Images (each divided by its entry in `exposures`, by image file name), masks,
    transforms.json, the COLMAP model and the camera picture; `pixels` by image file name."""
    (out_dir / "images").mkdir(parents=True, exist_ok=True)
    if found.masks:
        (out_dir / "masks").mkdir(exist_ok=True)
    for p in found.photos:
        exposure = exposures.get(p.image_name)
        if exposure is not None:
            output.write_image(out_dir, p.name, evened(pixels[p.image_name], exposure))
        elif p.image_name in sfm.turned:  # the photo as taken, not as structure from motion saw it
            output.write_image(out_dir, p.name, pixels[p.image_name])
        else:
            shutil.copyfile(image_dir / p.image_name, out_dir / "images" / f"{p.name}.jpg")
        if found.masks:
            mask = objectbox.mask_image(found.masks[p.name])
            mask.save(out_dir / "masks" / f"{p.name}.png")
        advance(1)
    (out_dir / "colmap").mkdir(exist_ok=True)
    sfm.reconstruction.write(out_dir / "colmap")
    near_far = normalize.near_far(np.stack([p.camera.center for p in found.photos]), found.aabb)
    report.plot_cameras(out_dir / "cameras.png", [p.camera for p in found.photos], found.aabb,
                        found.points)
    return output.write_transforms_json(out_dir, found.photos, found.transform, found.aabb,
                                        near_far, found.background, bool(found.masks), str(source))


def _exposures(sfm: SfmResult, pixels: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The exposure of each placed photo that differs from the others' more than negligibly, by
    image file name (windowshop.photos.exposure); `pixels` are the photos as taken."""
    seen = {name: orient.for_sfm(p) if name in sfm.turned else p for name, p in pixels.items()}
    found = photo_exposures(sfm.reconstruction, seen)
    return {name: e for name, e in found.items() if not negligible(e)}


def _report(source: Path, inputs: Inputs, photos: list[Photo], dropped: Dropped,
            dark: list[str], sfm: SfmResult, found: Located, stages: Stages) -> dict:
    by_name = {p.name: p for p in photos}
    def shown(name: str) -> str:
        return by_name[name.rsplit(".", 1)[0]].shown

    unplaced = [shown(n) for n in sfm.unplaced]
    ring = {shown(n): report.RING_NOTES[how] for n, how in sorted(sfm.ring_method.items())}
    apart = {shown(n): [shown(m) for m in matches] for n, matches in _apart(sfm).items()}
    return {
        "input": str(source), "kind": inputs.kind, "ignored": inputs.ignored,
        "dropped": dropped.reasons, "used": len(photos), "placed": len(sfm.placed),
        "dark": dark, "cropped": _cropped(photos),
        "unplaced": unplaced, "estimated_from_ring": ring, "apart": apart,
        "reshoot": report.reshoot([p.shown for p in photos], unplaced + sorted(ring), apart),
        "reprojection_error_px": float(sfm.reconstruction.compute_mean_reprojection_error()),
        "points": int(sfm.reconstruction.num_points3D()), "object_points": len(found.points),
        "features_median": int(np.median(list(sfm.keypoints.values()))),
        "attempts": [vars(a) for a in sfm.attempts], "matcher": sfm.matcher,
        "turned": sorted(sfm.turned),  # images colmap/ holds turned a quarter (photos.orient)
        "pairs": sfm.pairs, "masks": found.mask_kind,
        "plane": {"found": found.plane is not None, "inlier_share": None if found.plane is None
                  else round(found.plane.inlier_share, 3)},
        "background": found.background, "aabb": found.aabb.tolist(),
        "views": [{"name": p.name, "photo": str(by_name[p.name].source),
                   "shown": by_name[p.name].shown} for p in found.photos],
        "seconds": {k: round(v, 3) for k, v in stages.seconds.items()},
    }


def _apart(sfm: SfmResult) -> dict[str, list[str]]:
    """The unplaced photos (image file names) that share no verified pair with any placed photo,
    each with the photos it does match: three photos of another object among the skull's
    matched only each other, and were told to add photos between them and the skull's."""
    if sfm.database is None:
        return {}
    linked = {name: set() for name in sfm.unplaced}
    for _, _, one, other in hypotheses.strongest_pairs(sfm.database):
        linked.setdefault(one, set()).add(other)
        linked.setdefault(other, set()).add(one)
    placed = set(sfm.placed) | set(sfm.guessed)
    return {name: sorted(linked[name]) for name in sfm.unplaced if not linked[name] & placed}


def _choose(sfm: SfmResult, pixels: dict[str, np.ndarray], work: Path, settings: SfmSettings,
            gravity: dict[str, np.ndarray] | None, cutouts: dict[str, np.ndarray] | None,
            options: PrepareOptions, shown: dict[str, str], steadied: bool
            ) -> hypotheses.Choice:
    """The verified hypothesis of the scene (windowshop.photos.hypotheses), its object found;
    UserError with what was wrong when none passes, unless `options.force`. `pixels` holds the
    photos by image file name, `cutouts` their own outlines; `steadied` as locate's."""
    search = hypotheses.Search(
        image_dir=work / "images", work=work, names=list(pixels), pixels=pixels, options=options,
        settings=settings,
        locate=partial(locate, gravity=gravity, cutouts=cutouts, steadied=steadied),
        check_placed=lambda result: check_placed(result, len(pixels), shown),
        deadline=time.perf_counter() + options.verify_seconds, evidence=sfm.database,
        gravity=gravity)
    choice = hypotheses.choose(search, sfm)
    if not choice.verified and not options.force:
        raise UserError(hypotheses.refusal(choice))
    chosen = choice.chosen.hypothesis
    if chosen.found is None:  # forced past failed poses: the object is still needed
        chosen.found = search.locate(chosen.sfm, search.pixels, options, chosen.up,
                                     chosen.by_points)
    return choice


def _verification(choice: hypotheses.Choice, forced: bool) -> dict:
    """report.json's account of the checks: each hypothesis tried, and the one delivered."""
    return {"verified": choice.verified, "forced": forced and not choice.verified,
            "chosen": choice.chosen.hypothesis.label,
            "seconds": round(sum(t.hypothesis.seconds for t in choice.tried), 2),
            "tried": [t.as_report() for t in choice.tried]}


def prepare(source: str | Path, out_dir: str | Path, options: PrepareOptions = PrepareOptions(),
            on_stage: StageCallback | None = None, show: bool = True) -> PrepareResult:
    """Pose the photos or video at `source` into a scene folder `out_dir` (see module docstring).

    `on_stage("prepare", fraction)` is called as the work advances; `show` draws stages and
    progress bars on stderr. UserError says what went wrong and what to do.
    """
    source, out_dir = Path(source), Path(out_dir)
    check_out_dir(source, out_dir, options.overwrite)
    stages = Stages(on_stage, show, report_as="prepare", fractions=SHARES)
    with tempfile.TemporaryDirectory(prefix="windowshop-prepare-") as tmp:
        work = Path(tmp)
        inputs = gather_inputs(source, work)
        photos, dropped = _read(inputs, options, stages)
        dark = [p.shown for p in photos if underexposed(p.pixels)]
        with _light_blamed(dark, len(photos)), _hand_held_blamed(work):
            transforms, summary = _pose(source, out_dir, work, inputs, photos, dropped, dark,
                                        options, stages)
    report.write_report(out_dir, summary)
    if show:
        print("\n".join(report.summary_lines(summary) + [f"scene written to {out_dir}"]),
              file=sys.stderr)
    return PrepareResult(out_dir=out_dir, transforms=transforms, report=summary)


def _pose(source: Path, out_dir: Path, work: Path, inputs: Inputs, photos: list[Photo],
          dropped: Dropped, dark: list[str], options: PrepareOptions, stages: Stages
          ) -> tuple[Path, dict]:
    """Structure from motion, the hypotheses and the verifier's choice, written to `out_dir`:
    (transforms.json's path, the report)."""
    priors = _priors(inputs, photos)
    settings = _settings(inputs, photos, options, priors)
    image_dir = work / "images"
    image_dir.mkdir()
    for photo in photos:  # as structure from motion sees them (windowshop.photos.orient)
        turn = f"{photo.name}.jpg" in settings.turned
        output.write_image(work, photo.name,
                           orient.for_sfm(photo.pixels) if turn else photo.pixels)
    pixels = {f"{p.name}.jpg": p.pixels for p in photos}  # by image file name, as taken
    sfm = reconstruct(image_dir, list(pixels), work, settings, stages)
    steady = None
    if sfm.steadying is not None:  # the steadied photos are what is posed, masked and delivered
        steady = _steady(sfm.steadying, work, pixels, settings)
        work, pixels, settings = steady.work, steady.pixels, steady.settings
        image_dir = work / "images"
        sfm = steady.unplaced(reconstruct(image_dir, list(pixels), work, settings, stages))
    matcher = sfm.matcher  # the first model's: the hypotheses' remaps keep its matches
    shown = {f"{p.name}.jpg": p.shown for p in photos}
    check_placed(sfm, len(photos), shown)
    with stages.stage("finding and checking the object"):
        choice = _choose(sfm, pixels, work, settings, _gravity(priors, photos),
                         _cutouts(photos), options, shown, steady is not None)
    sfm, found = choice.chosen.hypothesis.sfm, choice.chosen.hypothesis.found
    if steady is not None:
        sfm = steady.unplaced(sfm)
    with stages.stage("writing the scene", len(found.photos)) as advance:
        exposures = _exposures(sfm, pixels) if options.even_exposure else {}
        transforms = _write(out_dir, image_dir, pixels, sfm, found, source, exposures, advance)
    summary = _report(source, inputs, photos, dropped, dark, sfm, found, stages)
    summary["exposures"] = {name.rsplit(".", 1)[0]: [round(float(v), 3) for v in e]
                            for name, e in exposures.items()}
    summary["verification"] = _verification(choice, options.force)
    summary["steadied"] = None if steady is None else steady.as_report()
    if steady is not None:  # their room moved too far, not their view of the object too little
        summary["reshoot"] |= {shown[name]: report.SWUNG for name in steady.left_out}
        summary["apart"] = {name: matches for name, matches in summary["apart"].items()
                            if name not in {shown[n] for n in steady.left_out}}
    summary["priors"] = sensors.describe(priors, [p.name for p in photos], found.up_source,
                                         found.plane is not None,
                                         matcher)
    return transforms, summary


@dataclass
class Steady:
    """Photos of a phone that moved while the object turned, moved so that their backdrop stays
    still and cut to what all of them show (windowshop.photos.still.steadying)."""

    work: Path  # the scratch folder they are posed in, their images in images/
    pixels: dict[str, np.ndarray]  # by image file name
    settings: SfmSettings  # known intrinsics moved with the cut
    steadying: still.Steadying
    left_out: list[str]  # image file names steadying could not move onto the others

    def unplaced(self, sfm: SfmResult) -> SfmResult:
        """`sfm` of the steadied photos, with the photos left out among its unplaced."""
        return replace(sfm, unplaced=sorted(set(sfm.unplaced) | set(self.left_out)))

    def as_report(self) -> dict:
        return {"box": list(self.steadying.box),
                "left_out": [name.rsplit(".", 1)[0] for name in self.left_out],
                "moves": {name.rsplit(".", 1)[0]: np.round(h, 6).tolist()
                          for name, h in self.steadying.moves.items()}}


def _steady(steadying: still.Steadying, work: Path, pixels: dict[str, np.ndarray],
            settings: SfmSettings) -> Steady:
    """The photos `pixels` (by image file name) moved and cut by `steadying` into
    `work`/STEADY."""
    steady = work / STEADY
    (steady / "images").mkdir(parents=True)
    moved = {name: still.steadied(image, steadying.moves[name], steadying.box)
             for name, image in pixels.items() if name in steadying.moves}
    for name, image in moved.items():
        output.write_image(steady, name.rsplit(".", 1)[0], image)
    settings = replace(settings, steady=False)
    if settings.intrinsics is not None:  # the principal point moves with the cut
        fx, fy, cx, cy = settings.intrinsics
        left, top = steadying.box[:2]
        settings = replace(settings, intrinsics=(fx, fy, cx - left, cy - top))
    return Steady(steady, moved, settings, steadying, sorted(set(pixels) - set(moved)))


@contextlib.contextmanager
def _light_blamed(dark: list[str], count: int):
    """A refusal that also names the light when most of the `count` photos are `dark`: the
    likeliest cause of whatever failed (masks, matches)."""
    try:
        yield
    except UserError as err:
        if type(err) is not UserError or len(dark) <= count / 2:
            raise
        raise UserError(f"{err}\n{len(dark)} of {count} photos are dark: more light, or tap the "
                        "object on the phone's screen so that it sets the exposure by it") from err


HAND_HELD = ("the photos were taken from one spot, the phone held in the hand while the object "
             "turned, and even moved so that the room behind the object stays still they could "
             "not be placed: prop the phone up (a stand, a stack of books) and keep it still "
             "while you turn the object in smaller steps, or walk round the object instead")


@contextlib.contextmanager
def _hand_held_blamed(work: Path):
    """A refusal that says the phone was held while the object turned when its photos were
    steadied (into `work`/STEADY) and that did not help: what a walk's advice would only
    mislead."""
    try:
        yield
    except UserError as err:
        if type(err) is not UserError or not (work / STEADY).is_dir():
            raise
        raise UserError(f"{HAND_HELD} (what failed: {err})") from err


def check_intrinsics(values: tuple | None) -> None:
    """UserError unless `values` (fx, fy, cx, cy in pixels, or None) are four positive numbers."""
    if values is None:
        return
    numbers = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if len(values) != 4 or len(numbers) != 4 or min(numbers) <= 0:
        shown = ",".join(str(v) for v in values)
        raise UserError(f"--intrinsics {shown}: give four positive numbers fx,fy,cx,cy in pixels")
