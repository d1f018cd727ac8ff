"""What photos and videos windowshop takes in, in one place for the CLI and the service.

The file suffixes of photos and videos, HEIC/HEIF decoding (registered with Pillow when pillow-heif
is installed), and safe unzipping: entries that would land outside the folder (zip slip) and
symbolic links are refused, and the caller may bound the entry count and the unpacked bytes.
`photos/ingest.py` (the CLI's input) and `service/uploads.py` (the service's uploads) both use it.
"""

from __future__ import annotations

import re
import stat
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from windowshop.errors import UserError

HEIF_SUFFIXES = {".heic", ".heif"}
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".webp", ".tif", ".tiff", ".bmp"} | HEIF_SUFFIXES
# Both readers decode videos with ffmpeg (imageio-ffmpeg), which reads all of these containers.
VIDEO_SUFFIXES = {".mp4", ".mov", ".m4v", ".avi", ".mkv", ".webm"}
_COPY_CHUNK = 1 << 20

try:  # HEIC/HEIF (iPhone photos); without pillow-heif they are refused with a clear message
    from pillow_heif import register_heif_opener

    register_heif_opener()
    HEIF = True
except ImportError:
    HEIF = False


class Refused(UserError):
    """Input windowshop will not take: `code` says why in a word (the service maps it to HTTP)."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code, self.message = code, message


@dataclass(frozen=True)
class ZipLimits:
    """Bounds on a zip, all checked before anything is unpacked except `file_bytes`."""

    entries: int  # entries in the index (folders included)
    unpacked_bytes: int  # the entries' declared sizes together
    file_bytes: int  # one unpacked file, counted as it is written


def is_hidden(path: PurePosixPath | Path) -> bool:
    """Whether `path` is something an archiver or the OS added on its own (dot files, __MACOSX)."""
    return any(p == "__MACOSX" or (p.startswith(".") and p not in (".", "..")) for p in path.parts)


def entry_path(name: str) -> PurePosixPath | None:
    """The zip entry's relative path, or None when it would land outside the folder (zip slip)."""
    name = name.replace("\\", "/")
    if name.startswith("/") or re.match(r"^[A-Za-z]:", name):
        return None
    path = PurePosixPath(name)
    return None if ".." in path.parts else path


def copy_limited(src, dest: Path, limit: int | None, what: str) -> int:
    """Copy the file object `src` into `dest`, refusing past `limit` bytes; returns the size."""
    size = 0
    with open(dest, "wb") as out:
        while chunk := src.read(_COPY_CHUNK):
            size += len(chunk)
            if limit is not None and size > limit:
                raise Refused("file_too_large", f"{what} is larger than the limit of "
                              f"{limit // 2**20} MiB")
            out.write(chunk)
    return size


def unzip(archive: zipfile.ZipFile, folder: Path, name: str, limits: ZipLimits | None = None,
          keep: Callable[[PurePosixPath], bool] = lambda path: True,
          skip_unsafe: bool = False) -> Iterator[tuple[str, Path]]:
    """Unpack `archive` (called `name` in messages) into `folder`, yielding (entry name, file)
    for each file once written, so the caller can check it before the next.

    Hidden entries and those `keep` rejects are skipped. The whole index is checked first (see
    `check_index`); `skip_unsafe` skips escaping entries and links instead of refusing the zip.
    Entries keep their relative paths. Raises Refused.
    """
    entries = []
    for entry in archive.infolist():
        path = PurePosixPath(entry.filename.replace("\\", "/"))
        if not is_hidden(path) and keep(path) and not (skip_unsafe and _unsafe(entry, name)):
            entries.append(entry)
    check_index(entries, name, limits)
    for entry in entries:
        if entry.is_dir():
            continue
        path = entry_path(entry.filename)
        dest = folder / path
        dest.parent.mkdir(parents=True, exist_ok=True)
        what = f"{name!r}: entry {entry.filename!r}"
        try:
            with archive.open(entry) as src:  # reads at most the declared size, and checks the CRC
                copy_limited(src, dest, limits.file_bytes if limits else None, what)
        except (zipfile.BadZipFile, OSError, EOFError) as err:
            raise Refused("broken_zip", f"{what} cannot be unpacked ({err})") from None
        yield entry.filename, dest


def check_index(entries: list[zipfile.ZipInfo], name: str, limits: ZipLimits | None) -> None:
    """Refuse from the index alone: too many entries or bytes (with `limits`), escaping paths, links."""
    if limits is not None and len(entries) > limits.entries:
        raise Refused("too_many_entries", f"{name!r} has {len(entries)} entries; the limit is "
                      f"{limits.entries}")
    unpacked = sum(e.file_size for e in entries)
    if limits is not None and unpacked > limits.unpacked_bytes:
        raise Refused("zip_too_large", f"{name!r} unpacks to {unpacked // 2**20} MiB; the limit "
                      f"is {limits.unpacked_bytes // 2**20} MiB")
    for entry in entries:
        if refusal := _unsafe(entry, name):
            raise refusal


def _unsafe(entry: zipfile.ZipInfo, name: str) -> Refused | None:
    """Why the entry must not be unpacked (it escapes the folder, or is a link), or None."""
    if entry_path(entry.filename) is None:
        return Refused("zip_slip", f"{name!r}: entry {entry.filename!r} would be written outside "
                       "the zip's folder; zip the scene folder itself")
    if stat.S_ISLNK(entry.external_attr >> 16):
        return Refused("zip_link", f"{name!r}: entry {entry.filename!r} is a symbolic link; zip "
                       "the files themselves")
    return None

