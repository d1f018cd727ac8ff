"""`prepare` on a statue on a sloping street: a figure standing plumb on a granite table tilted by
15 degrees, photographed level (windowshop.scene.products.figure_on_granite(slope_deg=15)). The
support plane's normal is 15 degrees off the true up; the upright check must catch it and the
photos' up must be delivered."""

from __future__ import annotations

import json

import numpy as np

from windowshop.config import PrepareOptions
from windowshop.photos.align import rotation_between, umeyama
from windowshop.photos.prepare import prepare
from windowshop.scene import products, read_source
from windowshop.scene.cameras import up_vector
from shared_data import DATA

SLOPE_DEG = 15.0
UP_DEG = 3.0  # the delivered up within this of the true one


def delivered_up_error(scene_dir, truth_dir, true_up: np.ndarray) -> float:
    """Degrees between the delivered scene's up (+z of prepare's normalised frame) and `true_up`
    (in the truth's world), through the similarity aligning the delivered camera centres to the
    true ones."""
    report = json.loads((scene_dir / "report.json").read_text())
    stems = {v["name"]: v["photo"].rsplit("/", 1)[-1].rsplit(".", 1)[0] for v in report["views"]}
    delivered = {stems[f.image_path.stem]: f.camera.c2w for f in read_source(scene_dir).frames}
    truth = {f.image_path.stem: f.camera.c2w for f in read_source(truth_dir).frames}
    names = sorted(set(delivered) & set(truth))
    assert len(names) >= 3
    _, rot, _ = umeyama(np.stack([delivered[n][:3, 3] for n in names]),
                        np.stack([truth[n][:3, 3] for n in names]))
    up = rot @ np.array([0.0, 0.0, 1.0])
    return float(np.degrees(np.arccos(np.clip(up @ true_up / np.linalg.norm(up), -1.0, 1.0))))


def test_a_figure_on_a_slope_is_delivered_upright(tmp_path):
    products.figure_on_granite(tmp_path / "capture", count=12, size=(400, 300),
                               slope_deg=SLOPE_DEG)
    result = prepare(tmp_path / "capture" / "images", tmp_path / "scene", PrepareOptions(),
                     show=False)
    verification = result.report["verification"]
    assert "photos' up" in verification["chosen"], verification
    error = delivered_up_error(tmp_path / "scene", tmp_path / "capture", np.array([0.0, 0.0, 1.0]))
    assert error <= UP_DEG, (error, verification)


def test_a_can_on_a_floor_before_a_tiled_wall_stands_on_the_floor(tmp_path):
    """beer_can's frames 0000-0006 (about 40 degrees of its walk): the tiled wall behind the can
    holds more points than the floor, and the upright photos rule it out; the floor is found and
    the can delivered upright, not refused for want of an up (as it was before)."""
    beer = DATA / "beer_can"
    photos = tmp_path / "photos"
    photos.mkdir()
    for i in range(7):
        (photos / f"{i:04d}.jpg").symlink_to(beer / "images" / f"{i:04d}.jpg")
    result = prepare(photos, tmp_path / "scene", PrepareOptions(), show=False)
    assert result.report["plane"]["found"] and result.report["verification"]["verified"]
    published = read_source(beer / "sparse" / "0")
    # the level of the walk's cameras, as bench_verify takes it, but those near the published
    # model's folds (bench_fewphoto.beer_can): a short arc alone leaves it loose
    doubtful = {i for jump in (13, 34, 52) for i in range(jump - 1, jump + 7)} | {30, 44}
    true_up = up_vector(np.stack([f.camera.c2w for f in published.frames
                                  if int(f.image_path.stem) not in doubtful]), "level")
    truth = {f.image_path.stem: f.camera.c2w[:3, :3] for f in published.frames}
    delivered = read_source(tmp_path / "scene").frames
    # centres over a short arc leave a similarity loose: the turn is the cameras' own
    turn = rotation_between(np.stack([f.camera.c2w[:3, :3] for f in delivered]),
                            np.stack([truth[f.image_path.stem] for f in delivered]))
    up = turn @ np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(np.clip(up @ true_up, -1.0, 1.0))) <= UP_DEG
