"""Camera intrinsics and poses by structure from motion (pycolmap: SIFT, matching, incremental
mapping), retried with relaxed settings when the first attempt places too few photos.

Attempts, each kept only if it places more photos than the ones before:
1. default COLMAP settings;
2. a relaxed mapper (fewer matches and inliers needed to start a model and to add a view) -
   sparse rings such as the Middlebury temple split into two models without it;
3. denser SIFT features (a lower peak threshold), matched again, with the relaxed mapper.
pycolmap's own logging (glog) stays quiet unless `verbose`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import pycolmap

from windowshop.photos.progress import Stages

MIN_KEYPOINTS = 80  # fewer SIFT features than this in a photo: too little texture to place it
DENSE_PEAK = 0.002  # SIFT peak threshold of the dense retry (COLMAP's default is 0.0067)
DENSE_RETRY_BELOW = 0.9  # the dense retry runs only when fewer than this share are placed
# Video frames are matched with this many next frames only: frames far apart on a walk around a
# symmetric object (a can on a tiled floor) match "through" the symmetry and fold the path over.
SEQUENTIAL_OVERLAP = 5
CHUNK = 4  # photos per feature-extraction call (a progress step)


@dataclass(frozen=True)
class SfmSettings:
    """How structure from motion runs."""

    matcher: str = "exhaustive"  # "exhaustive" (photos) or "sequential" (video frames, by name)
    intrinsics: tuple[float, float, float, float] | None = None  # known fx, fy, cx, cy (working px)
    single_camera: bool = True  # all photos share one camera (same size and EXIF camera)
    seed: int = 0
    verbose: bool = False


@dataclass
class Attempt:
    label: str
    placed: int
    seconds: float


@dataclass
class SfmResult:
    """The best model found, and what it could not place."""

    reconstruction: pycolmap.Reconstruction
    placed: list[str]  # image file names with a pose
    unplaced: list[str]
    keypoints: dict[str, int]  # image file name -> SIFT features found
    attempts: list[Attempt] = field(default_factory=list)


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


def extract(database: Path, image_dir: Path, names: list[str], settings: SfmSettings,
            peak_threshold: float | None, advance) -> dict[str, int]:
    """SIFT features of `names` into `database`; returns the number of features per image."""
    mode = pycolmap.CameraMode.SINGLE if settings.single_camera else pycolmap.CameraMode.PER_IMAGE
    reader = _reader_options(settings)
    extraction = pycolmap.FeatureExtractionOptions()
    if peak_threshold is not None:
        extraction.sift.peak_threshold = peak_threshold
    for start in range(0, len(names), CHUNK):
        pycolmap.extract_features(database, image_dir, image_names=names[start:start + CHUNK],
                                  camera_mode=mode, reader_options=reader,
                                  extraction_options=extraction, device=pycolmap.Device.cpu)
        if settings.single_camera and reader.existing_camera_id < 0:
            # later chunks join the first chunk's camera rather than making their own
            with pycolmap.Database.open(database) as db:
                reader.existing_camera_id = db.read_all_cameras()[0].camera_id
        advance(len(names[start:start + CHUNK]))
    with pycolmap.Database.open(database) as db:
        return {image.name: db.num_keypoints_for_image(image.image_id)
                for image in db.read_all_images()}


def match(database: Path, settings: SfmSettings) -> None:
    """Match every pair (photos) or each frame with its next few frames (video)."""
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = settings.seed
    if settings.matcher == "sequential":
        pairing = pycolmap.SequentialPairingOptions(overlap=SEQUENTIAL_OVERLAP,
                                                    quadratic_overlap=False)
        pycolmap.match_sequential(database, pairing_options=pairing, device=pycolmap.Device.cpu,
                                  verification_options=verification)
    else:
        pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu,
                                  verification_options=verification)


def mapping_options(settings: SfmSettings, relaxed: bool) -> pycolmap.IncrementalPipelineOptions:
    """The incremental mapper's options; `relaxed` lowers what it needs to start and grow
    a model."""
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
    if relaxed:
        options.min_num_matches = 8
        options.mapper.init_min_num_inliers = 30
        options.mapper.init_min_tri_angle = 8.0
        options.mapper.abs_pose_min_num_inliers = 12
        options.mapper.abs_pose_min_inlier_ratio = 0.15
        options.triangulation.ignore_two_view_tracks = False
    return options


def map_once(database: Path, image_dir: Path, out: Path, settings: SfmSettings, relaxed: bool,
             advance) -> pycolmap.Reconstruction | None:
    """The largest model incremental mapping builds (None if it builds none)."""
    out.mkdir(parents=True, exist_ok=True)
    models = pycolmap.incremental_mapping(
        database, image_dir, out, options=mapping_options(settings, relaxed),
        initial_image_pair_callback=lambda: advance(2), next_image_callback=lambda: advance(1))
    if not models:
        return None
    return max(models.values(),
               key=lambda r: (r.num_reg_images(), -r.compute_mean_reprojection_error()))


def _placed(model: pycolmap.Reconstruction | None) -> int:
    return 0 if model is None else model.num_reg_images()


def reconstruct(image_dir: Path, names: list[str], work: Path, settings: SfmSettings,
                stages: Stages) -> SfmResult:
    """Structure from motion on the images `names` (file names in `image_dir`); `work` is scratch.

    Stops at the first attempt that places every image, otherwise keeps the best attempt.
    """
    quiet_logging(settings.verbose)
    pycolmap.set_random_seed(settings.seed)
    database = work / "database.db"
    best, attempts, keypoints = None, [], {}
    plans = [("default", None, False), ("relaxed", None, True), ("dense", DENSE_PEAK, True)]
    for i, (label, peak, relaxed) in enumerate(plans):
        if peak is not None and _placed(best) >= DENSE_RETRY_BELOW * len(names):
            break  # nearly all placed: not worth extracting everything again
        start = time.perf_counter()
        if i == 0 or peak is not None:  # (re)compute features and matches
            database.unlink(missing_ok=True)
            with stages.stage("finding features" + ("" if i == 0 else f" ({label})"),
                              len(names)) as advance:
                keypoints = extract(database, image_dir, names, settings, peak, advance)
            if sum(k >= MIN_KEYPOINTS for k in keypoints.values()) < 3:
                break  # nothing to match: the caller says why (too little texture)
            with stages.stage("matching" + ("" if i == 0 else f" ({label})")):
                match(database, settings)
        with stages.stage("placing cameras" + ("" if i == 0 else f" ({label})"),
                          len(names)) as advance:
            model = map_once(database, image_dir, work / f"sparse_{label}", settings, relaxed,
                             advance)
        attempts.append(Attempt(label, _placed(model), time.perf_counter() - start))
        if _placed(model) > _placed(best):
            best = model
        if _placed(best) == len(names):
            break
    placed = [] if best is None else sorted(im.name for im in best.images.values() if im.has_pose)
    return SfmResult(reconstruction=best, placed=placed,
                     unplaced=sorted(set(names) - set(placed)), keypoints=keypoints,
                     attempts=attempts)
