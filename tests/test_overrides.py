"""Settings derived from the config dataclasses: help from comments, typed overrides, generated
flags, environment variables and the service API's `settings` field, all from one field."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field

import pytest
from pydantic_settings import BaseSettings, SettingsConfigDict

from windowshop.cli import build_parser
from windowshop.config import FitConfig, PipelineConfig, RunConfig, VideoOptions
from windowshop.errors import UserError
from windowshop.model import apply_run_overrides, model_config
from windowshop.overrides import (add_flags, apply_overrides, field_help, flag_values, leaves,
                                  parse_assignments)


@dataclass(frozen=True)
class Lens:
    vignette: float = 0.0  # darkening at the frame's corners, 0..1
    bokeh: bool = False  # blur what is far from focus


@dataclass(frozen=True)
class Job:
    frames: int = 60  # frames of one turn
    lens: Lens = field(default_factory=Lens)
    fit: FitConfig = field(default_factory=FitConfig)


def test_help_comes_from_the_fields_comments():
    assert field_help(Lens) == {"vignette": "darkening at the frame's corners, 0..1",
                                "bokeh": "blur what is far from focus"}
    assert "training pixels wide" in field_help(__import__("windowshop.config").config.FastConfig)["voxel_pixels"]


def test_dotted_and_unique_names_typed_values():
    job = apply_overrides(Job(), {"lens.vignette": 1, "bokeh": "true", "fit.seconds": "2.5"})
    assert job.lens == Lens(vignette=1.0, bokeh=True) and isinstance(job.lens.vignette, float)
    assert job.fit.seconds == 2.5 and job.fit.iters is None  # one budget alone replaces the other
    assert apply_overrides(Job(), {"iters": 5, "seconds": 9}).fit.seconds == 9.0  # both given: both
    with pytest.raises(UserError, match="frames must be an integer"):
        apply_overrides(Job(), {"frames": 2.5})
    with pytest.raises(UserError, match="no setting lens.zoom; the settings: .*lens.vignette"):
        apply_overrides(Job(), {"lens.zoom": 2})
    with pytest.raises(UserError, match="max_side is ambiguous; say which: prepare.max_side, "
                                        "scene.max_side"):
        apply_overrides(PipelineConfig(), {"max_side": 100})


def test_model_settings_are_routed_and_checked_by_the_model():
    run = apply_run_overrides(RunConfig(), {"voxel_pixels": 2, "views": 4})
    assert run.model_settings == {"voxel_pixels": 2} and run.scene.views == 4
    nerf = apply_run_overrides(RunConfig(), {"model": "nerf", "n_fine": 0})
    assert nerf.model_settings == {"n_fine": 0}
    with pytest.raises(UserError, match="voxel_pixels must be a number"):
        apply_run_overrides(PipelineConfig(), {"model_settings.voxel_pixels": "big"})


def test_a_new_field_is_a_flag_an_environment_variable_and_an_api_key(monkeypatch):
    parser = argparse.ArgumentParser()
    add_flags(parser, Job)
    args = parser.parse_args(["--vignette", "0.5", "--lens.bokeh", "--fit.seconds", "3",
                              "--frames", "12"])
    values = flag_values(args)
    assert values == {"lens.vignette": 0.5, "lens.bokeh": True, "fit.seconds": 3.0, "frames": 12}
    assert apply_overrides(Job(), values).lens.vignette == 0.5
    assert "darkening at the frame's corners, 0..1 (default: 0.0)" in parser.format_help()

    class Settings(BaseSettings):
        model_config = SettingsConfigDict(env_prefix="TOY_", env_nested_delimiter="__")
        job: Job = Job()

    assert Settings().job.lens.vignette == 0.0
    monkeypatch.setenv("TOY_JOB__LENS__VIGNETTE", "0.25")
    assert Settings().job.lens.vignette == 0.25
    assert "lens.vignette" in leaves(Job)  # what the API's `settings` field accepts and documents


def test_cli_flags_follow_the_config():
    parser = build_parser()
    video = parser.parse_args(["video", "in", "--out", "o.mp4", "--frames", "9",
                               "--prepare.max-side", "800", "--scene.max-side", "200"])
    assert flag_values(video) == {"render.frames": 9, "prepare.max_side": 800, "scene.max_side": 200}
    with pytest.raises(SystemExit):  # two stages have max_side: a plain --max-side would be a guess
        parser.parse_args(["video", "in", "--out", "o.mp4", "--max-side", "200"])
    render = parser.parse_args(["render", "run", "--out", "o.mp4", "--fov", "40"])
    assert apply_overrides(VideoOptions(), flag_values(render)).fov == 40.0
    fit = parser.parse_args(["fit", "s", "--out", "r", "--voxel-pixels", "2", "--n-fine", "0"])
    assert flag_values(fit) == {"voxel_pixels": 2.0, "n_fine": 0}


def test_set_items_are_yaml_scalars():
    assert parse_assignments(["fit.seconds=30", "mlp-bf16=false", "path=spiral"]) == {
        "fit.seconds": 30, "mlp_bf16": False, "path": "spiral"}
    with pytest.raises(UserError, match="expected KEY=VALUE"):
        parse_assignments(["seconds"])


def test_exponents_without_a_dot_are_numbers():
    # YAML 1.1 (PyYAML) reads 1e-4 as text, so `--set tv_density=1e-4` and a study grid's
    # `tv_density: 1e-4` used to fail with "must be a number"
    run = apply_run_overrides(RunConfig(), parse_assignments(["tv_density=1e-4", "lr_grid=2E-1"]))
    fast = model_config(run.model, **run.model_settings)
    assert (fast.tv_density, fast.lr_grid) == (1e-4, 0.2)
    assert apply_overrides(Job(), {"lens.vignette": "5e-1"}).lens.vignette == 0.5
    with pytest.raises(UserError, match="vignette must be a number, got 'e-1'"):
        apply_overrides(Job(), {"lens.vignette": "e-1"})
    with pytest.raises(UserError, match="frames must be an integer"):
        apply_overrides(Job(), {"frames": "1e2"})


def test_api_settings_field_lists_every_knob(tmp_path):
    from fastapi.testclient import TestClient

    from windowshop.service.app import create_app
    from windowshop.service.settings import ServiceSettings

    app = create_app(ServiceSettings(data_dir=tmp_path), start_worker=False)
    with TestClient(app) as client:
        schema = client.get("/openapi.json").json()
    text = json.dumps(schema)
    for path in leaves(PipelineConfig):
        assert path in text
