"""Reading the user's photos: orientation, formats, zips, duplicates, blur and bad files."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from PIL import Image, ImageFilter, ImageOps

from windowshop import media
from windowshop.errors import UserError
from windowshop.photos import ingest
from shared_data import DATA

KERMIT = DATA / "kermit"


def _pattern(width: int = 64, height: int = 48) -> np.ndarray:
    """An asymmetric test picture (H, W, 3) uint8: a gradient with a bright top-left block."""
    y, x = np.mgrid[0:height, 0:width]
    image = np.stack([x * 255 // width, y * 255 // height, (x + y) % 256], -1).astype(np.uint8)
    image[:10, :16] = 255
    return image


def test_exif_orientation_is_applied(tmp_path):
    pixels = _pattern()
    exif = Image.Exif()
    exif[0x0112] = 6  # "rotate 90 CW to display": stored sideways, shown upright
    stored = Image.fromarray(pixels).transpose(Image.Transpose.ROTATE_90)
    stored.save(tmp_path / "side.png", exif=exif)
    photo = ingest.read_photo(tmp_path / "side.png", max_side=None)
    assert photo.pixels.shape == pixels.shape
    np.testing.assert_array_equal(photo.pixels, pixels)


def test_a_large_jpeg_shrunk_while_decoding_matches_the_whole_photo_shrunk(tmp_path):
    """JPEG's reduced decoding (Image.draft) of a photo stored sideways gives the working-size
    photo that decoding it whole and shrinking would give, with the scale and size of the whole."""
    upright = Image.open(KERMIT / "kermit000.jpg").resize((1200, 1600), Image.Resampling.BICUBIC)
    exif = Image.Exif()
    exif[0x0112] = 6
    upright.transpose(Image.Transpose.ROTATE_90).save(tmp_path / "big.jpg", quality=95, exif=exif)
    photo = ingest.read_photo(tmp_path / "big.jpg", max_side=320)
    with Image.open(tmp_path / "big.jpg") as whole:
        expected = ImageOps.exif_transpose(whole).convert("RGB")
    expected = np.asarray(expected.resize((240, 320), Image.Resampling.LANCZOS), np.float32)
    assert photo.pixels.shape == (320, 240, 3)
    assert photo.scale == pytest.approx(0.2) and photo.camera_key[-1] == (1200, 1600)
    assert np.abs(photo.pixels - expected).mean() < 2.0


def test_a_digital_zoom_is_another_camera(tmp_path):
    """A phone's digital zoom keeps the lens's EXIF focal length and writes its ratio beside it
    (0: none): the photos it took get a camera key of their own, with the focal length zoomed."""
    keys = {}
    for zoom in (None, 0.0, 1.0, 2.0):
        exif = Image.Exif()
        exif[0x010F], exif[0x0110] = "Phone", "X"
        details = exif.get_ifd(0x8769)
        details[0x920A] = 4.25
        if zoom is not None:
            details[0xA404] = zoom
        Image.fromarray(_pattern()).save(tmp_path / f"{zoom}.jpg", exif=exif)
        keys[zoom] = ingest.read_photo(tmp_path / f"{zoom}.jpg", max_side=None).camera_key
    assert keys[None] == keys[0.0] == keys[1.0]
    assert keys[2.0][2] == pytest.approx(8.5) and keys[2.0][::3] == keys[None][::3]


def test_resized_to_working_size_with_scale():
    photo = ingest.read_photo(KERMIT / "kermit000.jpg", max_side=320)
    assert photo.pixels.shape == (240, 320, 3)
    assert photo.scale == pytest.approx(0.5)
    assert photo.name == "kermit000"


def test_a_cut_out_is_laid_on_grey_and_keeps_its_outline(tmp_path):
    """A PNG whose background was removed (transparent, black under it, as background removers
    leave it): the backdrop's grey where it is clear, the opaque part as the cut-out, both at
    working size."""
    pixels = _pattern(128, 96)
    alpha = np.zeros((96, 128), np.uint8)
    alpha[20:70, 30:90] = 255
    Image.fromarray(np.dstack([pixels * (alpha[..., None] > 0), alpha])).save(tmp_path / "c.png")
    photo = ingest.read_photo(tmp_path / "c.png", max_side=64)
    assert photo.pixels.shape == (48, 64, 3)
    expected = np.zeros((48, 64), bool)
    expected[10:35, 15:45] = True
    np.testing.assert_array_equal(photo.cutout, expected)
    far = np.ones((48, 64), bool)  # clear, 4 pixels or more from the outline (Lanczos' reach)
    far[6:39, 11:49] = False
    assert (photo.pixels[far] == ingest.BACKDROP).all()
    np.testing.assert_allclose(photo.pixels[12:33, 17:43].mean((0, 1)),
                               pixels[24:66, 34:86].mean((0, 1)), atol=3)
    # an opaque alpha channel (a screenshot) cuts nothing out
    Image.fromarray(np.dstack([pixels, np.full((96, 128), 255, np.uint8)])).save(tmp_path / "o.png")
    opaque = ingest.read_photo(tmp_path / "o.png", max_side=None)
    assert opaque.cutout is None
    np.testing.assert_array_equal(opaque.pixels, pixels)


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_a_sixteen_bit_grey_photo_keeps_its_tones(tmp_path, suffix):
    # a raw converter's export: Pillow opens it as I;16, and its own convert to RGB clips every
    # value over 255, a photo turned white
    with Image.open(KERMIT / "kermit000.jpg") as image:
        grey = np.asarray(image.convert("L"))
    Image.fromarray(grey.astype(np.uint16) * 257).save(tmp_path / f"k{suffix}")
    with Image.open(tmp_path / f"k{suffix}") as stored:
        assert stored.mode.startswith("I")
    photo = ingest.read_photo(tmp_path / f"k{suffix}", max_side=None)
    assert photo.pixels.dtype == np.uint8 and photo.pixels.shape == grey.shape + (3,)
    assert np.abs(photo.pixels.astype(int) - grey[..., None]).max() <= 1


@pytest.mark.skipif(not media.HEIF, reason="pillow-heif is not installed")
def test_heic_photo_is_read(tmp_path):
    Image.open(KERMIT / "kermit000.jpg").save(tmp_path / "k.heic", quality=90)
    photo = ingest.read_photo(tmp_path / "k.heic", max_side=None)
    reference = np.asarray(Image.open(KERMIT / "kermit000.jpg"), dtype=np.float32)
    assert photo.pixels.shape == reference.shape
    assert np.abs(photo.pixels.astype(np.float32) - reference).mean() < 8.0


def test_not_an_image_is_named(tmp_path):
    (tmp_path / "notes.jpg").write_text("this is a shopping list, not a photo")
    with pytest.raises(UserError, match=r"notes\.jpg: not an image"):
        ingest.read_photo(tmp_path / "notes.jpg", max_side=None)


def test_truncated_image_is_named(tmp_path):
    data = (KERMIT / "kermit001.jpg").read_bytes()
    (tmp_path / "cut.jpg").write_bytes(data[: len(data) // 3])
    with pytest.raises(UserError, match=r"cut\.jpg: the image is truncated"):
        ingest.read_photo(tmp_path / "cut.jpg", max_side=None)


def test_read_photos_lists_every_bad_file(tmp_path):
    (tmp_path / "a.jpg").write_text("no")
    (tmp_path / "b.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 20)
    files = [tmp_path / "a.jpg", tmp_path / "b.png", KERMIT / "kermit000.jpg"]
    with pytest.raises(UserError, match=r"2 of 3 files could not be read") as err:
        ingest.read_photos(files, None, ingest.Dropped())
    assert "a.jpg" in str(err.value) and "b.png" in str(err.value)


def test_duplicates_and_blurred_are_dropped_with_names(tmp_path):
    files = sorted(KERMIT.glob("*.jpg"))[:5]
    copy = tmp_path / "again.jpg"
    copy.write_bytes(files[2].read_bytes())
    blurred = tmp_path / "shaky.jpg"
    Image.open(files[3]).filter(ImageFilter.GaussianBlur(4)).save(blurred, quality=95)
    dropped = ingest.Dropped()
    photos = ingest.read_photos([*files, copy, blurred], None, dropped)
    assert [p.name for p in photos] == [f.stem for f in files]
    assert dropped.reasons["again.jpg"] == f"exact duplicate of {files[2].name}"
    assert dropped.reasons["shaky.jpg"].startswith("too blurred")


def test_a_sharp_photo_of_plainer_things_is_not_called_blurred(tmp_path, monkeypatch):
    """A sharp photo of fruit on a table among kermit's cluttered desk: its Laplacian's variance
    is under BLUR_RATIO of theirs (what it shows, not how sharp it is), and it is kept; the
    same photo blurred is dropped."""
    files = sorted(KERMIT.glob("*.jpg"))[:6]
    fruit = DATA / "fruit" / "newfruit_small" / "IMG_3650.jpg"
    shaky = tmp_path / "shaky.jpg"
    Image.open(fruit).filter(ImageFilter.GaussianBlur(1.5)).save(shaky, quality=95)
    photos = [ingest.read_photo(path, 640) for path in [*files, fruit, shaky]]
    median = np.median([p.sharpness for p in photos])
    assert photos[-2].sharpness < ingest.BLUR_RATIO * median  # the variance alone would drop it
    dropped = ingest.Dropped()
    kept = ingest.drop_blurred(photos, dropped)
    assert [p.name for p in kept] == [f.stem for f in files] + ["IMG_3650"]
    assert list(dropped.reasons) == ["shaky.jpg"] and "blur 0." in dropped.reasons["shaky.jpg"]
    monkeypatch.setattr(ingest, "BLUR_EXCESS", -1.0)  # the variance alone dropped it
    alone = ingest.Dropped()
    ingest.drop_blurred(photos, alone)
    assert "IMG_3650.jpg" in alone.reasons


def test_a_photo_with_too_little_light_is_underexposed_and_a_black_backdrop_is_not():
    photo = np.asarray(Image.open(KERMIT / "kermit000.jpg"))
    assert not ingest.underexposed(photo)
    assert ingest.underexposed((0.25 * photo).astype(np.uint8))  # a quarter of the light
    temple = np.asarray(Image.open(DATA / "temple_sparse" / "templeSR0001.png").convert("RGB"))
    assert np.median(temple) < 30 and not ingest.underexposed(temple)  # bright on black


def test_fewer_than_five_usable_photos(tmp_path):
    files = sorted(KERMIT.glob("*.jpg"))[:4]
    copy = tmp_path / "copy.jpg"
    copy.write_bytes(files[0].read_bytes())
    with pytest.raises(UserError, match=r"only 4 usable photos; .* at least 5") as err:
        ingest.read_photos([*files, copy], None, ingest.Dropped())
    assert "copy.jpg: exact duplicate of kermit000.jpg" in str(err.value)


def test_gather_folder_reads_its_subfolders_and_ignores_other_files(tmp_path):
    """A folder is read as a zip of it is: its subfolders' photos too (a phone's DCIM/100APPLE,
    101APPLE, ...), hidden ones left out."""
    for name in ["b.jpg", "a.PNG", "notes.txt", ".DS_Store", "sub/c.jpg", "sub/list.txt",
                 ".thumbnails/d.jpg"]:
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "empty").mkdir()
    inputs = ingest.gather_inputs(tmp_path, tmp_path / "scratch")
    assert inputs.kind == "photos"
    assert [p.relative_to(tmp_path).as_posix() for p in inputs.files] == ["a.PNG", "b.jpg",
                                                                          "sub/c.jpg"]
    assert inputs.ignored == ["notes.txt", "sub/list.txt"]


def test_photos_of_one_name_in_two_folders_are_shown_by_their_folders(tmp_path):
    """Two phones' photos in a folder each both start at IMG_0001.jpg: the report must say which
    one it means."""
    files = {"phone_a/IMG_0001.jpg": "kermit000", "phone_b/IMG_0001.jpg": "kermit001",
             "phone_b/IMG_0002.jpg": "kermit001", "kermit002.jpg": "kermit002",
             "kermit003.jpg": "kermit003", "kermit004.jpg": "kermit004"}
    for name, source in files.items():
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes((KERMIT / f"{source}.jpg").read_bytes())
    dropped = ingest.Dropped()
    inputs = ingest.gather_inputs(tmp_path, tmp_path / "scratch")
    photos = ingest.read_photos(inputs.files, 160, dropped)
    assert sorted(p.shown for p in photos) == ["kermit002.jpg", "kermit003.jpg", "kermit004.jpg",
                                               "phone_a/IMG_0001.jpg", "phone_b/IMG_0001.jpg"]
    assert dropped.reasons == {"IMG_0002.jpg": "exact duplicate of phone_b/IMG_0001.jpg"}
    assert len({p.name for p in photos}) == len(photos)


def test_gather_zip_keeps_its_folders_and_cannot_escape(tmp_path):
    archive = tmp_path / "photos.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.write(KERMIT / "kermit000.jpg", "a/kermit000.jpg")
        zf.write(KERMIT / "kermit001.jpg", "b/kermit000.jpg")  # same name in another folder
        zf.write(KERMIT / "kermit002.jpg", "../../evil.jpg")
        zf.writestr("__MACOSX/._kermit000.jpg", b"junk")
        zf.writestr("readme.txt", b"hello")
    scratch = tmp_path / "scratch"
    inputs = ingest.gather_inputs(archive, scratch)
    assert sorted(p.relative_to(scratch).as_posix() for p in inputs.files) == [
        "unzipped/a/kermit000.jpg", "unzipped/b/kermit000.jpg"]
    assert sorted(ingest.shown_names(inputs.files).values()) == ["a/kermit000.jpg",
                                                                  "b/kermit000.jpg"]
    assert all(scratch in p.parents for p in inputs.files)
    assert not list(tmp_path.rglob("evil.jpg"))  # a member climbing out with ".." is skipped


def test_gather_refuses_other_files(tmp_path):
    (tmp_path / "list.txt").write_text("hello")
    with pytest.raises(UserError, match=r"list\.txt: not a photo, a video"):
        ingest.gather_inputs(tmp_path / "list.txt", tmp_path)


def test_sharpness_drops_with_blur():
    image = Image.open(KERMIT / "kermit000.jpg")
    sharp = ingest.sharpness(np.asarray(image))
    soft = ingest.sharpness(np.asarray(image.filter(ImageFilter.GaussianBlur(3))))
    assert soft < 0.2 * sharp
