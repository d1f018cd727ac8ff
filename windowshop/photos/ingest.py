"""The user's input (a folder or zip of photos, or a video) -> checked photos at working size.

Photos are decoded with Pillow (HEIC/HEIF through pillow-heif), turned upright by their EXIF
orientation and resized; the user's files are only ever read. Exact duplicates and very blurred
photos are dropped and named, so the user knows which. A photo whose transparency cuts the object
out (a PNG from a background remover or a phone's "lift subject") is laid on grey, and its
transparency kept as the object's outline.
"""

from __future__ import annotations

import hashlib
import math
import re
import zipfile
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path, PurePosixPath

import numpy as np
from PIL import Image, ImageOps, UnidentifiedImageError

from windowshop.errors import UserError
from windowshop.media import HEIF, HEIF_SUFFIXES, IMAGE_SUFFIXES, VIDEO_SUFFIXES, is_hidden, unzip
from windowshop.photos.sensors import CAPTURE_FILE, find_capture
from windowshop.scene.images import eight_bit, parallel_map

MIN_PHOTOS = 5  # below this the verifier's checks cannot tell a right model from a wrong one
BLUR_RATIO = 0.3  # a photo this many times less sharp than the set's median counts as blurred
# ... when its blur (blur_of) also lies this much over the set's: the Laplacian's variance
# follows what a photo shows as much as how sharp it is (a plain apple scores 0.28 of a cluttered
# desk's median, sharp), Crete's measure much less (bench/RESULTS.md, stop 57: every photo of the
# shared sets the variance drops lies 0.05-0.11 over its set's median; a sharp photo of another
# object among kermit's, 0.03 under it)
BLUR_EXCESS = 0.03
BLUR_SAMPLE = 9  # photos whose blur gives the set's median (evenly spaced), besides the suspects
# a photo whose brightest 1% lies under this share of white was taken with too little light (the
# shared captures' lie at 0.52-1.0, black backdrops included; kermit's at a quarter of their
# light, 0.21-0.23): its masks and colours suffer, which the advice says
DARK = 0.35
# a photo counts as a cut-out when at least this share of it is transparent (alpha under half):
# an opaque PNG (a screenshot's alpha all 255) or a few clear corner pixels is not one
CUTOUT_SHARE = 0.01
DRAFT_MARGIN = 2.0  # a JPEG is decoded at no less than this times its working size

# what a cut-out is laid on: its outline's corners are features too, and grey leaves a light
# object's outline as clear as a dark one's (dtu_skull's 12 photos cut out by their hand-made
# masks: 12 placed on black or grey, 11 on white; bench/RESULTS.md, stop 58)
BACKDROP = (128, 128, 128)


@dataclass
class Photo:
    """One usable photo (or video frame) at working resolution."""

    name: str  # unique working_name of the file stem (a video frame: <its stem>_<frame index>)
    source: Path  # the user's file it came from
    pixels: np.ndarray  # (H, W, 3) uint8, upright
    scale: float  # working pixels per pixel of the upright original
    camera_key: tuple = ()  # photos with equal keys come from one camera (EXIF make, model, focal)
    sharpness: float = 0.0
    cutout: np.ndarray | None = None  # (H, W) bool, the opaque pixels of a cut-out (see above)
    shown: str = ""  # the name the user knows it by (shown_names; a video frame's own name)

    def __post_init__(self):
        self.shown = self.shown or self.source.name


@dataclass
class Inputs:
    """What the input held: photo files or one video, and what was ignored."""

    kind: str  # "photos" | "video"
    files: list[Path]
    ignored: list[str] = field(default_factory=list)
    capture: Path | None = None  # the page's capture.json beside the photos (photos.sensors)
    root: Path | None = None  # the folder read, which `ignored` is relative to


@dataclass
class Dropped:
    """Photos left out, each with the reason."""

    reasons: dict[str, str] = field(default_factory=dict)  # file name -> why


