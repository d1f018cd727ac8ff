"""Cameras are right when known 3D points land on the right pixels (not when shapes match)."""

from pathlib import Path

import numpy as np
import pycolmap
import pytest

from windowshop.config import SceneOptions
from windowshop.rays import project
from windowshop.scene import load_scene, read_source
from windowshop.scene.distortion import Distortion, distort_pixels
from shared_data import DATA

BEER_MODEL = DATA / "beer_can" / "sparse" / "0"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason="shared datasets not present")


def to_scene(points: np.ndarray, transform: np.ndarray) -> np.ndarray:
    return points @ transform[:3, :3].T + transform[:3, 3]


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity (s, R, t) minimising |dst - (s R src + t)|^2 over points (N, 3)."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    u, sig, vt = np.linalg.svd(b.T @ a / len(src))
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ fix @ vt
    scale = np.trace(np.diag(sig) @ fix) / (a ** 2).sum(1).mean()
    return scale, rot, mu_d - scale * rot @ mu_s


@pytest.fixture(scope="module")
def beer_colmap():
    return load_scene(BEER_MODEL, SceneOptions(downscale=8))


def test_colmap_points_project_where_pycolmap_projects_them(beer_colmap):
    rec = pycolmap.Reconstruction(str(BEER_MODEL))
    by_name = {im.name: im for im in rec.images.values()}
    checked = 0
    for view in beer_colmap.views:
        image = by_name[Path(view.name).name]
        # pycolmap's own projection of every point seen by this image (pixels of the stored image)
        world = np.array([rec.points3D[p.point3D_id].xyz for p in image.points2D if p.has_point3D()])
        ref = np.array([image.project_point(x) for x in world])
        # ours: the normalised pinhole camera, then back through the lens model to stored pixels
        uv, depth = project(to_scene(world, beer_colmap.transform), view.camera)
        stored = view.stored_camera.resized(view.camera.width, view.camera.height)
        ours = distort_pixels(uv, view.camera, stored, Distortion(**view.distortion))
        ours = ours * np.array([view.stored_camera.width / view.camera.width,
                                view.stored_camera.height / view.camera.height])
        assert np.all(depth > 0)
        assert np.abs(ours - ref).max() < 0.5
        checked += len(world)
    assert checked > 10000


def test_colmap_observations_match_our_projection_within_reprojection_error(beer_colmap):
    """Independent of pycolmap's projection: the 2D keypoints COLMAP measured."""
    rec = pycolmap.Reconstruction(str(BEER_MODEL))
    by_name = {im.name: im for im in rec.images.values()}
    view = beer_colmap.views[5]
    image = by_name[Path(view.name).name]
    obs = [(p.xy, rec.points3D[p.point3D_id].xyz) for p in image.points2D if p.has_point3D()]
    xy, xyz = np.array([o[0] for o in obs]), np.array([o[1] for o in obs])
    uv, _ = project(to_scene(xyz, beer_colmap.transform), view.camera)
    stored = view.stored_camera.resized(view.camera.width, view.camera.height)
    ours = distort_pixels(uv, view.camera, stored, Distortion(**view.distortion)) * 8
    assert np.median(np.linalg.norm(ours - xy, axis=-1)) < 2.0


def test_llff_and_colmap_give_the_same_camera_centres_up_to_a_similarity():
    llff = read_source(DATA / "beer_can")
    colmap = read_source(BEER_MODEL)
    assert (llff.format, colmap.format) == ("llff", "colmap")
    a = np.stack([f.camera.center for f in llff.frames])
    b = np.stack([f.camera.center for f in colmap.frames])
    scale, rot, t = umeyama(a, b)
    residual = np.linalg.norm(b - (scale * a @ rot.T + t), axis=-1)
    assert residual.max() < 1e-3 * np.linalg.norm(b - b.mean(0), axis=-1).mean()
    # the viewing directions agree too once rotated
    dirs_a = np.stack([-f.camera.c2w[:3, 2] for f in llff.frames]) @ rot.T
    dirs_b = np.stack([-f.camera.c2w[:3, 2] for f in colmap.frames])
    assert np.min(np.sum(dirs_a * dirs_b, axis=-1)) > 0.9999


def test_temples_published_box_projects_inside_all_16_images():
    scene = load_scene(DATA / "temple_sparse", SceneOptions(downscale=4))
    assert scene.format == "middlebury" and len(scene.views) == 16
    lo = np.array([-0.073568, 0.021728, -0.012445])
    hi = np.array([0.028855, 0.181892, 0.062736])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    for view in scene.views:
        uv, depth = project(to_scene(corners, scene.transform), view.camera)
        assert np.all(depth > 0)
        assert np.all((uv >= 0) & (uv <= [view.camera.width, view.camera.height])), view.name
        # and the box is not a speck: it covers a good part of the image
        assert np.ptp(uv[:, 0]) > 0.2 * view.camera.width


def test_every_lego_camera_looks_at_the_origin():
    source = read_source(DATA / "lego")
    assert source.format == "blender" and len(source.frames) == 400
    for frame in source.frames:
        origin, forward = frame.camera.center, -frame.camera.c2w[:3, 2]
        closest = origin - (origin @ forward) * forward  # the optical axis' point nearest to 0
        assert np.linalg.norm(closest) < 1e-4
        uv, _ = project(np.zeros((1, 3)), frame.camera)  # so the origin is the image centre
        np.testing.assert_allclose(uv[0], [frame.camera.cx, frame.camera.cy], atol=1e-3)


def test_lego_tiny_and_lego_agree_on_the_shared_views():
    tiny = read_source(DATA / "lego_tiny.npz")
    lego = read_source(DATA / "lego")
    train = [f for f in lego.frames if f.split == "train"]
    for a, b in zip(tiny.frames[:100], train):
        np.testing.assert_allclose(a.camera.c2w, b.camera.c2w, atol=1e-5)
        assert a.camera.fx == pytest.approx(b.camera.fx * 100 / 400, rel=1e-5)
