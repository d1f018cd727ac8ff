"""The one media module: both readers (the CLI's photos/ingest and the service's uploads) take the
same videos, and the safe unzip refuses what the service refused."""

from __future__ import annotations

import zipfile

import imageio_ffmpeg
import numpy as np
import pytest

from windowshop import media
from windowshop.photos import ingest
from windowshop.photos.frames import sample_frames
from windowshop.service import uploads
from windowshop.service.jobs import pipeline_input
from windowshop.service.settings import ServiceSettings

# A codec each container holds; "-f" names the muxer where the suffix alone does not.
CONTAINERS = {".mp4": ("libx264", "mp4"), ".mov": ("libx264", "mov"), ".m4v": ("libx264", "mp4"),
              ".avi": ("mpeg4", "avi"), ".mkv": ("libx264", "matroska"), ".webm": ("libvpx", "webm")}


def _video(path, frames: int = 6, size: int = 32):
    """A tiny video at `path`: frames of rising grey with a moving bright square."""
    codec, muxer = CONTAINERS[path.suffix]
    writer = imageio_ffmpeg.write_frames(str(path), (size, size), codec=codec, fps=5,
                                         macro_block_size=16, output_params=["-f", muxer])
    writer.send(None)
    for k in range(frames):
        frame = np.full((size, size, 3), 30 * k, np.uint8)
        frame[4:12, 4 + 2 * k:12 + 2 * k] = 255
        writer.send(frame.tobytes())
    writer.close()
    return path


def test_every_container_is_covered():
    assert set(CONTAINERS) == media.VIDEO_SUFFIXES


@pytest.mark.parametrize("suffix", sorted(CONTAINERS))
def test_both_readers_take_the_same_videos(tmp_path, suffix):
    video = _video(tmp_path / f"walk{suffix}")
    # the CLI: a video by its suffix, decoded by ffmpeg
    assert ingest.gather_inputs(video, tmp_path / "scratch").kind == "video"
    assert len(sample_frames(video, 3, None)) == 3
    # the service: a video by its content, decoded, stored under a suffix the job then recognises
    with open(video, "rb") as f:
        assert uploads.sniff(f.read(16)) == "video"
    uploads.check_video(video, "walk", ServiceSettings(data_dir=tmp_path / "data"))
    job = tmp_path / "job"
    (job / "input").mkdir(parents=True)
    stored = job / "input" / f"walk{uploads.video_suffix(video)}"
    video.rename(stored)
    assert pipeline_input(job) == stored


def _zip(path, entries: dict[str, bytes], links: tuple[str, ...] = ()):
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in entries.items():
            zf.writestr(name, data)
        for name in links:
            info = zipfile.ZipInfo(name)
            info.external_attr = 0o120777 << 16  # a symbolic link's mode
            zf.writestr(info, "/etc/passwd")
    return path


@pytest.mark.parametrize("entries, links, code", [
    ({"../evil.jpg": b"x"}, (), "zip_slip"),
    ({"/abs.jpg": b"x"}, (), "zip_slip"),
    ({"C:\\win.jpg": b"x"}, (), "zip_slip"),
    ({"ok.jpg": b"x"}, ("link.jpg",), "zip_link"),
    ({f"{i}.jpg": b"x" for i in range(4)}, (), "too_many_entries"),
    ({"big.jpg": b"x" * 200}, (), "zip_too_large"),
])
def test_unzip_refuses_from_the_index_before_writing(tmp_path, entries, links, code):
    limits = media.ZipLimits(entries=3, unpacked_bytes=100, file_bytes=100)
    out = tmp_path / "out"
    with zipfile.ZipFile(_zip(tmp_path / "a.zip", entries, links)) as zf:
        with pytest.raises(media.Refused) as err:
            list(media.unzip(zf, out, "a.zip", limits))
    assert err.value.code == code
    assert not out.exists() or not any(out.rglob("*"))  # nothing was written


def test_unzip_keeps_paths_and_skips_hidden_and_rejected(tmp_path):
    archive = _zip(tmp_path / "a.zip", {"a/x.jpg": b"1", "b/x.jpg": b"2", "__MACOSX/a/._x.jpg": b"",
                                        ".DS_Store": b"", "notes.txt": b"3"})
    with zipfile.ZipFile(archive) as zf:
        kept = [p.relative_to(tmp_path / "kept").as_posix()
                for _, p in media.unzip(zf, tmp_path / "kept", "a.zip")]
        photos = [p.relative_to(tmp_path / "photos").as_posix()
                  for _, p in media.unzip(zf, tmp_path / "photos", "a.zip",
                                          keep=lambda p: p.suffix == ".jpg")]
    assert kept == ["a/x.jpg", "b/x.jpg", "notes.txt"]
    assert photos == ["a/x.jpg", "b/x.jpg"]
    assert (tmp_path / "photos" / "b" / "x.jpg").read_bytes() == b"2"


def test_unzip_counts_file_bytes_as_written(tmp_path):
    limits = media.ZipLimits(entries=10, unpacked_bytes=10**6, file_bytes=10)
    with zipfile.ZipFile(_zip(tmp_path / "a.zip", {"big.bin": b"x" * 11})) as zf:
        with pytest.raises(media.Refused) as err:
            list(media.unzip(zf, tmp_path / "out", "a.zip", limits))
    assert err.value.code == "file_too_large"
    assert uploads.UploadRefused.of(err.value).status == 413


def test_skip_unsafe_leaves_escaping_entries_and_links_out(tmp_path):
    archive = _zip(tmp_path / "a.zip", {"../evil.jpg": b"1", "ok.jpg": b"2"}, links=("link.jpg",))
    with zipfile.ZipFile(archive) as zf:
        written = [p.name for _, p in media.unzip(zf, tmp_path / "out", "a.zip", skip_unsafe=True)]
    assert written == ["ok.jpg"]
    assert not list(tmp_path.rglob("evil.jpg"))