def _is_media(path: PurePosixPath) -> bool:
    """Photos, videos and the page's capture.json: what prepare reads of a zip."""
    return path.suffix.lower() in IMAGE_SUFFIXES | VIDEO_SUFFIXES or path.name.lower() == CAPTURE_FILE


def _unzip(archive: Path, scratch: Path) -> Path:
    """Extract the photos and videos of `archive` into `scratch/unzipped`, in their folders, as a
    folder is read (shown_names tells apart one name in two folders); the user's own file, so
    without limits, and with unsafe entries skipped."""
    out = scratch / "unzipped"
    out.mkdir(parents=True, exist_ok=True)
    try:
        with zipfile.ZipFile(archive) as zf:
            list(unzip(zf, out, str(archive), keep=_is_media, skip_unsafe=True))
    except zipfile.BadZipFile as err:
        raise UserError(f"{archive}: not a readable zip file ({err}); "
                        f"zip the photos again") from err
    return out


def gather_inputs(path: str | Path, scratch: Path) -> Inputs:
    """The photo files or the video that `path` (folder, zip, video or photo) holds."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"{path}: no such file or folder")
    if path.is_file() and path.suffix.lower() == ".zip":
        path = _unzip(path, scratch)
    if path.is_file():
        suffix = path.suffix.lower()
        if suffix in VIDEO_SUFFIXES:
            return Inputs("video", [path])
        if suffix in IMAGE_SUFFIXES:
            return Inputs("photos", [path])
        raise UserError(f"{path}: not a photo, a video, or a folder or zip of photos "
                        f"(photos: {', '.join(sorted(IMAGE_SUFFIXES))}; "
                        f"videos: {', '.join(sorted(VIDEO_SUFFIXES))})")
    # subfolders too, as a zip of the folder is read (a phone's DCIM/100APPLE, 101APPLE, ...)
    entries = sorted(p for p in path.rglob("*")
                     if p.is_file() and not is_hidden(p.relative_to(path)))
    photos = [p for p in entries if p.suffix.lower() in IMAGE_SUFFIXES]
    videos = [p for p in entries if p.suffix.lower() in VIDEO_SUFFIXES]
    if not photos and len(videos) == 1:
        return Inputs("video", videos)
    capture = find_capture(entries)
    ignored = [p.relative_to(path).as_posix() for p in entries if p not in photos and p != capture]
    return Inputs("photos", photos, ignored, capture, path)


def _camera_key(image: Image.Image, size: tuple[int, int]) -> tuple:
    """(make, model, focal length, size): photos sharing it can share one set of intrinsics. A
    phone's digital zoom crops the lens's picture and keeps its focal length in the EXIF, with
    the zoom beside it: the zoom multiplies the focal length."""
    exif = image.getexif()
    details = exif.get_ifd(0x8769)  # Exif IFD
    focal, zoom = details.get(0x920A), details.get(0xA404)  # FocalLength, DigitalZoomRatio
    if focal is not None and zoom:  # a ratio of 0 means no digital zoom
        focal = float(focal) * float(zoom)
    return (exif.get(0x010F), exif.get(0x0110), float(focal) if focal is not None else None, size)


def read_photo(path: Path, max_side: int | None) -> Photo:
    """Decode, turn upright (EXIF orientation) and shrink one photo; UserError if it is unusable."""
    if path.suffix.lower() in HEIF_SUFFIXES and not HEIF:
        raise UserError(f"{path}: HEIC/HEIF photos need the pillow-heif package "
                        f"(pip install pillow-heif), or export the photos as JPEG")
    try:
        with Image.open(path) as image:
            stored = image.size
            scale = 1.0 if max_side is None else min(1.0, max_side / max(stored))
            # a JPEG decodes straight to 1/2, 1/4 or 1/8 of its size, no smaller than asked;
            # asked for twice the working size, so that the last shrink is still the filter's
            # and a photo up to twice it decodes as before (beer_can's 1280 px frames: a direct
            # 1/2 decode moved their pixels enough to change a knife-edge model; stop 58)
            image.draft(image.mode, tuple(math.ceil(side * min(1.0, DRAFT_MARGIN * scale))
                                          for side in stored))
            image.load()
            upright = ImageOps.exif_transpose(image)
            full = stored if upright.size == image.size else stored[::-1]  # turned a quarter
            key = _camera_key(image, full)
            rgb, alpha = _laid_on_backdrop(eight_bit(upright))
    except UnidentifiedImageError as err:
        raise UserError(f"{path}: not an image (its contents are not a photo format we read); "
                        f"remove it from the input") from err
    except (OSError, SyntaxError, ValueError) as err:
        raise UserError(f"{path}: the image is truncated or damaged ({err}); copy it again from "
                        f"the camera or remove it") from err
    size = (max(1, round(full[0] * scale)), max(1, round(full[1] * scale)))
    if rgb.size != size:
        # box-reduced to 3x the size first (reducing_gap): 2x faster from 12 megapixels, within
        # 0.2 of 255 of the full filter on average
        rgb = rgb.resize(size, Image.Resampling.LANCZOS, reducing_gap=3.0)
        alpha = None if alpha is None else alpha.resize(size, Image.Resampling.BILINEAR)
    pixels = np.asarray(rgb, dtype=np.uint8)
    cutout = None if alpha is None else np.asarray(alpha) >= 128
    if cutout is not None and (1.0 - cutout.mean() < CUTOUT_SHARE or not cutout.any()):
        cutout = None
    return Photo(name=working_name(path.stem), source=path, pixels=pixels, scale=size[0] / full[0],
                 camera_key=key, sharpness=sharpness(pixels), cutout=cutout)


def _photo_or_why(path: Path, max_side: int | None) -> Photo | str:
    """read_photo's photo, or what was wrong with the file."""
    try:
        return read_photo(path, max_side)
    except UserError as err:
        return str(err)


