"""`prepare` on bad input: each failure says what is wrong and what to do, and writes nothing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from windowshop.config import PrepareOptions
from windowshop.errors import UserError
from windowshop.photos.prepare import check_out_dir, prepare
from shared_data import DATA

KERMIT = DATA / "kermit"


def _kermit(folder: Path, count: int) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for path in sorted(KERMIT.glob("*.jpg"))[:count]:
        shutil.copyfile(path, folder / path.name)
    return folder


def _fails(source: Path, out: Path, match: str, **options) -> UserError:
    with pytest.raises(UserError, match=match) as err:
        prepare(source, out, PrepareOptions(max_side=320, **options), show=False)
    assert not out.exists() or not any(out.iterdir())  # nothing half-written
    return err.value


def test_a_file_that_is_not_an_image(tmp_path):
    photos = _kermit(tmp_path / "photos", 5)
    (photos / "receipt.jpg").write_text("total: 12.50")
    _fails(photos, tmp_path / "out", r"receipt\.jpg: not an image")


def test_a_truncated_photo(tmp_path):
    photos = _kermit(tmp_path / "photos", 5)
    data = (KERMIT / "kermit005.jpg").read_bytes()
    (photos / "half.jpg").write_bytes(data[: len(data) // 2])
    _fails(photos, tmp_path / "out", r"half\.jpg: the image is truncated or damaged")


def test_fewer_than_five_usable_photos(tmp_path):
    photos = _kermit(tmp_path / "photos", 4)
    shutil.copyfile(photos / "kermit000.jpg", photos / "kermit000_again.jpg")
    err = _fails(photos, tmp_path / "out", r"only 4 usable photos; windowshop needs at least 5")
    assert "kermit000_again.jpg: exact duplicate of kermit000.jpg" in str(err)


def _video(path: Path) -> Path:
    """A real 12-frame MP4 of noise, 64 x 48."""
    import imageio_ffmpeg

    writer = imageio_ffmpeg.write_frames(str(path), (64, 48), fps=4)
    writer.send(None)
    for frame in np.random.default_rng(0).integers(0, 256, (12, 48, 64, 3), dtype=np.uint8):
        writer.send(frame)
    writer.close()
    return path


def test_a_video_among_too_few_photos_is_named(tmp_path):
    """A folder is read as photos or as one video: the video beside four photos is left out, and
    the refusal says so instead of counting four photos without a word on it. A Live Photo's
    own clip, exported beside its photo under its name, is no video the user meant."""
    photos = _kermit(tmp_path / "photos", 4)
    _video(photos / "walk.mp4")
    _video(photos / "kermit000.mov")
    err = _fails(photos, tmp_path / "out", r"only 4 usable photos")
    assert "walk.mp4: a video among photos" in str(err) and "give the video alone" in str(err)
    assert "kermit000.mov" not in str(err)


def test_two_videos_are_not_taken_for_no_photos(tmp_path):
    (tmp_path / "videos").mkdir()
    for name in ("front.mp4", "back.mov"):
        _video(tmp_path / "videos" / name)
    _fails(tmp_path / "videos", tmp_path / "out",
           r"2 videos found \(back\.mov, front\.mp4\): give one video at a time")


def test_no_photos_at_all(tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "notes.txt").write_text("hello")
    _fails(tmp_path / "photos", tmp_path / "out", r"no photos found")


def test_photos_that_cannot_be_placed(tmp_path):
    """Five photos of five different things share no view: nothing can be placed."""
    photos = tmp_path / "photos"
    photos.mkdir()
    for source in [KERMIT / "kermit000.jpg", DATA / "temple_sparse" / "templeSR0001.png",
                   DATA / "beer_can" / "images" / "0000.jpg", DATA / "lego" / "train" / "r_0.png",
                   DATA / "dtu_skull" / "images" / "000.jpg"]:
        name = f"{source.parent.parent.name}_{source.stem}.png"
        Image.open(source).convert("RGB").save(photos / name)
    err = _fails(photos, tmp_path / "out", r"(?i)take more photos with overlap")
    assert "could only place 0 of 5 photos" in str(err) and "data_kermit000.png" in str(err)


def test_photos_of_something_else_among_the_photos_are_named_as_such(tmp_path):
    """Kermit's 11 photos with three of the skull's among them (a seller's photos of another
    listing): the object is delivered, and the skull's photos are named as sharing nothing with
    it, not sent to be retaken between kermit's."""
    from windowshop.quality import advice

    photos = _kermit(tmp_path / "photos", 11)
    for stem in ("000", "001", "030"):  # two neighbours that match each other, one alone
        shutil.copyfile(DATA / "dtu_skull" / "images" / f"{stem}.jpg", photos / f"skull{stem}.jpg")
    result = prepare(photos, tmp_path / "out", PrepareOptions(max_side=320), show=False)
    found = result.report
    assert found["placed"] >= 8 and not any(v["name"].startswith("skull") for v in found["views"])
    assert found["apart"] == {"skull000.jpg": ["skull001.jpg"], "skull001.jpg": ["skull000.jpg"],
                              "skull030.jpg": []}
    assert found["reshoot"]["skull000.jpg"].startswith("it matches only skull001.jpg, none of the")
    assert found["reshoot"]["skull030.jpg"].startswith("it shares no details with any other photo")
    tips = advice(found)
    assert tips[0].startswith("photos skull000.jpg, skull001.jpg and skull030.jpg share no details")
    assert not any("skull" in tip for tip in tips[1:])  # not also told to retake them in steps


