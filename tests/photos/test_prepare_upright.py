"""`prepare` on a statue on a sloping street: a figure standing plumb on a granite table tilted by
15 degrees, photographed level (windowshop.scene.products.figure_on_granite(slope_deg=15)). The
support plane's normal is 15 degrees off the true up; the upright check must catch it and the
photos' up must be delivered."""

from __future__ import annotations

import json

import numpy as np

from windowshop.config import PrepareOptions
from windowshop.photos.align import umeyama
from windowshop.photos.prepare import prepare
from windowshop.scene import products, read_source

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