def _laid_on_backdrop(image: Image.Image) -> tuple[Image.Image, Image.Image | None]:
    """(the RGB image, laid on BACKDROP where it is transparent; its alpha (L), or None when it
    has no transparency). The colour under a clear pixel is whatever the tool left there."""
    if image.mode not in ("RGBA", "LA", "PA") and "transparency" not in image.info:
        return image.convert("RGB"), None
    rgba = image.convert("RGBA")
    backdrop = Image.new("RGBA", rgba.size, BACKDROP + (255,))
    return Image.alpha_composite(backdrop, rgba).convert("RGB"), rgba.getchannel("A")


def underexposed(pixels: np.ndarray) -> bool:
    """Whether the photo (H, W, 3) uint8 is too dark: its brightest 1% (every other pixel) under
    DARK of white."""
    return float(np.percentile(pixels[::2, ::2].mean(-1), 99)) < DARK * 255


def sharpness(pixels: np.ndarray) -> float:
    """Variance of the Laplacian of the grey image (H, W, 3) uint8: low for blurred photos."""
    grey = pixels.astype(np.float32).mean(-1) / 255.0
    lap = (grey[:-2, 1:-1] + grey[2:, 1:-1] + grey[1:-1, :-2] + grey[1:-1, 2:]
           - 4.0 * grey[1:-1, 1:-1])
    return float(lap.var())


def working_name(stem: str) -> str:
    """A file stem as the photo's working name: its whitespace made "_", since COLMAP reads
    the list of pairs to match split on it ("Photo 12.jpg", as macOS and Windows name copies:
    kermit's 11 so named, 0 of 11 placed)."""
    return re.sub(r"\s+", "_", stem)


def shown_names(files: list[Path]) -> dict[Path, str]:
    """The name the user knows each file by: its file name, or where files in different folders
    share one (two phones' IMG_0001.jpg), as much of its path as tells them apart."""
    by_name: dict[str, list[Path]] = {}
    for path in files:
        by_name.setdefault(path.name, []).append(path)
    shown = {}
    for same in by_name.values():
        parts = 1
        while len({Path(*f.parts[-parts:]) for f in same}) < len(same) and parts < max(
                len(f.parts) for f in same):
            parts += 1
        shown.update({f: Path(*f.parts[-parts:]).as_posix() for f in same})
    return shown


