"""A briefly trained fast model of the built-in object, in a scene whose source frame is not the
normalised one (so the side file's matrix has work to do)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from windowshop.config import FitConfig
from windowshop.model import model_config
from windowshop.scene.synthetic import synthetic_scene

# source frame -> normalised frame: a turn about x, a scale and a shift (a similarity)
TURN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
SOURCE_TO_NORMALISED = np.block([[0.5 * TURN, np.array([[0.2], [-0.1], [0.3]])],
                                 [np.zeros((1, 3)), np.ones((1, 1))]])


def object_scene():
    """The built-in object's scene, said to come from a source frame SOURCE_TO_NORMALISED away."""
    scene = synthetic_scene(n_train=24, n_test=4, size=32)
    scene.transform = SOURCE_TO_NORMALISED
    scene.views = [dataclasses.replace(v, stored_camera=scene.source_camera(v.camera))
                   for v in scene.views]
    return scene


@pytest.fixture(scope="session")
def object_run(tmp_path_factory) -> Path:
    from windowshop.fit.trainer import fit

    out = tmp_path_factory.mktemp("object_run")
    fit(object_scene(), "fast", model_config("fast", voxels=32**3), FitConfig(iters=150), out,
        "cpu", show_progress=False)
    return out
