"""`windowshop study`: grids as data, the runner's resume, and a complete report on lego_tiny."""

import csv
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from windowshop.cli import main
from windowshop.config import FitConfig, NerfConfig, SceneOptions
from windowshop.errors import UserError
from windowshop.overrides import parse_assignments
from windowshop.study.grids import budget_overrides, load_grid
from windowshop.study.report import rank_correlation, report_markdown
from windowshop.study.records import ResultRow
from windowshop.study.runner import cpu_model, resolve, study_info
from shared_data import DATA

LEGO = DATA / "lego_tiny.npz"
needs_lego = pytest.mark.skipif(not LEGO.is_file(), reason="needs ../shared/data/lego_tiny.npz")
TABLE_1 = [  # images, L, N_c, view dependence (all 2000 iterations), published PSNR (Table 2)
    (100, 6, 64, True, 23.5), (100, 10, 64, True, 23.8), (100, 6, 128, True, 24.2),
    (25, 6, 64, True, 25.0), (25, 10, 64, True, 23.8), (10, 6, 64, False, 22.5),
    (5, 6, 64, True, 23.0), (5, 6, 128, True, 15.0), (5, 10, 64, True, 24.0), (5, 10, 128, True, 16.0)]
# every run of the CLI study: two steps of a very small MLP on 25x25 images, one held-out view
TINY = ["--iters", "2", "--quiet", "--set", "batch_rays=32", "--set", "test_views=1", "--set",
        "downscale=4", "--set", "width=8", "--set", "depth=1", "--set", "freqs_dir=1"]


def test_seed_preset_is_table_1():
    grid = load_grid("seed")
    assert grid.columns == ("views", "freqs", "n_coarse", "view_dependent")
    assert [c.index for c in grid.combinations] == list(range(1, 11))
    for combo, (views, freqs, n_coarse, vd, psnr) in zip(grid.combinations, TABLE_1, strict=True):
        spec = resolve(combo.settings, combo.folder)
        assert spec.scene_options.views == views
        assert spec.fit_config.iters == 2000 and spec.fit_config.seconds is None
        assert (spec.model_config.freqs, spec.model_config.n_coarse) == (freqs, n_coarse)
        assert spec.model_config.view_dependent is vd and spec.model_config.n_fine == 0
        assert combo.published == {"psnr": psnr}


def test_nerf_ablation_rows():
    grid = load_grid("nerf-ablation")
    specs = {c.name: resolve(c.settings, c.folder) for c in grid.combinations}
    assert len(specs) == 9
    assert specs["no-PE-VD-H"].model_config == NerfConfig(freqs=0, freqs_dir=0, view_dependent=False,
                                                          n_coarse=256, n_fine=0)
    assert specs["complete"].model_config == NerfConfig()
    assert specs["img25"].scene_options.views == 25 and specs["L15"].model_config.freqs == 15
    assert grid.combinations[-1].published == {"psnr": 31.01, "ssim": 0.947, "lpips": 0.081}


def test_budget_and_set_override_every_row():
    overrides = {**parse_assignments(["batch-rays=256", "freqs_dir=2"]), **budget_overrides(None, 20)}
    for combo in load_grid("seed", overrides=overrides).combinations:
        spec = resolve(combo.settings, combo.folder)
        assert spec.fit_config == FitConfig(iters=None, seconds=20.0, batch_rays=256)
        assert spec.model_config.freqs_dir == 2
    with pytest.raises(UserError, match="rows themselves set view_dependent"):
        load_grid("seed", overrides=parse_assignments(["view_dependent=false"]))
    with pytest.raises(UserError, match="--iters"):
        budget_overrides(0, None)
    with pytest.raises(UserError, match="KEY=VALUE"):
        parse_assignments(["batch_rays"])


