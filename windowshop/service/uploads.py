"""Checks on what a job is made from, by content and never by name.

An upload is photos (JPEG, PNG, WebP, HEIC when pillow-heif is installed; with the page's
capture.json of the phone's sensors beside them when shot on the page), one video (MP4/MOV,
WebM/MKV, AVI: probed by decoding its first frame with ffmpeg) or one zip (photos, or an already
posed scene: images plus the scene's JSON/text/NumPy/binary files). Every refusal is an
`UploadRefused` carrying the HTTP status, a short code and a message that names the file.
"""

from __future__ import annotations

import re
import shutil
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import imageio_ffmpeg
from PIL import Image, UnidentifiedImageError

from windowshop import media
from windowshop.errors import UserError
from windowshop.media import HEIF, Refused, ZipLimits
from windowshop.photos.sensors import CAPTURE_FILE, read_capture
from windowshop.service.settings import ServiceSettings

IMAGE_FORMATS = {"JPEG": ".jpg", "PNG": ".png", "WEBP": ".webp", "HEIF": ".heic"}
SCENE_DATA_SUFFIXES = {".json", ".txt", ".npy", ".npz", ".bin", ".ply", ".csv"}
_HEIF_BRANDS = {b"heic", b"heix", b"hevc", b"heim", b"heis", b"mif1", b"msf1", b"avif"}
_TOO_LARGE = {"file_too_large", "too_many_entries", "zip_too_large"}  # media's codes sent as 413


class UploadRefused(Exception):
    """An upload the service will not take: `status` (4xx), `code` and a message for the user."""

    def __init__(self, status: int, code: str, message: str):
        super().__init__(message)
        self.status, self.code, self.message = status, code, message

    @classmethod
    def of(cls, err: Refused) -> "UploadRefused":
        """`media`'s refusal with its HTTP status: 413 for sizes and counts, else 400."""
        return cls(413 if err.code in _TOO_LARGE else 400, err.code, err.message)


@dataclass(frozen=True)
class CheckedUpload:
    """An accepted upload: its kind, a line describing it, and the path the pipeline reads."""

    kind: str  # "photos" | "video" | "zip"
    summary: str
    input_path: Path


def sniff(head: bytes) -> str | None:
    """The kind of a file from its first 16 bytes: "image", "video", "zip" or None."""
    if head.startswith((b"\xff\xd8\xff", b"\x89PNG\r\n\x1a\n")):
        return "image"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "image"
    if head[4:8] == b"ftyp":
        return "image" if head[8:12] in _HEIF_BRANDS else "video"
    if head.startswith(b"\x1a\x45\xdf\xa3") or (head[:4] == b"RIFF" and head[8:11] == b"AVI"):
        return "video"
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return "zip"
    return None


def video_suffix(path: Path) -> str:
    """The file suffix of the video container at `path` (a video is recognised by its suffix later)."""
    with open(path, "rb") as f:
        head = f.read(16)
    if head[4:8] == b"ftyp":
        return ".mov" if head[8:12] == b"qt  " else ".mp4"
    return ".avi" if head[:4] == b"RIFF" else ".mkv"


def safe_stem(name: str, fallback: str) -> str:
    """A file stem safe on any disk, keeping the user's name where it can (photos are traced by it)."""
    base = re.split(r"[\\/]", name)[-1]
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", base.rsplit(".", 1)[0] if "." in base else base)
    return stem.lstrip(".")[:80] or fallback


def copy_limited(src, dest: Path, limit: int, what: str) -> int:
    """Copy the file object `src` into `dest`, refusing (413) past `limit` bytes; returns the size."""
    try:
        return media.copy_limited(src, dest, limit, what)
    except Refused as err:
        raise UploadRefused.of(err) from None


