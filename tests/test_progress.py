"""Progress bars: tqdm at a terminal, a few plain lines when written to a pipe or a log file."""

import io
import subprocess
import sys

import pytest
from shared_data import DATA
from tqdm import tqdm

from windowshop.progress import LineProgress, bar

LEGO_TINY = DATA / "lego_tiny.npz"


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_log_gets_one_line_per_interval_and_one_at_the_end():
    out, clock = io.StringIO(), Clock()
    progress = LineProgress(total=100, desc="fit", unit="step", file=out, interval=5.0, clock=clock)
    with progress:
        for _ in range(100):
            clock.now += 0.2  # 20 s in all: the first update, one line every 5 s, then the close
            progress.update(1)
            progress.set_postfix(loss="0.5")
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert len(lines) == 5
    assert lines[0].startswith("fit: 1/100 step (1%)")
    assert lines[-1].startswith("fit: 100/100 step (100%) 20.0 s") and lines[-1].endswith("loss=0.5")


def test_iterating_yields_every_item_and_closes_with_the_count():
    out = io.StringIO()
    assert list(LineProgress(range(7), desc="render", unit="frame", file=out)) == list(range(7))
    assert out.getvalue().splitlines()[-1].startswith("render: 7/7 frame (100%)")


def test_bar_picks_by_the_stream():
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    assert isinstance(bar(total=3, file=io.StringIO()), LineProgress)
    assert isinstance(bar(total=3, file=Terminal()), tqdm)
    silent = bar(total=3, file=io.StringIO(), show=False)
    assert isinstance(silent, tqdm) and silent.disable


@pytest.mark.skipif(not LEGO_TINY.is_file(), reason="shared test data not present")
def test_a_fit_piped_to_a_log_prints_plain_bounded_lines(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "windowshop", "fit", str(LEGO_TINY), "--views", "5", "--test-views", "1",
         "--set", "voxels=4096", "--set", "hidden=16", "--iters", "100", "--out", str(tmp_path / "run"),
         "--device", "cpu"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "\r" not in done.stderr and "\r" not in done.stdout
    fit_lines = [line for line in done.stderr.splitlines() if line.startswith("fit: ")]
    assert 1 <= len(fit_lines) <= 30  # 100 steps: a line every 5 s, not one per step
    assert fit_lines[-1].startswith("fit: 100/100 step (100%)")


def test_a_prepare_stage_called_back_past_its_count_stops_full(capsys):
    """The mapper calls back once per photo for every start it tries: the bar stops at the
    photos' count instead of showing 10/4 (250%)."""
    from windowshop.photos.progress import Stages

    with Stages(show=True).stage("placing cameras", 4) as advance:
        for _ in range(10):
            advance(1)
    shown = capsys.readouterr().err
    assert "placing cameras: 4/4" in shown
    assert not any(f"{n}/4" in shown for n in range(5, 11))
