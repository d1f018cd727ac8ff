"""Each photo's exposure and white balance, solved from the points photos share, and taken out."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from windowshop.config import PrepareOptions
from windowshop.photos import exposure
from windowshop.photos.prepare import prepare
from windowshop.photos.report import summary_lines
from shared_data import DATA


def _observations(rng, exposures: np.ndarray, points: int, per_point: int, noise: float):
    """Each point seen by `per_point` random photos: (images, points, log colours)."""
    photos = len(exposures)
    colour = rng.uniform(np.log(0.1), np.log(0.8), (points, 3))
    images = np.concatenate([rng.choice(photos, per_point, replace=False) for _ in range(points)])
    ids = np.repeat(np.arange(points), per_point)
    logs = np.log(exposures)[images] + colour[ids] + rng.normal(0, noise, (len(ids), 3))
    return images, ids, logs


def test_exposures_are_recovered_past_highlights_and_held_to_their_bounds():
    rng = np.random.default_rng(0)
    truth = np.exp(rng.uniform(-0.3, 0.3, (8, 3)))
    truth[5] = [3.0, 1.0, 1.0]  # a red cast beyond what is taken out
    images, points, logs = _observations(rng, truth, 400, 4, 0.01)
    highlights = rng.random(len(logs)) < 0.1  # a tenth of the pixels far off their point's colour
    logs[highlights] += rng.uniform(0.3, 1.0, (highlights.sum(), 1))
    found = exposure.solve(images, points, logs, 8)
    expected = truth / np.median(truth, axis=0)  # scaled to the photos' median
    others = np.arange(8) != 5
    assert np.allclose(found[others], expected[others], rtol=0.02)
    assert found[5, 0] == pytest.approx(exposure.MAX_EXPOSURE)
    # a photo seen by too few of the points keeps its colours
    few = np.flatnonzero(images == 2)[exposure.MIN_OBSERVATIONS - 1:]
    found = exposure.solve(np.delete(images, few), np.delete(points, few), np.delete(logs, few, 0), 8)
    assert np.all(found[2] == 1.0)


def test_evened_divides_each_channel_and_stays_in_range():
    pixels = np.array([[[100, 200, 250]]], np.uint8)
    assert exposure.evened(pixels, np.array([2.0, 0.5, 0.5])).tolist() == [[[50, 255, 255]]]
    assert exposure.negligible(np.array([1.005, 0.995, 1.0]))
    assert not exposure.negligible(np.array([1.0, 1.0, 1.03]))


@pytest.fixture(scope="module")
def kermit_in_two_lights(tmp_path_factory):
    """kermit's photos as taken, and each with its own white balance and exposure (a phone that
    sets them anew for every shot), prepared at the defaults: (gains, plain, cast) scene folders."""
    root = tmp_path_factory.mktemp("exposure")
    rng = np.random.default_rng(1)
    photos = sorted((DATA / "kermit").glob("*.jpg"))
    gains = np.exp(rng.uniform(-0.15, 0.15, (len(photos), 3)))
    (root / "cast").mkdir()
    for path, gain in zip(photos, gains):
        pixels = np.asarray(Image.open(path).convert("RGB"), np.float32) * gain
        Image.fromarray(np.clip(np.rint(pixels), 0, 255).astype(np.uint8)).save(
            root / "cast" / f"{path.stem}.png")
    prepare(DATA / "kermit", root / "plain", PrepareOptions(), show=False)
    prepare(root / "cast", root / "scene", PrepareOptions(), show=False)
    return dict(zip((p.stem for p in photos), gains)), root / "plain", root / "scene"


def test_a_capture_whose_colours_change_shot_to_shot_is_evened_out(kermit_in_two_lights):
    gains, plain, cast = kermit_in_two_lights
    seen = {k: np.array(v) for k, v in json.loads((cast / "report.json").read_text())["exposures"].items()}
    before = {k: np.array(v) for k, v in json.loads((plain / "report.json").read_text())["exposures"].items()}
    names = sorted(set(gains) & {p.stem for p in (plain / "images").glob("*.jpg")}
                   & {p.stem for p in (cast / "images").glob("*.jpg")})
    assert len(names) >= 10
    report = json.loads((cast / "report.json").read_text())
    most = max(max(v, 1 / v) for e in seen.values() for v in e)
    assert f"  exposure and white balance evened out on {len(seen)} of {report['placed']} photos " \
           f"(the furthest off by a factor of {most:.2f})" in summary_lines(report)
    # the cast found is the one given, on top of the photos' own (up to the median's scale); a
    # photo left out of the report was within 1% of the median
    ratio = np.stack([seen.get(n, np.ones(3)) / (gains[n] * before.get(n, np.ones(3)))
                      for n in names])
    assert np.abs(ratio / np.median(ratio, axis=0) - 1).max() < 0.05
    # the scene's images now show each point in one colour: near the photos as taken
    def pixels(folder, name):
        return np.asarray(Image.open(folder / "images" / f"{name}.jpg"), np.float32)

    evened = np.mean([np.abs(pixels(cast, n) * np.median(ratio, 0) - pixels(plain, n)).mean()
                      for n in names])
    given = np.mean([np.abs(np.asarray(Image.open(DATA / "kermit" / f"{n}.jpg"), np.float32)
                            * gains[n] - pixels(plain, n)).mean() for n in names])
    assert evened < 0.35 * given


def test_exposures_left_alone_when_asked(tmp_path):
    photos = sorted((DATA / "kermit").glob("*.jpg"))
    (tmp_path / "cast").mkdir()
    for k, path in enumerate(photos):
        pixels = np.asarray(Image.open(path).convert("RGB"), np.float32) * (0.8 if k % 2 else 1.0)
        Image.fromarray(np.rint(pixels).astype(np.uint8)).save(tmp_path / "cast" / f"{path.stem}.png")
    prepare(tmp_path / "cast", tmp_path / "scene", PrepareOptions(even_exposure=False), show=False)
    assert json.loads((tmp_path / "scene" / "report.json").read_text())["exposures"] == {}
    written = np.asarray(Image.open(tmp_path / "scene" / "images" / "kermit001.jpg"), np.float32)
    given = np.asarray(Image.open(tmp_path / "cast" / "kermit001.png"), np.float32)
    assert np.abs(written - given).mean() < 2.0
