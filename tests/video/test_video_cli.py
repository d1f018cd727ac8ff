"""`windowshop video` / `make_video`: input -> prepare -> fit -> render, with stage reports."""

from __future__ import annotations

import json

import pytest
from PIL import Image

from windowshop.cli import main
from windowshop.errors import UserError
from windowshop.config import PipelineConfig
from windowshop.fit.checkpoint import load_run
from windowshop.overrides import apply_overrides
from windowshop.pipeline import (EXPORT_SECONDS, FIT_OVERHEAD_SECONDS, RENDER_RAYS_PER_SECOND,
                                 fit_within_deadline,
                                 is_posed_scene, make_video)
from windowshop.scene.synthetic import synthetic_scene
from windowshop.scene.writer import write_transforms
from windowshop.video.encode import probe_video
from shared_data import DATA

TINY = apply_overrides(PipelineConfig(), {"fit.iters": 4, "scene.max_side": 32, "render.frames": 4,
                                          "render.width": 32, "render.height": 32, "models": False})


@pytest.fixture(scope="module")
def posed(tmp_path_factory):
    """A small posed scene on disk (the built-in object, written as transforms.json)."""
    folder = tmp_path_factory.mktemp("posed")
    write_transforms(synthetic_scene(n_train=8, n_test=1, size=32), folder)
    return folder


def test_a_long_prepare_shortens_training_to_meet_the_deadline():
    config = PipelineConfig()  # 30 s of training, a 60 s deadline, 60 frames of 256x256, models
    after = FIT_OVERHEAD_SECONDS + 60 * 256 * 256 / RENDER_RAYS_PER_SECOND + EXPORT_SECONDS
    assert fit_within_deadline(config, 2.0).seconds == 30.0  # time enough: the whole budget
    assert fit_within_deadline(config, 15.0).seconds == pytest.approx(60.0 - 15.0 - after)
    # without the models, their time is training's
    video_only = apply_overrides(config, {"models": False})
    assert fit_within_deadline(video_only, 20.0).seconds == pytest.approx(60.0 - 20.0 - after + EXPORT_SECONDS)
    assert fit_within_deadline(config, 55.0).seconds == config.min_fit_seconds
    assert fit_within_deadline(apply_overrides(config, {"deadline": None}), 55.0).seconds == 30.0
    steps = apply_overrides(config, {"fit.iters": 100})  # a budget in steps is the user's call
    assert fit_within_deadline(steps, 55.0) == steps.fit


def test_posed_scene_skips_prepare_and_reports_stages(posed, tmp_path):
    calls = []
    result = make_video(posed, tmp_path / "spin.mp4", TINY, frames_dir=tmp_path / "frames",
                        on_stage=lambda stage, fraction: calls.append((stage, fraction)),
                        show=False)
    stages = [s for i, (s, _) in enumerate(calls) if i == 0 or calls[i - 1][0] != s]
    assert stages == ["fit", "render"]
    assert all(0.0 <= f <= 1.0 for _, f in calls)
    for stage in stages:
        fractions = [f for s, f in calls if s == stage]
        assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert len([f for s, f in calls if s == "render"]) >= TINY.render.frames
    video = probe_video(result.mp4)
    assert (video["frames"], video["width"], video["height"]) == (4, 32, 32)
    assert result.poster.is_file() and len(list((tmp_path / "frames").glob("*.jpg"))) == 4
    assert set(result.seconds) == {"fit", "render"} and result.scene_dir == posed
    assert json.loads((tmp_path / "spin_work" / "video.json").read_text())["mp4"] == str(result.mp4)
    report = json.loads((tmp_path / "spin_report.json").read_text())  # the capture's quality report
    assert report == json.loads(json.dumps(result.report)) and report["placed"] == 9
    assert report["held_out_photos"] == 1 and report["held_out_psnr"] == result.metrics["psnr"]
    assert (tmp_path / "spin_coverage.png").is_file()


def test_video_writes_the_3d_models_beside_it(posed, tmp_path):
    config = apply_overrides(TINY, {"models": True, "fit.iters": 150, "export.texture": 64,
                                    "export.resolution": 32, "export.triangles": 800})
    result = make_video(posed, tmp_path / "spin.mp4", config, show=False)
    assert result.models == [tmp_path / "spin.glb", tmp_path / "spin.usdz"]
    assert all(p.is_file() and p.with_name(p.name + ".json").is_file() for p in result.models)
    assert "export" in result.seconds


def test_cli_video_prints_each_stage(posed, tmp_path, capsys):
    code = main(["video", str(posed), "--out", str(tmp_path / "out.mp4"), "--iters", "3",
                 "--frames", "3", "--size", "32", "--scene.max-side", "16", "--no-models"])
    assert code == 0
    err = capsys.readouterr().err
    assert "fit: " in err and "render: " in err and "wrote" in err
    assert probe_video(tmp_path / "out.mp4")["frames"] == 3
    # The run records the options the scene was trained with, so `eval` reloads it at 16 px
    run = tmp_path / "out_work" / "run"
    assert load_run(run).scene_options.max_side == 16
    assert main(["eval", str(run), "--device", "cpu"]) == 0
    truth = next((run / "eval").glob("*.png"))
    assert Image.open(truth).height == 16  # truth | render | error side by side, 16 px high


def test_an_output_named_without_a_video_suffix_is_refused_before_any_work(posed, tmp_path, capsys):
    for name in ("spin", "spin.avi"):
        code = main(["video", str(posed), "--out", str(tmp_path / name), "--iters", "3"])
        assert code == 2 and "name the video .mp4" in capsys.readouterr().err
        assert not (tmp_path / f"{name.split('.')[0]}_work").exists()  # nothing prepared or fitted


def test_a_foreign_work_folder_is_never_emptied(posed, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    (work / "thesis.tex").write_text("precious")
    with pytest.raises(UserError, match=r"not from `windowshop video`"):
        make_video(posed, tmp_path / "x.mp4", TINY, work_dir=work, show=False)
    assert (work / "thesis.tex").read_text() == "precious"


def test_what_counts_as_posed(posed):
    assert is_posed_scene(posed) and is_posed_scene(DATA / "temple_sparse")
    assert not is_posed_scene(DATA / "kermit")
    assert not is_posed_scene(DATA / "beer_can" / "Beer.mp4")


@pytest.mark.slow
def test_beer_video_to_turntable(tmp_path, capsys):
    """Beer.mp4 -> 40 frames -> poses -> fit -> a playable turntable (several minutes on a CPU)."""
    out = tmp_path / "beer.mp4"
    code = main(["video", str(DATA / "beer_can" / "Beer.mp4"), "--out", str(out), "--seconds", "60",
                 "--frames", "24", "--size", "128"])
    assert code == 0
    report = json.loads((tmp_path / "beer_work" / "scene" / "report.json").read_text())
    assert report["kind"] == "video" and report["placed"] >= 0.8 * report["used"]
    video = probe_video(out)
    assert (video["frames"], video["width"], video["height"]) == (24, 128, 128)
    assert (tmp_path / "beer_poster.jpg").is_file()
    err = capsys.readouterr().err
    assert all(f"{stage}: " in err for stage in ("prepare", "fit", "render"))

