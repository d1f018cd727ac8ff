"""`windowshop study --broker`: redis-server and two `windowshop worker` processes on loopback run a
tiny grid on lego_tiny; the gathered study folder is the one a local study writes."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest
from PIL import Image

from distributed_helpers import REDIS, Cluster
from windowshop.cli import main
from shared_data import DATA

LEGO = DATA / "lego_tiny.npz"
pytestmark = [
    pytest.mark.skipif(REDIS is None, reason="redis-server is not installed "
                       "(apt-get install redis-server)"),
    pytest.mark.skipif(not LEGO.is_file(), reason="needs ../shared/data/lego_tiny.npz")]
# two steps of a very small MLP on 25x25 images, one held-out view (as tests/test_study.py)
TINY = ["--iters", "2", "--quiet", "--set", "batch_rays=32", "--set", "test_views=1", "--set",
        "downscale=4", "--set", "width=8", "--set", "depth=1", "--set", "freqs_dir=1"]
GRID = {"base": {"model": "nerf", "n_coarse": 16, "n_fine": 0},
        "product": {"views": [5, 10], "freqs": [2, 4]}}


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    cluster = Cluster(tmp_path_factory.mktemp("study-cluster"))
    try:
        cluster.start_redis()
        cluster.start_worker("w1")
        cluster.start_worker("w2")
        yield cluster
    finally:
        cluster.stop()


def study(cluster: Cluster, grid: Path, out: Path) -> int:
    return main(["study", "--grid", str(grid), "--scene", str(LEGO), "--out", str(out),
                 "--broker", cluster.broker, *TINY])


def test_study_on_two_workers_gathers_a_complete_report_and_resumes(cluster, tmp_path, capsys):
    grid = tmp_path / "tiny.json"
    grid.write_text(json.dumps(GRID))
    out = tmp_path / "study"
    assert study(cluster, grid, out) == 0, capsys.readouterr().err + cluster.logs()
    with open(out / "results.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    expected = [(5, 2), (5, 4), (10, 2), (10, 4)]
    assert [(int(r["views"]), int(r["freqs"])) for r in rows] == expected
    for index, row in enumerate(rows, start=1):
        assert int(row["index"]) == index and int(row["train_views"]) == int(row["views"])
        assert int(row["iterations"]) == 2 and row["status"] == "trained"
        assert 5.0 < float(row["psnr"]) < 30.0
        run_dir = out / row["folder"]
        metrics = json.loads((run_dir / "metrics.json").read_text())
        assert metrics["psnr"] == pytest.approx(float(row["psnr"]))
        # the gathered run names this machine's scene, so eval/render/resume work on it here
        source = json.loads((run_dir / "config.json").read_text())["scene"]["source"]
        assert Path(source).resolve() == LEGO.resolve()  # ../shared may be a symlink
        assert (run_dir / "study_view.png").is_file() and (run_dir / "checkpoint.pt").is_file()
    workers = {json.loads((out / r["folder"] / "study_row.json").read_text())["worker"] for r in rows}
    assert workers == {"w1@test", "w2@test"}
    report = (out / "REPORT.md").read_text()
    table = [line for line in report.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert len(table) == 4 and "--broker" in report and "2 iterations per run" in report
    for name in ("psnr_vs_images.png", "psnr_vs_time.png", "contact_sheet.png"):
        assert f"]({name})" in report and Image.open(out / name).width > 100
    assert Image.open(out / "truth_view.png").size == Image.open(
        out / rows[0]["folder"] / "study_view.png").size

    from windowshop.fit.checkpoint import load_run

    assert Path(load_run(out / rows[0]["folder"], "cpu").scene_source).resolve() == LEGO.resolve()
    stamps = {p: os.stat(p).st_mtime_ns for p in out.glob("runs/*/checkpoint.pt")}
    capsys.readouterr()
    assert study(cluster, grid, out) == 0  # again: everything finished, nothing is sent
    assert "sent to the" not in capsys.readouterr().out
    with open(out / "results.csv", newline="") as handle:
        assert [r["status"] for r in csv.DictReader(handle)] == ["skipped"] * 4
    assert {p: os.stat(p).st_mtime_ns for p in out.glob("runs/*/checkpoint.pt")} == stamps


def test_a_failing_combination_is_named_and_the_others_are_kept(cluster, tmp_path, capsys):
    grid = tmp_path / "bad.json"  # 500 views: more than lego_tiny has, known only on loading
    grid.write_text(json.dumps({"base": {"model": "nerf", "n_coarse": 16, "n_fine": 0},
                                "rows": [{"views": 5}, {"views": 500}]}))
    out = tmp_path / "study"
    assert study(cluster, grid, out) == 2
    assert "combination 02-views=500" in capsys.readouterr().err
    with open(out / "results.csv", newline="") as handle:
        assert [r["status"] for r in csv.DictReader(handle)] == ["trained"]
