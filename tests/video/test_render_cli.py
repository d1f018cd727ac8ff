"""`windowshop render` through the real CLI, and the turntable loop with an exact sphere model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from windowshop.cli import main
from windowshop.config import FitConfig, VideoOptions
from windowshop.model import Bounds, RadianceModel, RenderOutput, model_config
from windowshop.scene.synthetic import orbit_cameras, synthetic_scene
from windowshop.scene.types import Camera
from windowshop.video.encode import VideoOutputs, read_video
from windowshop.video.paths import read_camera_path, turntable_path, write_camera_path
from windowshop.video.turntable import VIDEO_BACKGROUNDS, default_outputs, depth_range, render_turntable

RED = (0.9, 0.1, 0.1)


class Sphere(RadianceModel):
    """An opaque red sphere of `radius` at the origin, ray-traced exactly (a test double).

    It records the largest batch it was asked to render, to check that frames come in chunks.
    """

    name = "sphere"

    def __init__(self, radius: float = 0.5):
        super().__init__(None, Bounds(aabb=((-1.0,) * 3, (1.0,) * 3), near=0.5, far=8.0))
        self.radius, self.largest_batch = radius, 0

    def render_rays(self, origins, directions, background) -> RenderOutput:
        self.largest_batch = max(self.largest_batch, len(origins))
        b = (origins * directions).sum(-1)
        disc = b * b - ((origins * origins).sum(-1) - self.radius ** 2)
        hit = disc > 0
        t = torch.where(hit, -b - disc.clamp(min=0).sqrt(), torch.zeros_like(b))
        red = torch.tensor(RED).expand_as(background)
        rgb = torch.where(hit[:, None], red, background)
        return RenderOutput(rgb=rgb, depth=t, opacity=hit.float())


def red_mask(frame: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels of a decoded uint8 frame that show the red sphere."""
    return (frame[..., 0] > 150) & (frame[..., 1] < 100)


def test_sphere_stays_centred_and_the_same_size_in_every_frame(tmp_path):
    model = Sphere()
    train = orbit_cameras(12, 32, radius=3.0)
    # a fixed radius and field of view: the box (a cube) would otherwise be framed frame by frame
    cameras = turntable_path(train, VideoOptions(frames=10, width=64, height=48, radius=3.0, fov=40.0),
                             model.bounds)
    done = []
    result = render_turntable(model, cameras, VideoOutputs(mp4=tmp_path / "s.mp4",
                                                           depth=tmp_path / "d.mp4"),
                              fps=10, memory_budget=int(500 * model.bytes_per_ray(training=False)),
                              progress=False,
                              on_frame=lambda k, n: done.append((k, n)))
    assert model.largest_batch == 500  # frames of 3072 rays were rendered 500 at a time (the budget's worth)
    assert done == [(k, 10) for k in range(1, 11)]
    assert result.frames == 10 and result.files == [tmp_path / "s.mp4", tmp_path / "d.mp4"]
    _, frames = read_video(tmp_path / "s.mp4")
    areas = []
    for frame in frames:
        rows, cols = np.nonzero(red_mask(frame))
        assert abs(rows.mean() + 0.5 - 24) < 0.5 and abs(cols.mean() + 0.5 - 32) < 0.5
        areas.append(len(rows))
    assert max(areas) - min(areas) <= 0.03 * np.mean(areas)
    # the sphere's expected disc: radius 0.5 at distance 3 seen with the path's focal
    focal = cameras[0].fy
    expected = np.pi * (focal * 0.5 / np.sqrt(3.0 ** 2 - 0.5 ** 2)) ** 2
    assert np.mean(areas) == pytest.approx(expected, rel=0.1)
    _, depth_frames = read_video(tmp_path / "d.mp4")
    depth = next(depth_frames).astype(float)
    assert depth[24, 32].sum() > 200 and depth[2, 2].sum() < 10  # a bright surface on black