def check_image(path: Path, what: str, settings: ServiceSettings) -> str:
    """Decode the image at `path` (bounded by the pixel limit); returns Pillow's format name."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(path) as im:
                width, height = im.size
                if width * height > settings.max_pixels:
                    raise _too_many_pixels(what, width, height, settings)
                if im.format not in IMAGE_FORMATS:
                    raise UploadRefused(415, "unsupported_type", f"{what}: {im.format} images are "
                                        "not supported; send JPEG, PNG or WebP photos")
                if im.format == "JPEG":  # decode the whole stream at 1/8 scale: only validity matters
                    im.draft("RGB", (max(1, width // 8), max(1, height // 8)))
                im.load()
                return im.format
        except Image.DecompressionBombError:
            raise UploadRefused(413, "too_many_pixels", f"{what} has too many pixels (a decompression "
                                f"bomb?); the limit is {settings.max_pixels} pixels per image") from None
        except UnidentifiedImageError:
            if _is_heif(path) and not HEIF:
                raise UploadRefused(415, "unsupported_type", f"{what} is a HEIC photo, which this "
                                    "service cannot decode (pillow-heif is not installed); set the "
                                    "camera to JPEG ('Most compatible') or convert it") from None
            raise UploadRefused(415, "broken_image", f"{what} looks like an image but cannot be "
                                "decoded; send the original photo file") from None
        except (OSError, SyntaxError, ValueError) as err:
            raise UploadRefused(415, "broken_image", f"{what} looks like an image but cannot be "
                                f"decoded ({err}); send the original photo file") from None


def _is_heif(path: Path) -> bool:
    with open(path, "rb") as f:
        head = f.read(12)
    return head[4:8] == b"ftyp" and head[8:12] in _HEIF_BRANDS


def _too_many_pixels(what: str, width: int, height: int, settings: ServiceSettings) -> UploadRefused:
    return UploadRefused(413, "too_many_pixels", f"{what} is {width}x{height} = {width * height} "
                         f"pixels, over the limit of {settings.max_pixels}; send smaller photos")


def check_video(path: Path, what: str, settings: ServiceSettings) -> dict:
    """Probe the video at `path` by decoding its first frame; returns ffmpeg's metadata."""
    reader = imageio_ffmpeg.read_frames(str(path))
    try:
        meta = next(reader)
        next(reader)  # the first frame: the stream really decodes
    except (RuntimeError, OSError, StopIteration):
        raise UploadRefused(415, "broken_video", f"{what} looks like a video but ffmpeg cannot "
                            "decode it; send the file as the camera saved it") from None
    finally:
        reader.close()
    width, height = meta["size"]
    if width * height > settings.max_pixels:
        raise _too_many_pixels(what, width, height, settings)
    if meta.get("duration", 0) > settings.max_video_seconds:
        raise UploadRefused(413, "video_too_long", f"{what} lasts {meta['duration']:.0f} s; the "
                            f"limit is {settings.max_video_seconds:.0f} s (a slow walk around "
                            "the object is enough)")
    return meta


def check_upload(parts: list[tuple[Path, str]], job_dir: Path,
                 settings: ServiceSettings) -> CheckedUpload:
    """Check the saved parts `(path, name the user gave)` and lay them out in `job_dir/input`."""
    if not parts:
        raise UploadRefused(400, "no_files", "no files were sent: add photos, a video or a zip in "
                            "the form field 'files'")
    capture = _capture_part(parts)
    parts = [p for p in parts if p is not capture]
    kinds = []
    for path, name in parts:
        with open(path, "rb") as f:
            kind = sniff(f.read(16))
        if kind is None:
            raise UploadRefused(415, "unsupported_type", f"{name!r} is not a photo, a video or a "
                                "zip (checked by its content, not its name)")
        kinds.append(kind)
    inputs = job_dir / "input"
    inputs.mkdir(parents=True, exist_ok=True)
    if set(kinds) == {"image"}:
        checked = _take_photos(parts, inputs, settings)
        if capture is not None:  # the phone's sensors, read by prepare beside the photos
            shutil.move(capture[0], inputs / CAPTURE_FILE)
        return checked
    if len(parts) == 1 and kinds[0] == "video":
        meta = check_video(parts[0][0], repr(parts[0][1]), settings)
        dest = inputs / (safe_stem(parts[0][1], "video") + video_suffix(parts[0][0]))
        shutil.move(parts[0][0], dest)
        w, h = meta["size"]
        return CheckedUpload("video", f"a {meta.get('duration', 0):.0f} s video, {w}x{h}", dest)
    if len(parts) == 1 and kinds[0] == "zip":
        return unpack_zip(parts[0][0], parts[0][1], inputs, settings)
    raise UploadRefused(400, "mixed_upload", "send either photos, or one video, or one zip, not "
                        f"a mix ({len(parts)} files: {', '.join(sorted(set(kinds)))})")