def test_grid_file_rows_product_and_errors(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("base: {model: nerf, preset: tiny, seconds: 30}\n"
                    "rows:\n  - {name: small, n-coarse: 16, published: {psnr: 20}}\n  - {freqs: 4}\n"
                    "product: {views: [5, 10]}\n")
    grid = load_grid(path=path)
    assert grid.name == "mine" and grid.columns == ("views", "n_coarse", "freqs")
    assert [c.folder for c in grid.combinations] == [
        "01-small-views=5", "02-small-views=10", "03-freqs=4-views=5", "04-freqs=4-views=10"]
    spec = resolve(grid.combinations[3].settings, "row 4")
    assert spec.fit_config.iters is None and spec.fit_config.seconds == 30.0
    assert spec.scene_options == SceneOptions(views=10) and spec.model_config.freqs == 4
    assert grid.combinations[1].published == {"psnr": 20.0}
    fast = tmp_path / "fast.json"
    fast.write_text(json.dumps({"rows": [{"model": "fast", "voxels": 32**3, "iters": 5}]}))
    assert resolve(load_grid(path=fast).combinations[0].settings, "x").model_config.voxels == 32**3
    for bad, message in [({"frequencies": 3}, "01.*no setting frequencies"),
                         ({"voxels": "many"}, "voxels must be an integer"),
                         ({"views": "all"}, "views"), ({"model": "nope"}, "unknown model")]:
        fast.write_text(json.dumps({"rows": [{"model": "fast", "voxels": 32**3, "iters": 5, **bad}]}))
        combo = load_grid(path=fast).combinations[0]
        with pytest.raises(UserError, match=message):
            resolve(combo.settings, combo.folder)
    (tmp_path / "oops.yaml").write_text("rowz: []\n")
    with pytest.raises(UserError, match="unknown key"):
        load_grid(path=tmp_path / "oops.yaml")


def test_rank_correlation_known_answers():
    assert rank_correlation([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert rank_correlation([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert rank_correlation([1, 2], [1, 2]) is None


def test_report_never_mixes_machines_silently():
    grid = load_grid("seed", overrides=budget_overrides(5, None))

    def row(combo, machine, load):
        return ResultRow(index=combo.index, name=combo.name, folder=f"runs/{combo.folder}",
                         settings=resolve(combo.settings, "").effective(), train_views=100,
                         test_views=6, iterations=5, train_seconds=1.0, seconds_per_iter=0.2,
                         psnr=20.0, ssim=0.8, eval_seconds=0.1, published=combo.published,
                         machine=machine, load=load, finished=f"2026-01-0{combo.index}T00:00:00")

    first, second = grid.combinations[:2]
    info = study_info(grid, "lego_tiny.npz", {"iters": 5}, "cpu")
    text = report_markdown(grid, [row(first, "CPU X", 3.0), row(second, "GPU Y", None)], info, {})
    assert "M1 = CPU X; M2 = GPU Y" in text
    assert "load average of the machine when the runs started: 3.0" in text.lower()
    table = [line for line in text.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert [line.rstrip(" |").split("| ")[-1] for line in table] == ["M1", "M2"]
    single = report_markdown(grid, [row(first, "CPU X", 3.0)], info, {})
    assert "Machine: CPU X;" in single and "| M1" not in single


def run_cli_study(out: Path, *extra: str) -> int:
    return main(["study", "--preset", "seed", "--scene", str(LEGO), "--out", str(out), "--device",
                 "cpu", *TINY, *extra])


def read_rows(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def seed_study(tmp_path_factory):
    """The seed preset's ten rows, two tiny steps each, through the real CLI."""
    out = tmp_path_factory.mktemp("study") / "seed"
    assert run_cli_study(out) == 0
    return out


@needs_lego
def test_study_report_rows_match_the_grid(seed_study):
    rows = read_rows(seed_study)
    assert [int(r["index"]) for r in rows] == list(range(1, 11))
    for row, (views, freqs, n_coarse, vd, psnr) in zip(rows, TABLE_1, strict=True):
        assert (int(row["views"]), int(row["train_views"]), int(row["freqs"]), int(row["n_coarse"])) == (
            views, views, freqs, n_coarse)
        assert row["view_dependent"] == str(vd) and float(row["published_psnr"]) == psnr
        assert int(row["iterations"]) == 2 and row["status"] == "trained"
        assert 5.0 < float(row["psnr"]) < 30.0 and float(row["train_seconds"]) > 0
        metrics = json.loads((seed_study / row["folder"] / "metrics.json").read_text())
        assert metrics["psnr"] == pytest.approx(float(row["psnr"]))
    report = (seed_study / "REPORT.md").read_text()
    table = [line for line in report.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert len(table) == 10
    for line, (views, freqs, n_coarse, vd, psnr) in zip(table, TABLE_1):
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[1:5] == [str(views), str(freqs), str(n_coarse), "yes" if vd else "no"]
        assert cells[5] == "2" and cells[-1] == f"{psnr:.2f}"
    assert cpu_model() in report and "2 iterations per run" in report
    for name in ("psnr_vs_images.png", "psnr_vs_time.png", "contact_sheet.png"):
        assert f"]({name})" in report and Image.open(seed_study / name).width > 100


@needs_lego
def test_contact_tile_is_the_runs_own_render(seed_study):
    from windowshop.fit.checkpoint import load_run
    from windowshop.render.frames import display_background, render_camera
    from windowshop.scene import load_scene

    run_dir = seed_study / "runs" / "06-img10-L6-Nc64-novd"
    run = load_run(run_dir, "cpu")
    view = load_scene(LEGO, run.scene_options).split("test")[0]
    frame = render_camera(run.model, view.camera, display_background(run.background))
    tile = np.asarray(Image.open(run_dir / "study_view.png"), dtype=np.float32) / 255.0
    assert tile.shape == frame.rgb.shape
    assert np.abs(tile - frame.rgb).max() <= 1.0 / 255.0 + 1e-5
    truth = np.asarray(Image.open(seed_study / "truth_view.png"), dtype=np.float32) / 255.0
    assert np.abs(truth - view.image).max() <= 1.0 / 255.0 + 1e-5


@needs_lego
def test_study_resumes_and_skips_finished_runs(seed_study, tmp_path):
    out = tmp_path / "seed"
    shutil.copytree(seed_study, out)
    checkpoints = sorted(out.glob("runs/*/checkpoint.pt"))
    stamps = [os.stat(p).st_mtime_ns for p in checkpoints]
    # an interrupted study: run 4 has its checkpoint but was never measured, run 9 never started
    for name in ("metrics.json", "study_row.json"):
        (out / "runs/04-img25-L6-Nc64" / name).unlink()
    shutil.rmtree(out / "runs/09-img5-L10-Nc64")
    assert run_cli_study(out) == 0
    rows = read_rows(out)
    assert [r["status"] for r in rows] == ["skipped"] * 3 + ["resumed"] + ["skipped"] * 4 + [
        "trained", "skipped"]
    assert all(int(r["iterations"]) == 2 for r in rows)
    kept = [os.stat(p).st_mtime_ns for p in checkpoints if "09-" not in str(p) and "04-" not in str(p)]
    assert kept == [s for p, s in zip(checkpoints, stamps) if "09-" not in str(p) and "04-" not in str(p)]
    assert run_cli_study(out) == 0
    assert {r["status"] for r in read_rows(out)} == {"skipped"}
    assert run_cli_study(out, "--set", "seed=1") == 2  # other settings: refuse, never mix