def unique_names(photos: list[Photo]) -> None:
    """Make the photos' names unique in place (a.jpg and a.png -> a, a-2)."""
    seen: set[str] = set()
    for photo in photos:
        name, n = photo.name, 2
        while name in seen:
            name = f"{photo.name}-{n}"
            n += 1
        photo.name = name
        seen.add(name)


def drop_duplicates(photos: list[Photo], dropped: Dropped) -> list[Photo]:
    """Photos with distinct pixels; the later copies of a photo are dropped and named."""
    first: dict[str, Photo] = {}
    kept = []
    for photo in photos:
        digest = hashlib.sha1(photo.pixels.tobytes() + str(photo.pixels.shape).encode()).hexdigest()
        if digest in first:
            dropped.reasons[photo.shown] = f"exact duplicate of {first[digest].shown}"
            continue
        first[digest] = photo
        kept.append(photo)
    return kept


def blur_of(pixels: np.ndarray) -> float:
    """How blurred the image (H, W, 3) uint8 is, 0 (sharp) to 1: Crete et al. 2007's no-reference
    measure (skimage.measure.blur_effect), how little the neighbours' differences fall when the
    photo is blurred again; sharp photos of any content score about 0.3-0.45."""
    from skimage.measure import blur_effect

    return float(blur_effect(pixels.astype(np.float32).mean(-1)))


def drop_blurred(photos: list[Photo], dropped: Dropped, ratio: float = BLUR_RATIO) -> list[Photo]:
    """The photos, less those under `ratio` of the set's median sharpness whose blur (blur_of)
    also lies BLUR_EXCESS over the set's median blur: those are dropped, named."""
    if len(photos) <= MIN_PHOTOS:
        return photos
    median = float(np.median([p.sharpness for p in photos]))
    suspects = [p for p in photos if p.sharpness < ratio * median]
    if not suspects:
        return photos
    sample = [photos[i] for i in np.unique(np.linspace(0, len(photos) - 1, BLUR_SAMPLE).round()
                                           .astype(int))]
    blur = {id(p): blur_of(p.pixels) for p in [*sample, *suspects]}
    usual = float(np.median([blur[id(p)] for p in sample]))
    blurred = {id(p) for p in suspects if blur[id(p)] > usual + BLUR_EXCESS}
    for photo in photos:
        if id(photo) in blurred:
            dropped.reasons[photo.shown] = (
                f"too blurred (sharpness {photo.sharpness / median:.2f} of the median, blur "
                f"{blur[id(photo)]:.2f} against the photos' {usual:.2f})")
    return [p for p in photos if id(p) not in blurred]


def check_enough(photos: list[Photo], dropped: Dropped, what: str = "photos") -> None:
    """UserError unless at least MIN_PHOTOS photos are usable."""
    if len(photos) >= MIN_PHOTOS:
        return
    why = "".join(f"\n  {name}: {reason}" for name, reason in dropped.reasons.items())
    raise UserError(f"only {len(photos)} usable {what}; windowshop needs at least {MIN_PHOTOS} "
                    f"(better 20-60, taken all around the object with overlap){why}")


def read_photos(files: list[Path], max_side: int | None, dropped: Dropped,
                advance=lambda n=1: None) -> list[Photo]:
    """Decode every file (UserError naming each unusable one), then drop duplicates and blur."""
    # on every core: a HEIC photo has no reduced decoding (0.5 s for 12 megapixels)
    read = parallel_map(partial(_photo_or_why, max_side=max_side), files, advance)
    photos = [r for r in read if isinstance(r, Photo)]
    errors = [r for r in read if isinstance(r, str)]
    if errors:
        raise UserError(f"{len(errors)} of {len(files)} files could not be read:\n  "
                        + "\n  ".join(errors))
    unique_names(photos)
    shown = shown_names([p.source for p in photos])
    for photo in photos:
        photo.shown = shown[photo.source]
    photos = drop_blurred(drop_duplicates(photos, dropped), dropped)
    check_enough(photos, dropped)
    return photos
