"""Refining the texture by least squares: a plane photographed from a few cameras, its texture
baked wrong (blurred, or one flat colour), is drawn right again."""

import numpy as np
import pytest
from scipy import ndimage

from export_helpers import square
from windowshop.export.photos import Photos
from windowshop.export.raster import render_mesh
from windowshop.export.refine import refine_texture
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

SIZE = 32  # texels a side
SUPERSAMPLE = 2  # samples a pixel side of the photos (anti-aliased)
UV = np.array([[2.0, 30.0], [30.0, 30.0], [30.0, 2.0], [2.0, 2.0]]) / SIZE  # the square's texels


def true_texture() -> np.ndarray:
    """(SIZE, SIZE, 3) float in [0, 1]: a pattern of about 8 texels' period."""
    y, x = np.mgrid[:SIZE, :SIZE] + 0.5
    value = 0.5 + 0.35 * np.sin(2 * np.pi * x / 8) * np.cos(2 * np.pi * y / 11)
    return np.stack([value, 1 - value, 0.5 + 0 * value], -1)


def photographed(texture: np.ndarray, eye: list[float], pixels: int = 48) -> tuple[Camera,
                                                                                    np.ndarray]:
    """A camera at `eye` looking at the square and what it sees there, anti-aliased."""
    c2w = look_at(np.array(eye), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    camera = Camera(fx=2.0 * pixels, fy=2.0 * pixels, cx=pixels / 2, cy=pixels / 2,
                    width=pixels, height=pixels, c2w=c2w)
    k = SUPERSAMPLE
    vertices, faces = square(0.0, 0.5)
    image, _ = render_mesh(vertices, faces, camera.resized(pixels * k, pixels * k), uv=UV,
                           texture=np.round(texture * 255).astype(np.uint8))
    return camera, image.reshape(pixels, k, pixels, k, 3).mean((1, 3))


def photos(texture: np.ndarray) -> Photos:
    """The square from above and from 25 degrees off to three sides."""
    shots = [photographed(texture, eye) for eye in
             ([0.0, 0.0, 2.0], [0.85, 0.0, 1.8], [-0.85, 0.0, 1.8], [0.0, 0.85, 1.8])]
    return Photos([c for c, _ in shots], [i for _, i in shots], [None] * len(shots))


@pytest.mark.parametrize("wrong", ["blurred", "flat"])
def test_a_wrong_texture_is_refined_to_the_photographed_one(wrong):
    truth = true_texture()
    start = (ndimage.uniform_filter(truth, (5, 5, 1)) if wrong == "blurred"
             else np.full_like(truth, 0.5))
    vertices, faces = square(0.0, 0.5)
    refined = refine_texture(vertices, faces, UV, start.astype(np.float32), photos(truth))
    inner = (slice(4, SIZE - 4), slice(4, SIZE - 4))  # away from the square's rim
    before = np.abs(start - truth)[inner].mean()
    after = np.abs(refined - truth)[inner].mean()
    assert before > 0.05
    assert after < 0.02
    # and a view no photo was taken from sees it right too
    _, seen = photographed(truth, [0.6, -0.6, 1.7])
    _, drawn = photographed(refined, [0.6, -0.6, 1.7])
    assert np.abs(drawn - seen).mean() < 0.2 * np.abs(photographed(start, [0.6, -0.6, 1.7])[1]
                                                      - seen).mean()


def test_the_room_behind_a_masked_photo_lends_the_texture_no_colour():
    """Photos of the square over a black room, their masks saying where the square is: the mesh
    drawn a little too large lies partly over the room, whose black must not darken its texture
    (it counts as white there, as the masked object is shown)."""
    truth = np.full((SIZE, SIZE, 3), 0.8)
    shots = photos(truth)
    masked_images, alphas = [], []
    for camera, image in zip(shots.cameras, shots.images):
        _, inside = render_mesh(*square(0.0, 0.5), camera, colours=np.zeros((4, 3), np.uint8))
        alphas.append(inside.astype(np.float32))
        masked_images.append(np.where(inside[..., None], image, 0.0).astype(np.float32))
    vertices, faces = square(0.0, 0.6)  # the mesh 20% larger than the photographed square
    start = np.full((SIZE, SIZE, 3), 0.8, dtype=np.float32)
    refined = refine_texture(vertices, faces, UV, start, Photos(shots.cameras, masked_images, alphas))
    unmasked = refine_texture(vertices, faces, UV, start,
                              Photos(shots.cameras, masked_images, [None] * len(alphas)))
    rim = np.ones((SIZE, SIZE), bool)
    rim[5:-5, 5:-5] = False
    rim[:2], rim[-2:], rim[:, :2], rim[:, -2:] = False, False, False, False  # chart padding
    assert unmasked[rim].mean() < 0.7  # without the masks the room darkens the rim
    assert refined[rim].mean() > 0.78


def test_an_estimated_mask_that_misses_the_object_does_not_bleach_it():
    """A dark square photographed four times, one mask missing its right half (a segmentation's
    slip). Given masks are trusted: white there, and those texels pale for every view. Estimated
    masks are not: the pixels the mask calls background do not count, and the other views keep
    the square's colour."""
    truth = np.full((SIZE, SIZE, 3), 0.3)
    shots = photos(truth)
    alphas = []
    for camera in shots.cameras:
        _, inside = render_mesh(*square(0.0, 0.5), camera, colours=np.zeros((4, 3), np.uint8))
        alphas.append(inside.astype(np.float32))
    alphas[0][:, alphas[0].shape[1] // 2:] = 0.0  # the top view's mask misses the right half
    vertices, faces = square(0.0, 0.5)
    start = np.full((SIZE, SIZE, 3), 0.3, dtype=np.float32)
    masked = Photos(shots.cameras, shots.images, alphas)
    given = refine_texture(vertices, faces, UV, start, masked)
    estimated = refine_texture(vertices, faces, UV, start, masked, estimated=True)
    right = (slice(6, SIZE - 6), slice(SIZE // 2 + 3, SIZE - 6))  # texels under the missed half
    assert given[right].mean() > 0.35  # (the photo's gain, refine.exposures, takes in some of it)
    assert abs(estimated[right].mean() - 0.3) < 0.02


def test_the_photos_noise_is_not_refined_into_the_texture(monkeypatch):
    """The four photos with noise of their own (sigma 0.1 a pixel, as a dim phone photo has): a
    correction free texel by texel fits it as grain, the smooth one (refine.SMOOTH) recovers the
    pattern from a flat start at half the error."""
    from windowshop.export import refine

    truth = true_texture()
    shots = photos(truth)
    rng = np.random.default_rng(0)
    noisy = Photos(shots.cameras, [np.clip(image + rng.normal(0.0, 0.1, image.shape), 0, 1)
                                   .astype(np.float32) for image in shots.images], shots.alphas)
    vertices, faces = square(0.0, 0.5)
    start = np.full_like(truth, 0.5, dtype=np.float32)
    inner = (slice(4, SIZE - 4), slice(4, SIZE - 4))
    smooth = np.abs(refine_texture(vertices, faces, UV, start, noisy) - truth)[inner].mean()
    monkeypatch.setattr(refine, "SMOOTH", 0.0)
    grainy = np.abs(refine_texture(vertices, faces, UV, start, noisy) - truth)[inner].mean()
    assert smooth < 0.03  # the 8-texel pattern is still there (0.19 from the flat start)
    assert smooth < 0.7 * grainy


def test_texels_side_by_side_in_two_charts_are_not_smoothed_together():
    """Two triangles, each its own chart, whose texels touch in the texture across x = 0.5: the
    differences link texels within a triangle, never one of each."""
    from windowshop.export.refine import chart_differences
    from windowshop.export.texture import rasterise

    uv = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 1.0], [0.5, 0.0], [1.0, 0.0], [1.0, 1.0]])
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    size = 16
    ids = rasterise(uv, faces, size).reshape(-1)
    used = np.flatnonzero(ids >= 0)
    differences = chart_differences(uv, faces, size, used).tocoo()
    assert np.allclose(np.asarray(differences.sum(1)), 0.0)  # each row: +1 and -1
    first = used[differences.col[differences.data > 0]]
    second = used[differences.col[differences.data < 0]]
    rows = differences.row[differences.data > 0], differences.row[differences.data < 0]
    first, second = first[np.argsort(rows[0])], second[np.argsort(rows[1])]
    assert len(first) > 50
    assert (ids[first] == ids[second]).all()
    # the two triangles do touch: side by side across their border, in the texture
    grid = ids.reshape(size, size)
    assert ((grid[:, :-1] == 0) & (grid[:, 1:] == 1)).any()


def test_each_photos_exposure_is_found_and_kept_out_of_the_texture(monkeypatch):
    """One of the four photos taken 30% brighter (the phone's exposure, or a light that moved
    with it): its gain is found, and the texture keeps the other three's exposure; solved
    without gains it comes out a third of that photo's brightening too bright."""
    from windowshop.export import refine

    rng = np.random.default_rng(1)
    drawn = rng.uniform(0.2, 0.6, (400, 3))
    photo = np.repeat(np.arange(5), 80)
    gains = np.array([1.0, 1.3, 0.8, 1.0, 1.1])
    found = refine.exposures(drawn, drawn * gains[photo][:, None], photo, 5)
    np.testing.assert_allclose(found, gains / np.median(gains), rtol=1e-9)
    glaring = np.where(photo[:, None] == 1, 5.0 * drawn, drawn)  # a photo five times as bright
    assert refine.exposures(drawn, glaring, photo, 5)[1] == refine.MAX_GAIN
    blind = refine.exposures(drawn, drawn * gains[photo][:, None], photo, 7)  # 5, 6 see nothing
    np.testing.assert_allclose(blind[:5], gains / np.median(gains), rtol=1e-9)
    assert blind[5] == blind[6] == 1.0 / np.median(gains)

    truth = 0.8 * true_texture()
    shots = photos(truth)
    images = list(shots.images)
    images[1] = np.clip(1.3 * images[1], 0, 1).astype(np.float32)
    brighter = Photos(shots.cameras, images, shots.alphas)
    vertices, faces = square(0.0, 0.5)
    start = np.full_like(truth, 0.5, dtype=np.float32)
    inner = (slice(4, SIZE - 4), slice(4, SIZE - 4))
    kept = refine_texture(vertices, faces, UV, start, brighter) - truth
    monkeypatch.setattr(refine, "GAINS", False)
    pulled = refine_texture(vertices, faces, UV, start, brighter) - truth
    assert abs(kept[inner].mean()) < 0.01 < pulled[inner].mean()
    assert np.abs(kept[inner]).mean() < 0.5 * np.abs(pulled[inner]).mean()
