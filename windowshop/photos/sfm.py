"""Camera intrinsics and poses by structure from motion (pycolmap: SIFT, matching, incremental
mapping), retried with relaxed settings when the first attempt places too few photos.

Attempts, each kept only if it places more photos than the ones before:
1. default COLMAP settings, but SIFT on the photos as they are when they are rich in features
   (RICH_FEATURES), at most FEATURE_BUDGET features over the set, COLMAP's own
   bundle-adjustment speed-ups, and for a long walk (LONG_WALK) every other photo mapped first;
2. a relaxed mapper (fewer matches and inliers needed to start a model and to add a view),
   growing the first attempt's model - sparse rings such as the Middlebury temple split into
   two models without it;
3. "wide": features for wide baselines, matched again, with the relaxed mapper: denser SIFT (a
   lower peak threshold); for small sets (WIDE_MAX_PHOTOS) also affine-adapted shapes (features
   that survive the foreshortening of a 30-45 degree step), a looser ratio test and fewer inliers
   needed for a pair. (Guided
   matching placed no more of bench_fewphoto's sets and doubled the matching time.)
4. "lowest": for a few photos of which fewer than 3 are placed, the wide matches mapped again
   needing fewer inliers to add a view (LOWEST_POSE_INLIERS).
Then, for a few photos (WIDE_MAX_PHOTOS) of which some are left over, the known-turntable prior
(windowshop.photos.fill) places the rest, as "ring" in the attempts.
Pairs are matched in chunks (windowshop.photos.pairs picks them), so matching shows progress.
pycolmap's own logging (glog) stays quiet unless `verbose`.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from windowshop.photos import fill, orient, pairs, still
from windowshop.photos.progress import Stages

MIN_KEYPOINTS = 80  # fewer SIFT features than this in a photo: too little texture to place it
DENSE_PEAK = 0.002  # SIFT peak threshold of the wide retry (COLMAP's default is 0.0067)
WIDE_RATIO = 0.9  # ratio test of the wide retry (COLMAP's default is 0.8) ...
WIDE_MIN_INLIERS = 8  # ... and the inliers a verified pair needs (default 15)
RETRY_BELOW = 0.9  # the wide retry runs only when fewer than this share are placed
# Inliers a view needs in the last retry, which runs only for a few photos of which fewer than
# fill.MIN_PLACED are placed (default 12, relaxed 12): on fruit's 8 it places 4 (all right) in
# place of 2; on temple's 8 it places 6 in place of 4, one of them 31 degrees wrong, hence last
LOWEST_POSE_INLIERS = 8
# Affine shapes, the looser ratio test and fewer inliers only for sets this small, whose steps
# between photos are wide: on 20 of fruit's photos they tripled the retry (matching 17 s -> 52 s:
# RANSAC on more outliers) to place the same 20; on 8 photos they place more (temple 3 -> 4,
# dtu_skull 7 -> 8)
WIDE_MAX_PHOTOS = 12
CHUNK = 4  # photos per feature-extraction call (a progress step)
# SIFT features a photo keeps: FEATURE_BUDGET over the set, at least MIN_FEATURES and at most
# COLMAP's 8192 a photo. Matching and bundle adjustment grow with the features, and a richly
# textured table gives every photo 8192: 88 photos of a figure on granite took 47 s to match
# and 116 s to map at 8192, 16 s and 49 s at 2048 (placing all 88, reprojection error 0.19 px
# either way). The shared captures' photos have 400-3000, so sets under 60 photos keep all.
FEATURE_BUDGET = 200_000
MIN_FEATURES = 2048
# Bundle adjustment as COLMAP's own speed-ups have it: global BA leaves out 3D points that
# many other points already constrain and runs when the model has grown by 40% (not 10%). (It
# runs on one thread: see mapping_options; on two, 88 granite photos mapped no faster, 10.4 s
# against 9.3, bench/RESULTS.md)
GLOBAL_BA_RATIO = 1.4
# A set of more photos than this is mapped from every other photo first, then the rest are
# added to that model: 88 granite photos 30.9 s -> 25.1 s (7.5 s for 44, then 17.6 s), the same
# 88 placed and 0.193 px
LONG_WALK = 60
# SIFT starts from the photo doubled (COLMAP's first_octave -1) unless a few photos of a set of
# more than WIDE_MAX_PHOTOS hold at least RICH_FEATURES features at their own size (octave 0):
# at 640 pixels the granite table's photos have 1,400-1,500 there, the shared captures' 60-670
# (their doubled photos 400-3,000). Octave 0 costs a quarter: 88 granite photos prepared in 40 s
# instead of 108 (all placed, every check passed); fruit's 78 at octave 0 placed only 46.
RICH_FEATURES = 1024
RICH_SAMPLE = 4
# Matching is done in about MATCH_STEPS calls (progress steps) of at least MATCH_CHUNK pairs:
# each call reads its photos' features again (kermit's 55 pairs: 3.6 s in one call, 7.0 in 20;
# fruit's 190 dense pairs: 14.2 s in one, 18.6 in five)
MATCH_STEPS, MATCH_CHUNK = 10, 100


@dataclass(frozen=True)
class SfmSettings:
    """How structure from motion runs."""

    # "auto" (by count and order: windowshop.photos.pairs), "exhaustive", "sequential" (video
    # frames, by name) or "retrieval"
    matcher: str = "auto"
    intrinsics: tuple[float, float, float, float] | None = None  # known fx, fy, cx, cy (working px)
    # image names that share one camera, a set for each lens (EXIF make, model, focal length
    # and digital zoom) and shape as turned; empty: one camera for all
    cameras: tuple[frozenset[str], ...] = ()
    # image names turned a quarter for structure from motion (windowshop.photos.orient)
    turned: frozenset[str] = frozenset()
    seed: int = 0
    verbose: bool = False
    # the known-turntable prior for a few photos (windowshop.photos.fill): photos left over are
    # registered by PnP, else placed from a neighbour and the ring of the placed ones, else
    # guessed on that ring
    ring: bool = True
    # ... and the photos even that leaves over put on the ring by shooting order: off by
    # default, as bench_fewphoto scored fruit's 4 such guesses all wrong (uneven steps, a
    # hand-held ring), and a wrong pose spoils the fit more than a missing photo does
    ring_guess: bool = False
    # the phone's heading of each photo, in the order of the names (None where unknown), from
    # capture.json: "auto" then matches by heading (windowshop.photos.pairs.heading_pairs)
    headings: tuple[float | None, ...] | None = None
    # photos of a phone that moved while the object turned in front of it are returned unmapped
    # (SfmResult.steadying), for prepare to steady them; off for the photos so steadied
    steady: bool = True


@dataclass
class Attempt:
    label: str
    placed: int
    seconds: float


@dataclass
class SfmResult:
    """The best model found, and what it could not place."""

    reconstruction: pycolmap.Reconstruction | None  # None when none was built
    placed: list[str]  # image file names with a measured pose
    unplaced: list[str]  # image file names without a pose
    keypoints: dict[str, int]  # image file name -> SIFT features found
    attempts: list[Attempt] = field(default_factory=list)
    matcher: str = ""  # the matcher used
    pairs: int = 0  # image pairs matched
    # posed with the ring's help, not measured: windowshop.photos.fill's "paired" and "guessed"
    guessed: list[str] = field(default_factory=list)
    ring_method: dict[str, str] = field(default_factory=dict)  # guessed name -> how
    database: Path | None = None  # the features and verified pairs the model is checked against
    turned: frozenset[str] = frozenset()  # images turned a quarter (windowshop.photos.orient)
    # taken by a phone that moved while the object turned: how to steady them (windowshop.photos.
    # still); they are not mapped, as the backdrop's matches would hold every photo at one spot
    steadying: still.Steadying | None = None


def quiet_logging(verbose: bool) -> None:
    """pycolmap (glog) prints nothing unless `verbose` (its errors become our UserErrors)."""
    pycolmap.logging.minloglevel = 0 if verbose else 3
    pycolmap.logging.stderrthreshold = 0 if verbose else 3


def _reader_options(settings: SfmSettings) -> pycolmap.ImageReaderOptions:
    options = pycolmap.ImageReaderOptions()
    if settings.intrinsics is not None:
        options.camera_model = "PINHOLE"
        options.camera_params = ",".join(f"{v:.6f}" for v in settings.intrinsics)
    return options


def features_per_photo(photos: int) -> int:
    """SIFT features each of `photos` photos keeps (FEATURE_BUDGET)."""
    return int(min(8192, max(MIN_FEATURES, FEATURE_BUDGET // max(photos, 1))))


def _extraction(wide: bool, photos: int, octave: int = -1) -> pycolmap.FeatureExtractionOptions:
    options = pycolmap.FeatureExtractionOptions()
    options.sift.max_num_features = features_per_photo(photos)
    options.sift.first_octave = octave
    if wide:
        options.sift.peak_threshold = DENSE_PEAK
        options.sift.estimate_affine_shape = photos <= WIDE_MAX_PHOTOS
    return options


def extract(database: Path, image_dir: Path, names: list[str], settings: SfmSettings,
            wide: bool, advance) -> dict[str, int]:
    """SIFT features of `names` into `database`, a camera for each of `settings.cameras`;
    returns the number of features per image."""
    octave = -1 if wide else first_octave(database, image_dir, names, settings)
    extraction = _extraction(wide, len(names), octave)
    for group in _by_camera(names, settings.cameras):
        reader = _reader_options(settings)
        for start in range(0, len(group), CHUNK):
            chunk = group[start:start + CHUNK]
            pycolmap.extract_features(database, image_dir, image_names=chunk,
                                      camera_mode=pycolmap.CameraMode.SINGLE,
                                      reader_options=reader, extraction_options=extraction,
                                      device=pycolmap.Device.cpu)
            if reader.existing_camera_id < 0:
                # later chunks join the first chunk's camera rather than making their own
                with pycolmap.Database.open(database) as db:
                    reader.existing_camera_id = db.read_image_with_name(chunk[0]).camera_id
            advance(len(chunk))
    with pycolmap.Database.open(database) as db:
        in_given_order(db, names)
        return {image.name: db.num_keypoints_for_image(image.image_id)
                for image in db.read_all_images()}


def _by_camera(names: list[str], cameras: tuple[frozenset[str], ...]) -> list[list[str]]:
    """`names` in groups of one camera each, in the order given; names in none of `cameras`
    (all of them when it is empty) share one more."""
    index = {name: i for i, group in enumerate(cameras) for name in group}
    groups: dict[int, list[str]] = {}
    for name in names:
        groups.setdefault(index.get(name, -1), []).append(name)
    return list(groups.values())


def in_given_order(db: pycolmap.Database, names: list[str]) -> None:
    """Number `db`'s images (and their frames) in the order of `names`. Extraction's threads
    write each photo when its features are done, so the same photos came out in 3 orders in 4
    runs, and the mapper, which breaks ties by image id, then built different models from them
    (one skull capture refused in one run of three). One thread would cost 40% more time."""
    images = db.read_all_images()
    rank = {name: i for i, name in enumerate(names)}
    wanted = sorted(images, key=lambda im: (rank.get(im.name, len(rank)), im.image_id))
    if [im.image_id for im in wanted] == sorted(im.image_id for im in images):
        return
    frames = {frame.frame_id: frame for frame in db.read_all_frames()}
    features = {im.image_id: (db.read_keypoints(im.image_id), db.read_descriptors(im.image_id))
                for im in images}
    for clear in (db.clear_descriptors, db.clear_keypoints, db.clear_images, db.clear_frames):
        clear()
    for new_id, image in enumerate(wanted, start=1):
        frame = pycolmap.Frame(frame_id=new_id, rig_id=frames[image.frame_id].rig_id)
        frame.add_data_id(pycolmap.data_t(pycolmap.sensor_t(pycolmap.SensorType.CAMERA,
                                                            image.camera_id), new_id))
        db.write_frame(frame, use_frame_id=True)
        keypoints, descriptors = features[image.image_id]
        image.image_id, image.frame_id = new_id, new_id
        db.write_image(image, use_image_id=True)
        db.write_keypoints(new_id, keypoints)
        db.write_descriptors(new_id, descriptors)


def first_octave(database: Path, image_dir: Path, names: list[str], settings: SfmSettings) -> int:
    """0 (SIFT on the photos as they are) for a set rich in features at that size, else -1
    (doubled): see RICH_FEATURES. A few photos are tried in a scratch database beside
    `database`."""
    if len(names) <= WIDE_MAX_PHOTOS:
        return -1
    sample = names[::max(1, len(names) // RICH_SAMPLE)][:RICH_SAMPLE]
    scratch = database.with_name(database.stem + "_octave.db")
    pycolmap.extract_features(scratch, image_dir, image_names=sample,
                              reader_options=_reader_options(settings),
                              extraction_options=_extraction(False, len(names), 0),
                              device=pycolmap.Device.cpu)
    with pycolmap.Database.open(scratch) as db:
        counts = sorted(db.num_keypoints_for_image(image.image_id) for image in db.read_all_images())
    scratch.unlink()
    return 0 if counts and counts[len(counts) // 2] >= RICH_FEATURES else -1


def choose_pairs(image_dir: Path, names: list[str], matcher: str,
                 headings: tuple[float | None, ...] | None = None
                 ) -> tuple[str, list[tuple[str, str]]]:
    """(matcher, name pairs to match): "auto" becomes a matcher by the phone's `headings` when
    they are given and dense (pairs.dense), else by count and order."""
    if matcher == "auto" and headings is not None and pairs.dense(list(headings)):
        return "heading", [(names[i], names[j]) for i, j in pairs.heading_pairs(list(headings))]
    descriptors = None
    if matcher == "retrieval" or (matcher == "auto" and len(names) > pairs.EXHAUSTIVE_MAX):
        descriptors = pairs.tiny_descriptors([image_dir / n for n in names])
    if matcher == "auto":
        matcher = pairs.choose(len(names), descriptors)
    chosen = pairs.image_pairs(len(names), matcher, descriptors)
    return matcher, [(names[i], names[j]) for i, j in chosen]


def match(database: Path, work: Path, name_pairs: list[tuple[str, str]], settings: SfmSettings,
          wide: bool, advance) -> None:
    """Match and verify the image `name_pairs`, a chunk of pairs a call (`advance` per pair)."""
    matching = pycolmap.FeatureMatchingOptions()
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = settings.seed
    # matches that stay at the same pixel belong to the camera (dust, noise of a dark backdrop,
    # a watermark), not the scene: two temple photos 225 degrees apart share 2248 of them
    verification.filter_stationary_matches = True
    if wide and len({name for pair in name_pairs for name in pair}) <= WIDE_MAX_PHOTOS:
        matching.sift.max_ratio = WIDE_RATIO
        verification.min_num_inliers = WIDE_MIN_INLIERS
    step = max(MATCH_CHUNK, -(-len(name_pairs) // MATCH_STEPS))
    listing = work / "pairs.txt"
    for start in range(0, len(name_pairs), step):
        chunk = name_pairs[start:start + step]
        listing.write_text("".join(f"{a} {b}\n" for a, b in chunk))
        pycolmap.match_image_pairs(
            database, matching_options=matching, verification_options=verification,
            pairing_options=pycolmap.ImportedPairingOptions(match_list_path=listing),
            device=pycolmap.Device.cpu)
        advance(len(chunk))
    if still.fixed_camera(database) and not still.fixed_camera(database, still.STILL_PX):
        # the object turned in front of a phone nudged when its shutter was tapped: its
        # backdrop's matches moved a few pixels, past COLMAP's stationary 4, and would hold every
        # photo at one spot (a phone on a tripod keeps COLMAP's 4: 12 drops the object's
        # matches that move little too)
        verification.stationary_matches_max_error = still.STATIONARY_PX
        with pycolmap.Database.open(database) as db:
            db.clear_two_view_geometries()
        pycolmap.geometric_verification(database, two_view_geometry_options=verification)


def mapping_options(settings: SfmSettings, relaxed: bool, lowest: bool = False
                    ) -> pycolmap.IncrementalPipelineOptions:
    """The incremental mapper's options; `relaxed` lowers what it needs to start and grow
    a model, `lowest` lowers what a view needs still further (LOWEST_POSE_INLIERS)."""
    options = pycolmap.IncrementalPipelineOptions()
    options.random_seed = settings.seed
    options.mapper.random_seed = settings.seed
    options.triangulation.random_seed = settings.seed
    if settings.intrinsics is not None:  # known intrinsics stay fixed
        options.ba_refine_focal_length = False
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
        options.mapper.abs_pose_refine_focal_length = False
        options.mapper.abs_pose_refine_extra_params = False
    options.mapper.ba_global_ignore_redundant_points3D = True
    options.ba_global_frames_ratio = options.ba_global_points_ratio = GLOBAL_BA_RATIO
    # one thread, so that the same photos give the same model: with two, the same 8 skull_up
    # photos came out right (median 4.75 deg) in four runs of eight and 5-17 deg off in the rest
    options.num_threads = options.mapper.num_threads = 1
    if relaxed:
        options.min_num_matches = 8
        options.mapper.init_min_num_inliers = 30
        options.mapper.init_min_tri_angle = 8.0
        options.mapper.abs_pose_min_num_inliers = 12
        options.mapper.abs_pose_min_inlier_ratio = 0.15
        options.triangulation.ignore_two_view_tracks = False
    if lowest:
        options.mapper.abs_pose_min_num_inliers = LOWEST_POSE_INLIERS
    return options


def map_once(database: Path, image_dir: Path, out: Path, settings: SfmSettings, relaxed: bool,
             advance, lowest: bool = False, start: pycolmap.Reconstruction | None = None,
             only: list[str] | None = None, pair: tuple[int, int] | None = None
             ) -> pycolmap.Reconstruction | None:
    """The largest model incremental mapping builds (None if it builds none), growing `start`
    when given, from the images `only` when given (else all), starting from the images `pair`
    (database ids) when given (else the mapper's own choice)."""
    out.mkdir(parents=True, exist_ok=True)
    given = ""
    if start is not None:
        given = out / "start"
        given.mkdir(exist_ok=True)
        start.write(given)
    options = mapping_options(settings, relaxed, lowest)
    if only is not None:
        options.image_names = only
    if pair is not None:  # one model from that start: the mapper would otherwise start it
        # again for each further model, and each time its model falls short (25 s of retries
        # for a pair of neighbouring frames among 12 rolled beer_can photos, 0.06 s without)
        options.init_image_id1, options.init_image_id2 = pair
        options.multiple_models = False
    models = pycolmap.incremental_mapping(
        database, image_dir, out, input_path=given, options=options,
        initial_image_pair_callback=lambda: advance(2), next_image_callback=lambda: advance(1))
    if not models:
        return None
    return max(models.values(),
               key=lambda r: (r.num_reg_images(), -r.compute_mean_reprojection_error()))


def _placed(model: pycolmap.Reconstruction | None) -> int:
    return 0 if model is None else model.num_reg_images()


def attempt_database(work: Path, label: str = "default") -> Path:
    """The COLMAP database that reconstruct's attempt `label` matches into, in `work`."""
    return work / f"database_{label}.db"


def reconstruct(image_dir: Path, names: list[str], work: Path, settings: SfmSettings,
                stages: Stages) -> SfmResult:
    """Structure from motion on the images `names` (file names in `image_dir`); `work` is scratch.

    Stops at the first attempt that places every image, otherwise keeps the best attempt.
    """
    quiet_logging(settings.verbose)
    pycolmap.set_random_seed(settings.seed)
    best, best_database, attempts, keypoints = None, None, [], {}
    matcher, name_pairs = choose_pairs(image_dir, names, settings.matcher, settings.headings)
    plans = [("default", False, False, False), ("relaxed", False, True, False),
             ("wide", True, True, False), ("lowest", False, True, True)]
    for i, (label, wide, relaxed, lowest) in enumerate(plans):
        if wide and _placed(best) >= RETRY_BELOW * len(names):
            break  # nearly all placed: not worth extracting everything again
        if lowest and (_placed(best) >= fill.MIN_PLACED or len(names) > WIDE_MAX_PHOTOS):
            break  # enough to fit the ring: fewer inliers a view would risk wrong poses
        start = time.perf_counter()
        suffix = "" if i == 0 else f" ({label})"
        if i == 0 or wide:  # (re)compute features and matches, kept apart for the ring's use
            database = attempt_database(work, label)
            with stages.stage("finding features" + suffix, len(names)) as advance:
                keypoints = extract(database, image_dir, names, settings, wide, advance)
            if sum(k >= MIN_KEYPOINTS for k in keypoints.values()) < 3:
                break  # nothing to match: the caller says why (too little texture)
            if stages.show:
                print(f"matching {len(name_pairs)} pairs of {len(names)} photos ({matcher})",
                      file=sys.stderr)
            with stages.stage("matching" + suffix, len(name_pairs)) as advance:
                match(database, work, name_pairs, settings, wide, advance)
            steadying = (still.steadying(database) if i == 0 and settings.steady
                         and not settings.turned and still.hand_held(database) else None)
            if steadying is not None:
                # the object turned before a phone that moved: the room's matches would hold
                # every photo at one spot whatever the attempt (25 such photos: 0 placed in
                # 22 s, then 82 s of retries); prepare steadies them first
                return SfmResult(reconstruction=None, placed=[], unplaced=sorted(names),
                                 keypoints=keypoints, matcher=matcher, pairs=len(name_pairs),
                                 database=database, steadying=steadying)
        with stages.stage("placing cameras" + suffix, len(names)) as advance:
            # the relaxed mapper grows the first model rather than mapping all again (fruit's 78
            # photos: 7.0 s -> 1.2-2.9 s, the default having placed 45 of them)
            grow = best if label == "relaxed" else None
            if i == 0 and len(names) > LONG_WALK:
                grow = map_once(database, image_dir, work / "sparse_half", settings, relaxed,
                                advance, only=names[::2])
            model = map_once(database, image_dir, work / f"sparse_{label}", settings, relaxed,
                             advance, lowest, grow)
        attempts.append(Attempt(label, _placed(model), time.perf_counter() - start))
        if _placed(model) > _placed(best):
            best, best_database = model, database
        if _placed(best) == len(names):
            break
    placed = [] if best is None else sorted(im.name for im in best.images.values() if im.has_pose)
    filled = fill.Filled()
    if settings.ring and best is not None and len(placed) < len(names) <= WIDE_MAX_PHOTOS:
        start = time.perf_counter()
        filled = fill.fill(best, best_database, names, settings.seed, settings.ring_guess,
                           settings.turned)
        attempts.append(Attempt("ring", len(placed) + len(filled.measured),
                                time.perf_counter() - start))
    placed = sorted(placed + filled.measured)
    return SfmResult(reconstruction=best, placed=placed,
                     unplaced=sorted(set(names) - set(placed) - set(filled.paired)
                                     - set(filled.guessed)),
                     keypoints=keypoints, attempts=attempts, matcher=matcher,
                     pairs=len(name_pairs), guessed=sorted(filled.paired + filled.guessed),
                     ring_method={n: "paired" for n in filled.paired}
                     | {n: "guessed" for n in filled.guessed}, database=best_database,
                     turned=settings.turned)


def write_gravity(database: Path, gravity: dict[str, np.ndarray],
                  turned: frozenset[str] = frozenset()) -> None:
    """The phone's gravity of each image (by file name; `gravity` holds its up, camera frame with
    OpenCV axes) as COLMAP pose priors, which the global mapper's rotation averaging can use
    (COLMAP's prior holds the direction of gravity itself: down). `turned` images' gravity is
    turned with them."""
    with pycolmap.Database.open(database) as db:
        for image in db.read_all_images():
            if image.name not in gravity:
                continue
            up = np.asarray(gravity[image.name], dtype=np.float64)
            up = orient.sfm_vector(up) if image.name in turned else up
            sensor = pycolmap.sensor_t(pycolmap.SensorType.CAMERA, image.camera_id)
            db.write_pose_prior(pycolmap.PosePrior(
                corr_data_id=pycolmap.data_t(sensor, image.image_id), gravity=-up))
