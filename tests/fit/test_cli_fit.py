"""CPU smoke test through the real command line: `windowshop fit` for two steps, then `eval`."""

import json
import subprocess
import sys

import pytest
from shared_data import DATA

LEGO_TINY = DATA / "lego_tiny.npz"
SMALL = ["--preset", "tiny", "--depth", "2", "--width", "16", "--n-coarse", "8"]


def windowshop(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "windowshop", *args], capture_output=True, text=True,
                          timeout=300)


@pytest.mark.skipif(not LEGO_TINY.is_file(), reason="shared test data not present")
def test_fit_then_eval_on_the_cpu(tmp_path):
    run = tmp_path / "run"
    scene = ["--views", "5", "--test-views", "2", "--downscale", "4"]
    done = windowshop("fit", str(LEGO_TINY), "--model", "nerf", *SMALL, *scene, "--iters", "2",
                      "--batch-rays", "64", "--out", str(run), "--device", "cpu")
    assert done.returncode == 0, done.stderr
    assert "PSNR" in done.stdout
    for name in ("config.json", "checkpoint.pt", "log.jsonl", "metrics.json"):
        assert (run / name).is_file()
    first = json.loads((run / "metrics.json").read_text())
    assert first["iterations"] == 2 and first["test_views"] == 2

    (run / "metrics.json").unlink()
    done = windowshop("eval", str(run), "--device", "cpu")
    assert done.returncode == 0, done.stderr
    again = json.loads((run / "metrics.json").read_text())
    assert again["psnr"] == pytest.approx(first["psnr"], abs=1e-4)
    pngs = sorted((run / "eval").glob("*.png"))
    assert len(pngs) == 2

    done = windowshop("fit", "--resume", str(run), "--iters", "3", "--device", "cpu")
    assert done.returncode == 0, done.stderr
    assert json.loads((run / "metrics.json").read_text())["iterations"] == 3


def test_bad_requests_are_user_errors(tmp_path):
    done = windowshop("eval", str(tmp_path))
    assert done.returncode == 2 and "checkpoint.pt" in done.stderr and "Traceback" not in done.stderr
    done = windowshop("fit", str(LEGO_TINY), "--model", "nerf", "--preset", "huge", "--out", str(tmp_path))
    assert done.returncode == 2 and "huge" in done.stderr


@pytest.mark.skipif(not LEGO_TINY.is_file(), reason="shared test data not present")
def test_set_reaches_any_model_setting(tmp_path):
    run = tmp_path / "run"
    done = windowshop("fit", str(LEGO_TINY), "--set", "voxels=4096", "--set", "hidden=16",
                      "--views", "5", "--test-views", "1", "--iters", "2", "--out", str(run),
                      "--device", "cpu")
    assert done.returncode == 0, done.stderr
    config = json.loads((run / "config.json").read_text())
    assert config["model"] == "fast"
    assert (config["model_config"]["voxels"], config["model_config"]["hidden"]) == (4096, 16)
    done = windowshop("fit", str(LEGO_TINY), "--set", "voxel_size=2", "--out", str(tmp_path / "b"))
    assert done.returncode == 2 and "voxel_size" in done.stderr and "voxel_pixels" in done.stderr