def test_too_little_texture(tmp_path):
    """A smooth grey object on a smooth background: no features to match."""
    photos = tmp_path / "photos"
    photos.mkdir()
    y, x = np.mgrid[0:240, 0:320]
    for k in range(5):
        blob = np.exp(-((x - 120 - 20 * k) ** 2 + (y - 120) ** 2) / 3000.0)
        image = 90 + 100 * blob + 0.1 * x
        Image.fromarray(np.stack([image] * 3, -1).astype(np.uint8)).save(photos / f"smooth{k}.png")
    _fails(photos, tmp_path / "out", r"the background has too little texture")


def test_unreadable_video(tmp_path):
    (tmp_path / "walk.mp4").write_bytes(b"\x00" * 100)
    _fails(tmp_path / "walk.mp4", tmp_path / "out", r"walk\.mp4: not a video we can read")


def test_output_inside_the_input_is_refused(tmp_path):
    photos = _kermit(tmp_path / "photos", 3)
    _fails(photos, photos / "scene", r"must be outside the input")
    assert sorted(p.name for p in photos.iterdir()) == [f"kermit00{i}.jpg" for i in range(3)]


def test_an_existing_output_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    with pytest.raises(UserError, match=r"already exists and is not empty.*--overwrite"):
        check_out_dir(KERMIT, out, overwrite=False)
    with pytest.raises(UserError, match=r"already exists"):
        check_out_dir(KERMIT, out, overwrite=True)  # not an earlier prepare: never deleted
    assert (out / "mine.txt").read_text() == "keep me"
    (out / "mine.txt").unlink()
    (out / "transforms.json").write_text(json.dumps({"frames": [], "windowshop": {}}))
    (out / "images").mkdir()
    check_out_dir(KERMIT, out, overwrite=True)  # an earlier prepare's output is replaced
    assert not any(out.iterdir())


@pytest.mark.parametrize("text", ["1,2,3", "a,b,c,d", "1,2,3,-4"])
def test_bad_intrinsics(text, tmp_path, capsys):
    from windowshop.cli import main

    assert main(["prepare", str(KERMIT), "--out", str(tmp_path / "o"), "--intrinsics", text]) == 2
    assert "four positive numbers" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # refused before any work
