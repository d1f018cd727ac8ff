"""A briefly trained fast model of the built-in object (export_helpers.object_scene)."""

from pathlib import Path

import pytest

from export_helpers import object_scene
from windowshop.config import FitConfig
from windowshop.model import model_config


@pytest.fixture(scope="session")
def object_run(tmp_path_factory) -> Path:
    from windowshop.fit.trainer import fit

    out = tmp_path_factory.mktemp("object_run")
    fit(object_scene(), "fast", model_config("fast", voxels=32**3), FitConfig(iters=150), out,
        "cpu", show_progress=False)
    return out
