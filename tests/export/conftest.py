"""A briefly trained fast model of the built-in object (export_helpers.object_scene), and the
choice of z-buffer."""

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


@pytest.fixture(params=["kernel", "twin"])
def zbuffer(request, monkeypatch):
    """The test on both z-buffers: the C kernel and its pure-PyTorch twin (the twin alone where
    no C compiler is found)."""
    from windowshop.field import kernels

    if request.param == "kernel" and not kernels.available("cpu"):
        pytest.skip("no C compiler")
    if request.param == "twin":
        monkeypatch.setattr(kernels, "available", lambda device: False)
    return request.param