def test_a_transparent_turntable_shows_the_object_opaque_on_a_clear_ground(tmp_path):
    model = Sphere()
    cameras = turntable_path(orbit_cameras(12, 32, radius=3.0), VideoOptions(frames=3, width=32, height=32),
                             model.bounds)
    outputs = default_outputs(tmp_path / "s.webm", poster=True, frames_dir=tmp_path / "f",
                              transparent=True)
    render_turntable(model, cameras, outputs, fps=10, background=VIDEO_BACKGROUNDS["transparent"],
                     progress=False)
    _, frames = read_video(tmp_path / "s.webm", alpha=True)
    images = [*frames, np.asarray(Image.open(tmp_path / "s_poster.png")),
              *(np.asarray(Image.open(f)) for f in sorted((tmp_path / "f").glob("*.png")))]
    assert len(images) == 3 + 1 + 3
    for image in images:
        assert image.shape == (32, 32, 4)
        assert image[16, 16, 3] > 245 and red_mask(image[14:18, 14:18, :3]).all()  # the sphere
        assert max(image[0, 0, 3], image[0, -1, 3], image[-1, 0, 3], image[-1, -1, 3]) < 10


def test_depth_range_spans_the_box_as_the_path_sees_it():
    cameras = [Camera(10.0, 10.0, 8.0, 8.0, 16, 16, np.eye(4)) for _ in range(2)]
    cameras[0].c2w[:3, 3], cameras[1].c2w[:3, 3] = [5.0, 0.0, 0.0], [0.0, -4.0, 0.0]
    box = ((-1.0,) * 3, (1.0,) * 3)
    near, far = depth_range(cameras, Bounds(aabb=box, near=0.1, far=100.0))
    assert near == pytest.approx(3.0) and far == pytest.approx(np.sqrt(38.0))  # face, far corner
    assert depth_range(cameras, Bounds(aabb=box, near=3.5, far=5.0)) == (3.5, 5.0)  # rays stop there


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A briefly trained tiny NeRF of the built-in object (only its rendering is under test)."""
    from windowshop.fit.trainer import fit

    out = tmp_path_factory.mktemp("run")
    scene = synthetic_scene(n_train=8, n_test=1, size=16)
    config = model_config("nerf", "tiny", width=32, depth=2, n_coarse=16)
    fit(scene, "nerf", config, FitConfig(iters=5, batch_rays=64), out, "cpu", show_progress=False)
    return out


def test_render_cli_writes_every_output(run_dir, tmp_path, capsys):
    out = tmp_path / "spin.mp4"
    code = main(["render", str(run_dir), "--out", str(out), "--frames", "9", "--fps", "12",
                 "--size", "32x24", "--gif", "--webp", "--depth", "--poster", "--frames-dir",
                 str(tmp_path / "frames"), "--frames-format", "jpg", "--device", "cpu"])
    assert code == 0
    for video in (out, tmp_path / "spin_depth.mp4"):
        meta, frames = read_video(video)
        assert (meta["size"], meta["fps"], sum(1 for _ in frames)) == ((32, 24), 12.0, 9)
    for animation in ("spin.gif", "spin.webp"):
        with Image.open(tmp_path / animation) as im:
            assert im.n_frames == 9 and im.size == (32, 24)
    assert Image.open(tmp_path / "spin_poster.jpg").size == (32, 24)
    assert len(list((tmp_path / "frames").glob("frame_*.jpg"))) == 9
    # the frames folder says which camera made each frame
    from windowshop.fit.checkpoint import load_run

    run = load_run(run_dir)
    expected = turntable_path(run.train_cameras, VideoOptions(frames=9, width=32, height=24), run.bounds)
    saved = read_camera_path(tmp_path / "frames" / "camera_path.json")
    np.testing.assert_allclose(np.stack([c.c2w for c in saved]), np.stack([c.c2w for c in expected]),
                               atol=1e-9)
    assert "wrote" in capsys.readouterr().out
    # the run remembers what the turntable showed: the path, the photos' arc, the poster's frame
    summary = json.loads((run_dir / "render.json").read_text())
    assert summary["path"] == "orbit" and summary["frames"] == 9 and summary["background"] == "white"
    assert 0 < summary["covered_span_degrees"] <= 360 and 0 <= summary["poster_frame"] < 9


def test_render_cli_transparent_writes_a_webm_and_pngs_with_alpha(run_dir, tmp_path, capsys):
    out = tmp_path / "t.webm"
    assert main(["render", str(run_dir), "--out", str(out), "--background", "transparent",
                 "--frames", "3", "--size", "16", "--poster", "--frames-dir", str(tmp_path / "f"),
                 "--device", "cpu"]) == 0
    meta, frames = read_video(out, alpha=True)
    assert meta["codec"] == "vp9" and [f.shape for f in frames] == [(16, 16, 4)] * 3
    for png in [tmp_path / "t_poster.png", *sorted((tmp_path / "f").glob("frame_*.png"))]:
        assert Image.open(png).mode == "RGBA"
    assert json.loads((run_dir / "render.json").read_text())["background"] == "transparent"
    code = main(["render", str(run_dir), "--out", str(tmp_path / "t.mp4"), "--background",
                 "transparent", "--device", "cpu"])
    assert code == 2 and "webm" in capsys.readouterr().err and not (tmp_path / "t.mp4").exists()
    code = main(["render", str(run_dir), "--out", str(tmp_path / "t"), "--device", "cpu"])
    assert code == 2 and "name the video .mp4" in capsys.readouterr().err and not (tmp_path / "t").exists()


def test_render_cli_follows_a_camera_path_file(run_dir, tmp_path):
    cameras = turntable_path(orbit_cameras(8, 16), VideoOptions(frames=5, width=20, height=16),
                             Bounds(aabb=((-1.0,) * 3, (1.0,) * 3), near=0.1, far=10.0))
    path = write_camera_path(cameras, tmp_path / "path.json")
    out = tmp_path / "custom.mp4"
    assert main(["render", str(run_dir), "--out", str(out), "--path", str(path), "--fps", "5",
                 "--device", "cpu"]) == 0
    meta, frames = read_video(out)
    assert meta["size"] == (20, 16) and sum(1 for _ in frames) == 5


def test_render_cli_spiral(run_dir, tmp_path):
    out = tmp_path / "spiral.mp4"
    assert main(["render", str(run_dir), "--out", str(out), "--path", "spiral", "--frames", "4",
                 "--size", "16", "--device", "cpu"]) == 0
    assert sum(1 for _ in read_video(out)[1]) == 4


@pytest.mark.parametrize("extra,message", [(["--size", "33"], "even"), (["--size", "big"], "--size"),
                                           (["--fps", "0"], "--fps"),
                                           (["--path", "nowhere.json"], "nowhere.json"),
                                           (["--frames", "0"], "--frames")])
def test_render_cli_bad_input_is_a_clear_error(run_dir, tmp_path, capsys, extra, message):
    code = main(["render", str(run_dir), "--out", str(tmp_path / "x.mp4"), "--device", "cpu", *extra])
    assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "x.mp4").exists()


def test_render_cli_names_a_missing_run(tmp_path, capsys):
    code = main(["render", str(tmp_path / "norun"), "--out", str(tmp_path / "x.mp4")])
    assert code == 2 and "norun" in capsys.readouterr().err


def test_camera_path_json_from_the_frames_folder_is_valid_nerfstudio(run_dir, tmp_path):
    main(["render", str(run_dir), "--out", str(tmp_path / "a.mp4"), "--frames", "3", "--size", "16",
          "--frames-dir", str(tmp_path / "f"), "--device", "cpu"])
    doc = json.loads((tmp_path / "f" / "camera_path.json").read_text())
    assert doc["render_width"] == 16 and doc["seconds"] == pytest.approx(3 / 30)
    assert all(len(c["camera_to_world"]) == 16 for c in doc["camera_path"])
