"""The trainer, ray batches, run folders, resume and chunked rendering, on hand-built scenes."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from windowshop.config import FastConfig, FitConfig, NerfConfig, SceneOptions
from windowshop.field.fast import FastModel, with_priors
from windowshop.fit.batches import PixelBank
from windowshop.fit.checkpoint import load_checkpoint, load_run
from windowshop.fit.evaluate import comparison_image, evaluate_run, mean_color_psnr
from windowshop.fit.trainer import (Progress, TrainingBackground, capped_by_passes, fit, masked_training,
                                    training_pixels)
from windowshop.model import Bounds
from windowshop.rays import camera_rays
from windowshop.render.frames import render_camera
from windowshop.scene.types import Camera, Scene, View

TINY = NerfConfig(freqs=2, view_dependent=False, depth=2, width=16, n_coarse=8, n_fine=0)


def look_at(eye, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(4, 4) OpenGL camera-to-world matrix of a camera at `eye` looking at `target`."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    back = (eye - target) / np.linalg.norm(eye - target)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, np.cross(back, right), back], axis=1)
    c2w[:3, 3] = eye
    return c2w


def toy_scene(size=12, background="white", alpha=False) -> Scene:
    """Four training and one test camera around the origin; images of one flat colour."""
    views = []
    for i, angle in enumerate(np.linspace(0, 2 * np.pi, 5, endpoint=False)):
        eye = (3 * np.cos(angle), 3 * np.sin(angle), 1.0)
        # numpy scalars, as readers produce them: the checkpoint must still load weights-only
        camera = Camera(fx=np.float64(size), fy=np.float32(size), cx=size / 2, cy=size / 2,
                        width=np.int64(size), height=size, c2w=look_at(eye))
        image = np.full((size, size, 3), (0.8, 0.4, 0.2), dtype=np.float32)
        mask = np.ones((size, size), dtype=np.float32) * 0.5 if alpha else None
        views.append(View(camera, image, "test" if i == 4 else "train", f"view_{i}.png", mask))
    return Scene(views=views, format="hand", source=Path("toy"), aabb=np.array([[-1.0] * 3, [1.0] * 3]),
                 near=1.5, far=4.5, background=background)


def test_pixel_bank_rays_are_the_cameras_rays():
    scene = toy_scene()
    views = scene.split("train")
    views[1].image = np.random.default_rng(0).random(views[1].image.shape).astype(np.float32)
    bank = PixelBank(views, "cpu")
    index = torch.tensor([0, 5, 144 + 37, 3 * 144 + 143])
    batch = bank.rays(index)
    for k, (view, pixel) in enumerate([(0, 0), (0, 5), (1, 37), (3, 143)]):
        origins, directions = camera_rays(views[view].camera)
        assert torch.allclose(batch.origins[k], origins[pixel], atol=1e-6)
        assert torch.allclose(batch.directions[k], directions[pixel], atol=1e-6)
        assert torch.equal(batch.rgb[k], torch.from_numpy(views[view].image.reshape(-1, 3)[pixel]))


def test_alpha_targets_use_the_same_background_as_the_render():
    bank = PixelBank(toy_scene(alpha=True).split("train"), "cpu", use_alpha=True)
    batch = bank.sample(6)
    bg = torch.rand(6, 3)
    assert torch.allclose(batch.target(bg), 0.5 * batch.rgb + 0.5 * bg)


def test_composited_targets_swap_the_stored_background_for_the_new_one():
    # a straight colour c at alpha a stored over white is c a + (1 - a); over b it must be c a + b (1 - a)
    scene = toy_scene(alpha=True)
    straight = torch.tensor([0.8, 0.4, 0.2])
    for view in scene.views:
        view.image = (view.image * view.alpha[..., None] + (1 - view.alpha[..., None])).astype(np.float32)
    bank = PixelBank(scene.split("train"), "cpu", use_alpha=True, over=(1.0, 1.0, 1.0))
    bg = torch.rand(6, 3)
    assert torch.allclose(bank.sample(6).target(bg), 0.5 * straight + 0.5 * bg, atol=1e-6)


def test_masked_training_of_mattes_over_white_only_when_the_model_asks():
    scene = toy_scene(alpha=True)  # composited over white, every view with its matte
    few = FastModel.for_scene(FastConfig(), scene)  # 4 training photos: few
    many = dataclasses.replace(few, masked=False)
    assert masked_training(scene, few) and not masked_training(scene, many)
    assert not masked_training(scene, TINY)  # the NeRF has no such prior
    bank, background = training_pixels(scene, few, "cpu")
    assert background == TrainingBackground("alpha", "white", 1.0)  # few photos: masked to the end
    assert bank.alpha is not None and torch.equal(bank.over, torch.ones(3))
    bank, background = training_pixels(scene, many, "cpu")
    assert background == TrainingBackground("white") and bank.alpha is None
    assert not masked_training(toy_scene(), few)  # no mattes: nothing to mask with


def test_masked_training_returns_to_the_scenes_own_colour_late_unless_it_has_none():
    over_white = toy_scene(alpha=True)
    config = dataclasses.replace(FastModel.for_scene(FastConfig(), over_white), masked_until=0.5)
    _, background = training_pixels(over_white, config, "cpu")
    assert [background.at(f) for f in (0.0, 0.49, 0.5, 1.0)] == ["alpha", "alpha", "white", "white"]
    straight = toy_scene(alpha=True)
    straight.background = "alpha"  # mattes with no colour of their own: random colours throughout
    _, background = training_pixels(straight, config, "cpu")
    assert [background.at(f) for f in (0.0, 0.5, 1.0)] == ["alpha"] * 3
    assert TrainingBackground("white").at(0.9) == "white"


def test_few_photo_priors_switch_on_at_or_under_few_views():
    few, many = with_priors(FastConfig(), 20), with_priors(FastConfig(), 21)
    assert (few.distortion, few.tv_features, few.tv_density, few.max_passes, few.masked_until) == (
        0.01, 0.003, 1e-4, 50, 1.0)
    assert (many.distortion, many.tv_features, many.tv_density, many.max_passes, many.masked_until
            ) == (0, 0, 0, 0, 0.5)
    assert few.masked and many.masked  # mattes train over random colours at any count
    assert with_priors(FastConfig(distortion=0.5, masked=False), 8).distortion == 0.5
    assert not with_priors(FastConfig(distortion=0.5, masked=False), 8).masked
    assert with_priors(FastConfig(), None).distortion == 0.0  # a model built without a scene
    # many photos train at about the render step and threshold; few keep the finer ones
    assert (few.step, few.weight_threshold) == (0.5, 1e-4)
    assert (many.step, many.weight_threshold) == (0.7, 3e-3)
    assert with_priors(FastConfig(step=0.6, weight_threshold=1e-3), 8).step == 0.6
    assert with_priors(FastConfig(step=0.6, weight_threshold=1e-3), 30).weight_threshold == 1e-3


def test_few_photos_stop_after_their_passes_over_the_pixels():
    model = FastModel(FastConfig(voxels=8**3, max_passes=2.5), Bounds.of_scene(toy_scene()))
    by_time = FitConfig(iters=None, seconds=60, batch_rays=100)
    assert capped_by_passes(by_time, model, 1000).iters == 25  # 2.5 * 1000 pixels / 100 a step
    assert capped_by_passes(FitConfig(iters=20, batch_rays=100), model, 1000).iters == 20
    assert capped_by_passes(FitConfig(iters=30, batch_rays=100), model, 1000).iters == 25
    model.config = dataclasses.replace(model.config, max_passes=0.0)
    assert capped_by_passes(by_time, model, 1000) == by_time


def test_a_fit_on_few_photos_stops_after_its_passes(tmp_path):
    scene = toy_scene()
    pixels = sum(v.camera.width * v.camera.height for v in scene.split("train"))
    metrics = fit(scene, "fast", FastConfig(voxels=8**3, max_passes=1.0),
                  FitConfig(iters=None, seconds=600, batch_rays=64), tmp_path, "cpu",
                  show_progress=False)
    assert metrics["iterations"] == -(-pixels // 64) and metrics["stopped_by_passes"]
    assert json.loads((tmp_path / "config.json").read_text())["fit_config"]["iters"] == -(-pixels // 64)


def test_progress_follows_steps_or_seconds():
    assert Progress(step=50).fraction(FitConfig(iters=200)) == 0.25
    assert Progress(step=50, elapsed=30).fraction(FitConfig(iters=None, seconds=60)) == 0.5
    assert Progress(step=150, elapsed=30).fraction(FitConfig(iters=200, seconds=60)) == 0.75


def test_fit_writes_a_complete_run_folder(tmp_path):
    scene = toy_scene()
    scene.options = SceneOptions(views=4)  # as load_scene records the options it loaded with
    metrics = fit(scene, "nerf", TINY, FitConfig(iters=4, batch_rays=32, log_every=2), tmp_path / "run",
                  "cpu", show_progress=False)
    run_dir = tmp_path / "run"
    saved = json.loads((run_dir / "metrics.json").read_text())
    for key in ("psnr", "ssim", "test_views", "train_seconds", "iterations"):
        assert saved[key] == pytest.approx(metrics[key])
    assert saved["iterations"] == 4 and saved["test_views"] == 1
    config = json.loads((run_dir / "config.json").read_text())
    assert config["model"] == "nerf" and config["model_config"]["width"] == 16
    assert config["scene"]["options"]["views"] == 4
    lines = [json.loads(x) for x in (run_dir / "log.jsonl").read_text().splitlines()]
    assert [x["step"] for x in lines] == [1, 2, 4]
    assert {"loss", "psnr", "rays_per_s", "samples_per_s", "lr"} <= set(lines[0])
    assert len(list((run_dir / "eval").glob("*.png"))) == 1


def test_load_run_rebuilds_the_same_model(tmp_path):
    scene = toy_scene()
    fit(scene, "nerf", TINY, FitConfig(iters=3, batch_rays=16), tmp_path, "cpu", show_progress=False)
    run = load_run(tmp_path, "cpu")
    assert run.step == 3 and run.model_name == "nerf" and run.background == "white"
    assert run.model.config == TINY and not run.model.training
    assert run.bounds.near == 1.5 and run.scene_source == "toy"
    assert len(run.train_cameras) == 4
    assert np.allclose(run.train_cameras[2].c2w, scene.split("train")[2].camera.c2w)
    state = load_checkpoint(tmp_path)
    assert state["model_state"].keys() == run.model.state_dict().keys()
    assert all(torch.equal(state["model_state"][k], v) for k, v in run.model.state_dict().items())


def test_resume_continues_from_the_saved_step(tmp_path):
    scene = toy_scene()
    config = FitConfig(iters=3, batch_rays=16, log_every=1)
    fit(scene, "nerf", TINY, config, tmp_path, "cpu", show_progress=False)
    before = load_checkpoint(tmp_path)
    # nothing left of a spent budget: the weights stay as saved
    fit(scene, "nerf", TINY, config, tmp_path, "cpu", resume=tmp_path, show_progress=False)
    same = load_checkpoint(tmp_path)
    assert same["step"] == 3
    assert all(torch.equal(before["model_state"][k], same["model_state"][k]) for k in same["model_state"])
    fit(scene, "nerf", TINY, dataclasses.replace(config, iters=5), tmp_path, "cpu", resume=tmp_path,
        show_progress=False)
    after = load_checkpoint(tmp_path)
    steps = [json.loads(x)["step"] for x in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert after["step"] == 5 and steps == [1, 2, 3, 4, 5]
    assert after["elapsed_seconds"] > before["elapsed_seconds"]
    assert after["optimizer_state"]["state"][0]["step"] == 5  # Adam's moments carried over


def test_final_checkpoint_without_the_optimizer_still_renders_and_resumes(tmp_path):
    """The video pipeline's runs drop Adam's state at the end: smaller, and still a whole run."""
    scene = toy_scene()
    config = FitConfig(iters=3, batch_rays=16, final_optimizer=False)
    fit(scene, "nerf", TINY, config, tmp_path, "cpu", show_progress=False)
    state = load_checkpoint(tmp_path)
    assert state["optimizer_state"] is None and state["step"] == 3
    run = load_run(tmp_path)
    assert render_camera(run.model, scene.views[0].camera).rgb.shape == (12, 12, 3)
    fit(scene, "nerf", TINY, dataclasses.replace(config, iters=5, final_optimizer=True), tmp_path,
        "cpu", resume=tmp_path, show_progress=False)
    after = load_checkpoint(tmp_path)
    assert after["step"] == 5
    assert after["optimizer_state"]["state"][0]["step"] == 2  # Adam started afresh at step 3


def test_chunked_rendering_matches_one_pass():
    torch.manual_seed(0)
    from windowshop.field.nerf import NerfModel

    model = NerfModel(TINY, Bounds.of_scene(toy_scene()))
    camera = toy_scene().views[0].camera
    ray = model.bytes_per_ray(training=False)  # a budget of 7 rays: the 144 rays in 21 chunks
    whole = render_camera(model, camera, memory_budget=int(10_000 * ray))
    chunked = render_camera(model, camera, memory_budget=int(7 * ray))
    assert whole.rgb.shape == (12, 12, 3) and whole.depth.shape == (12, 12)
    assert np.allclose(whole.rgb, chunked.rgb, atol=1e-6)
    assert np.allclose(whole.opacity, chunked.opacity, atol=1e-6)
    assert model.training  # the caller's mode is restored


def test_evaluate_run_uses_the_recorded_scene(tmp_path, monkeypatch):
    scene = toy_scene(background="alpha", alpha=True)
    fit(scene, "nerf", TINY, FitConfig(iters=2, batch_rays=16), tmp_path, "cpu", show_progress=False)
    (tmp_path / "metrics.json").unlink()
    import windowshop.scene as scene_module

    monkeypatch.setattr(scene_module, "load_scene", lambda path, options: scene, raising=False)
    metrics = evaluate_run(tmp_path, "cpu")
    assert metrics["iterations"] == 2 and metrics["test_views"] == 1
    assert json.loads((tmp_path / "metrics.json").read_text())["psnr"] == pytest.approx(metrics["psnr"])


def test_comparison_image_is_truth_render_error():
    truth = np.zeros((4, 5, 3))
    render = np.full((4, 5, 3), 0.1)
    panel = comparison_image(truth, render)
    assert panel.shape == (4, 15, 3) and panel.dtype == np.uint8
    assert panel[0, 0, 0] == 0 and panel[0, 5, 0] == 26 and panel[0, 10, 0] == 102


def test_mean_color_floor():
    scene = toy_scene()
    train, test = scene.split("train"), scene.split("test")
    for view, value in zip(train, (0.2, 0.6, 0.2, 0.6)):
        view.image = np.full_like(view.image, value)
    test[0].image = np.full_like(test[0].image, 0.5)  # mean 0.4 is off by 0.1: MSE 0.01, 20 dB
    assert mean_color_psnr(train, test, "white") == pytest.approx(20.0, abs=1e-4)


def test_fit_command_seconds_replace_the_step_budget(tmp_path, monkeypatch):
    import windowshop.scene as scene_module
    from windowshop.errors import UserError
    from windowshop.fit.command import fit_command

    monkeypatch.setattr(scene_module, "load_scene", lambda path, options: toy_scene(), raising=False)
    overrides = {"model": "nerf", "preset": "tiny", "depth": 2, "width": 16, "n_coarse": 8,
                 "freqs": 2, "seconds": 0.5, "batch_rays": 16}
    metrics = fit_command("toy", overrides, str(tmp_path), None, "cpu")
    assert metrics["iterations"] >= 1 and metrics["train_seconds"] >= 0.5
    assert json.loads((tmp_path / "config.json").read_text())["fit_config"]["iters"] is None
    with pytest.raises(UserError, match="fast.* has no setting n_fine; its settings: .*voxels"):
        fit_command("toy", {"n_fine": 0}, str(tmp_path / "x"), None, "cpu")
    with pytest.raises(UserError, match="must be an integer"):  # typed, as the study's switches
        fit_command("toy", {"model": "nerf", "depth": 2.5}, str(tmp_path / "y"), None, "cpu")
    with pytest.raises(UserError, match="resumed run keeps its model"):
        fit_command(None, {"width": 8}, None, str(tmp_path), "cpu")


def test_a_batch_over_the_memory_budget_gets_the_gradient_of_one_pass():
    from types import SimpleNamespace

    from windowshop.field.nerf import NerfModel
    from windowshop.fit.losses import loss_terms
    from windowshop.fit.trainer import _backward_in_chunks

    torch.manual_seed(0)
    model = NerfModel(TINY, Bounds.of_scene(toy_scene())).eval()  # eval: no jitter, same samples
    origins, directions = camera_rays(toy_scene().views[0].camera)
    bg, target = torch.ones_like(origins), torch.rand_like(origins)
    grads = []
    for rays_per_chunk in (10_000, 7):  # one pass, then 21 chunks
        budget = int(rays_per_chunk * model.bytes_per_ray(training=True))
        run = SimpleNamespace(model=model, config=FitConfig(memory_budget=budget),
                              losses=loss_terms(model.config), virtual=None)
        model.zero_grad(set_to_none=True)
        loss, error, samples = _backward_in_chunks(run, origins, directions, bg, target)
        grads.append(torch.cat([p.grad.flatten() for p in model.parameters()]))
        assert samples == 144 * TINY.n_coarse
    assert torch.allclose(grads[0], grads[1], atol=1e-6, rtol=1e-4)


def test_pixel_bank_draws_every_pixel_once_a_pass():
    views = toy_scene().split("train")
    n = sum(v.camera.width * v.camera.height for v in views)
    for i, view in enumerate(views):  # each pixel's red is its flat index in the bank
        start = sum(v.camera.width * v.camera.height for v in views[:i])
        view.image = np.repeat(np.arange(start, start + view.image.shape[0] * view.image.shape[1],
                                         dtype=np.float32).reshape(*view.image.shape[:2], 1), 3, -1)
    bank = PixelBank(views, "cpu")
    torch.manual_seed(0)
    drawn = torch.cat([bank.sample(100).rgb[:, 0] for _ in range(2 * n // 100 + 1)]).long()
    first, second = drawn[:n], drawn[n:2 * n]  # batches of 100 straddle the passes' edge
    assert torch.equal(first.sort().values, torch.arange(n))
    assert torch.equal(second.sort().values, torch.arange(n))
    assert not torch.equal(first, second)  # each pass in a fresh order