def _capture_part(parts: list[tuple[Path, str]]) -> tuple[Path, str] | None:
    """The page's capture.json among the photos (windowshop.photos.sensors), checked."""
    part = next((p for p in parts if Path(p[1]).name.lower() == CAPTURE_FILE), None)
    if part is None:
        return None
    try:
        read_capture(part[0], {})
    except UserError as err:
        message = str(err).replace(str(part[0]), CAPTURE_FILE)
        raise UploadRefused(400, "bad_capture", message) from None
    return part


def _take_photos(parts: list[tuple[Path, str]], inputs: Path,
                 settings: ServiceSettings) -> CheckedUpload:
    if len(parts) < settings.min_photos:
        raise UploadRefused(400, "too_few_photos", f"{len(parts)} photo(s) sent; at least "
                            f"{settings.min_photos} are needed, taken all around the object")
    used: set[str] = set()
    for i, (path, name) in enumerate(parts):
        suffix = IMAGE_FORMATS[check_image(path, repr(name), settings)]
        stem = safe_stem(name, f"photo{i:03d}")
        if stem.lower() in used:
            stem = f"{stem}-{i:03d}"
        used.add(stem.lower())
        shutil.move(path, inputs / (stem + suffix))
    return CheckedUpload("photos", f"{len(parts)} photos", inputs)


def unpack_zip(path: Path, name: str, inputs: Path, settings: ServiceSettings) -> CheckedUpload:
    """Check every entry of the zip at `path`, then unpack it into `inputs`."""
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as err:
        raise UploadRefused(415, "broken_zip", f"{name!r} is not a readable zip ({err})") from None
    limits = ZipLimits(entries=settings.max_zip_entries, unpacked_bytes=settings.max_unpacked_bytes,
                       file_bytes=settings.max_file_bytes)
    with archive:
        try:
            images = sum(_check_entry(dest, f"{name!r}: entry {entry!r}", settings)
                         for entry, dest in media.unzip(archive, inputs, name, limits))
        except Refused as err:
            raise UploadRefused.of(err) from None
    path.unlink()
    if images == 0:
        raise UploadRefused(400, "no_images", f"{name!r} holds no photos (JPEG, PNG or WebP)")
    posed = any(inputs.rglob("transforms*.json")) or any(inputs.rglob("*.bin")) \
        or any(inputs.rglob("poses_bounds.npy"))
    what = "a posed scene" if posed else "photos"
    top = list(inputs.iterdir())
    root = top[0] if len(top) == 1 and top[0].is_dir() else inputs
    return CheckedUpload("zip", f"a zip of {what} with {images} images", root)


def _check_entry(path: Path, what: str, settings: ServiceSettings) -> int:
    """Check one unpacked entry by its content; returns 1 for an image, 0 for a scene file."""
    with open(path, "rb") as f:
        kind = sniff(f.read(16))
    if kind == "image":
        check_image(path, what, settings)
        return 1
    if kind in (None, "zip") and path.suffix.lower() in SCENE_DATA_SUFFIXES:  # .npz is a zip
        return 0
    raise UploadRefused(415, "unsupported_type", f"{what} is not a photo nor a scene file "
                        f"({', '.join(sorted(SCENE_DATA_SUFFIXES))})")
