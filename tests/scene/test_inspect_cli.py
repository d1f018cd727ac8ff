"""`windowshop inspect` through the real CLI entry point."""

import json
from pathlib import Path

import numpy as np
import pytest

from windowshop.cli import main
from windowshop.scene.synthetic import synthetic_scene
from windowshop.scene.writer import write_transforms
from shared_data import DATA

needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="shared datasets not present")


def _json(capsys, *argv) -> dict:
    assert main(["inspect", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@needs_data
def test_json_gives_the_datasets_own_cameras_before_downscale(capsys):
    meta = json.loads((DATA / "fruit" / "transforms.json").read_text())
    out = _json(capsys, str(DATA / "fruit"), "--max-side", "64", "--views", "5", "--test-views", "2")
    assert out["format"] == "nerfstudio"
    assert [v["split"] for v in out["views"]].count("train") == 5
    by_image = {Path(f["file_path"]).name: f for f in meta["frames"]}
    for view in out["views"]:
        assert set(view) >= {"split", "image", "width", "height", "fx", "fy", "cx", "cy", "c2w"}
        assert (view["width"], view["height"]) == (605, 806)
        assert (view["fx"], view["cy"]) == (pytest.approx(meta["fl_x"]), pytest.approx(meta["cy"]))
        np.testing.assert_allclose(view["c2w"], by_image[Path(view["image"]).name]["transform_matrix"],
                                   atol=1e-6)


@needs_data
def test_json_for_colmap_is_in_opengl_axes_of_the_colmap_world(capsys):
    import pycolmap

    out = _json(capsys, str(DATA / "beer_can" / "sparse" / "0"), "--downscale", "8")
    rec = pycolmap.Reconstruction(str(DATA / "beer_can" / "sparse" / "0"))
    image = next(im for im in rec.images.values() if im.name == Path(out["views"][0]["image"]).name)
    c2w = np.array(out["views"][0]["c2w"])
    np.testing.assert_allclose(c2w[:3, 3], image.projection_center(), atol=1e-9)
    np.testing.assert_allclose(-c2w[:3, 2], image.viewing_direction(), atol=1e-9)
    assert out["views"][0]["width"] == 720 and out["views"][0]["distortion"]["k1"] != 0


def test_text_summary_and_plot(tmp_path, capsys):
    write_transforms(synthetic_scene(n_train=5, n_test=2, size=16), tmp_path / "s")
    plot = tmp_path / "cams.png"
    assert main(["inspect", str(tmp_path / "s"), "--plot", str(plot)]) == 0
    text = capsys.readouterr().out
    assert "nerfstudio" in text and "5 train, 2 test" in text and "16x16" in text
    assert plot.stat().st_size > 10_000
    from PIL import Image

    assert Image.open(plot).size[0] >= 600


@needs_data
def test_kermit_without_poses_is_a_clear_error(capsys):
    assert main(["inspect", str(DATA / "kermit")]) == 2
    err = capsys.readouterr().err
    assert "kermit" in err and "windowshop prepare" in err and "Traceback" not in err
