"""The covered arc as a viewer's orbit (export/orbit.py), in the GLB's extras and the side file."""

import json

import numpy as np
import pytest

from windowshop.config import ExportOptions
from windowshop.export.command import export_command, side_file
from windowshop.export.glb import read_extras
from windowshop.export.orbit import covered_orbit, viewer_azimuths
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

SMALL = ExportOptions(resolution=48, triangles=3000, texture=128, bake_views=6)


def camera_at(eye) -> Camera:
    return Camera(fx=50, fy=50, cx=25, cy=25, width=50, height=50,
                  c2w=look_at(np.asarray(eye, float), np.zeros(3), np.array([0.0, 0.0, 1.0])))


def test_viewer_azimuth_is_model_viewer_theta():
    # normalised (x, y, z), z up -> model (x, z, -y), y up; theta = atan2(x_model, z_model)
    eyes = {0.0: (0, -3, 1), 90.0: (3, 0, 1), 180.0: (0, 3, 1), 270.0: (-3, 0, 1)}
    got = viewer_azimuths([camera_at(e) for e in eyes.values()], np.zeros(3))
    assert got == pytest.approx(list(eyes), abs=1e-6)


def test_a_full_turn_is_free_and_an_arc_is_limited_with_a_margin():
    around = [camera_at((3 * np.sin(a), -3 * np.cos(a), 1)) for a in np.radians(np.arange(0, 360, 20))]
    assert not covered_orbit(around, np.zeros(3))["limited"]
    arc = [camera_at((3 * np.sin(a), -3 * np.cos(a), 1)) for a in np.radians([200, 230, 240, 250, 300])]
    orbit = covered_orbit(arc, np.zeros(3), margin=10)
    assert orbit["limited"] and orbit["covered_degrees"] == pytest.approx(100, abs=0.1)
    assert (orbit["min"], orbit["max"]) == pytest.approx((190, 310), abs=0.1)
    assert 230 <= orbit["start"] <= 250  # the densest cluster of photos
    assert orbit["model_viewer"]["max-camera-orbit"] == "310.0deg auto auto"


def test_the_glb_and_its_side_file_carry_the_orbit(object_run, tmp_path):
    out = tmp_path / "model.glb"
    asset = export_command(str(object_run), str(out), None, SMALL)
    extras = read_extras(out)["windowshop"]["orbit"]
    side = json.loads(side_file(out).read_text())
    assert extras == side["orbit"] == json.loads(json.dumps(asset.info["orbit"]))
    assert not extras["limited"] and extras["covered_degrees"] > 300  # the object's 24 views go all round
    assert side["neighbour_angle"]["delivered"] > 0 and side["unseen_share"] >= 0
