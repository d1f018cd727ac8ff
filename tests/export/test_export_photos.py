"""An export whose run's scene can be read again takes its colour from the photos, carved by their
masks, and matches a photo better than the field's colour does; refining that texture against the
photos (the default) matches it better still."""

import dataclasses

import numpy as np

from export_helpers import object_scene
from windowshop.config import ExportOptions, FitConfig
from windowshop.export.command import build_asset
from windowshop.export.frame import apply
from windowshop.export.raster import render_mesh
from windowshop.fit.trainer import fit
from windowshop.model import model_config
from windowshop.scene import load_scene
from windowshop.scene.writer import write_transforms

SMALL = ExportOptions(triangles=3000, texture=256, resolution=48)


def test_photos_colour_the_model_and_masks_carve_it(tmp_path):
    write_transforms(object_scene(), tmp_path / "scene")
    scene = load_scene(tmp_path / "scene")
    fit(scene, "fast", model_config("fast", voxels=32**3), FitConfig(iters=100), tmp_path / "run",
        "cpu", show_progress=False)
    with_photos = build_asset(tmp_path / "run", SMALL)
    baked = build_asset(tmp_path / "run", dataclasses.replace(SMALL, refine=False))
    field_only = build_asset(tmp_path / "run", dataclasses.replace(SMALL, bake_views=0))
    assert with_photos.info["photos"] > 0 and field_only.info["photos"] == 0
    assert "refine" in with_photos.info["seconds"] and "refine" not in baked.info["seconds"]
    assert "carve" in with_photos.info["seconds"]  # the object scene's photos have masks
    angles = with_photos.info["neighbour_angle"]  # smoothed back after the tune
    assert angles["delivered"] <= angles["before tune"]
    errors = []
    view = scene.split("train")[1]
    for asset in (with_photos, baked, field_only):
        vertices = apply(np.linalg.inv(asset.frame.to_model), asset.vertices)
        image, silhouette = render_mesh(vertices, asset.faces, view.camera, uv=asset.uv,
                                        texture=asset.texture)
        inside = silhouette & (view.alpha > 0.99)
        errors.append(float(np.mean((image[inside] - view.image[inside]) ** 2)))
    assert errors[0] < errors[1] < errors[2]
