"""The baked texture refined by least squares against the training photos (as NeRF2Mesh's second
stage refines its texture).

Projecting photos onto the mesh (photos.py) averages each texel's colour over the views; where
the mesh lies a little off the photographed surface, or a texel is smeared over a pixel, the
average blurs. Instead, draw the mesh at the photos' cameras (raster.rasterise: the visible face
and its perspective-correct barycentrics at each sample), each sample reading the texture
bilinearly (SUPERSAMPLE^2 samples a pixel averaged, when more than one), and find the texture t
whose drawing matches the photos best:

    min_t  sum over pixels ||A t - photo||^2  +  WEIGHT * ||t - t_baked||^2
                                              +  SMOOTH * ||D (t - t_baked)||^2

(A: each pixel's texel weights; D: the differences between side-by-side texels of one chart),
over every pixel the mesh covers (all its samples) in all the training photos, not only the
bake's few: the mesh is not quite where the photographed surface is, and the more views the
texture must agree with, the better it holds at views between them. The prior keeps texels few
pixels pin down near their baked colours. A texel is about a photo's pixel (texture.bake_size),
so a correction free texel by texel also fits each photo's noise and the mesh's small
misplacement, as a grain over the surface (dtu_skull's cranium was speckled where its photos are
smooth); the third term asks the correction to be smooth within a chart, and leaves the baked
detail as it was. Conjugate gradients on the normal equations, ITERATIONS steps, all three
channels at once.
Each photo has an exposure of its own (a phone sets it photo by photo; DTU's lights move with
the camera), and a photo brighter than the rest pulls every texel it sees its way. So the
texture is solved twice: the first solve gives each photo's gain (`exposures`: one factor, the
least squares' own), and the second solves with each photo's pixels drawn at its gain. The
gains are scaled to a median of 1, so that the texture keeps the exposure most photos have.
Lego 400x400, 950 steps, 8 held-out views, PSNR anti-aliased: baked 24.81 dB; refined on the 24
bake photos 25.12, on 48 25.51, on all 100 25.71. Also tried: only pixels inside the photo's
alpha (>= 0.5) count, 0.1 dB worse (a mesh edge drawn over the background is best pale);
pixels near the mesh's silhouette and occluding edges weighted down (photos.edge_ramp), 0.25 dB
worse; rows weighted by cos^2(normal, view), as the bake weights views, 0.3 dB worse; 2x2
samples a pixel, +0.05 dB at 4x the time.
A photo with a mask counts over white where the mask says background: a real capture's photos
show the room there (dark for dtu_skull), which the mesh's edges drawn over it would take as the
object's colour (+0.02 dB on dtu_skull; on lego, over white already, nothing changes). Masks
estimated from the photos (a prepared capture's) are not trusted that far: where one says
background the pixel does not count at all, since it is as often the object the mask missed,
whose texels white would bleach for every other view (bench_models at 320da43, the GLB at one
sample a pixel: beer_can +0.35, fruit +0.37, kermit +0.30, dtu_skull +0.06 dB).
The smooth correction (SMOOTH 0 -> 1), GLB PSNR at the held-out photos at one sample a pixel
(bench/RESULTS.md, stop 57): dtu_skull in the mask 18.74 -> 19.05, kermit 19.68 -> 19.89, fruit
16.51 -> 16.61, beer_can 17.54 -> 17.58; lego 400x400 26.53 -> 26.75. SMOOTH 0.25 / 4 / 16 gave
dtu_skull 18.99 / 19.05 / 19.02; smoothing the whole texture instead of the correction, +0.03 at
most (and it would blur a print's detail that the bake got right).
The gains (GAINS, with SMOOTH 1): dtu_skull 19.05 -> 20.06, kermit 19.89 -> 19.88, fruit 16.61
-> 16.64, beer_can 17.58 -> 17.59; lego 26.75 -> 26.74. dtu_skull's photos' gains run 0.79-1.09;
scaled to their geometric mean instead of their median, dtu_skull scores 19.37: the level the
texture keeps is most of what the held-out photos see. The second solve costs 0.2-0.45 s.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy import sparse
from scipy.sparse import csgraph

from windowshop.export.carve import MASK_LEVEL
from windowshop.export.photos import Photos
from windowshop.export.raster import rasterise
from windowshop.scene.types import Camera

SUPERSAMPLE = 1  # samples a pixel side
WEIGHT = 0.2  # of the prior towards the baked colours, per texel (a pixel's weights sum to 1)
ITERATIONS = 15  # conjugate-gradient steps (15 and 60 score the same on lego)
SMOOTH = 1.0  # of the correction's squared differences between side-by-side texels of one chart
GAINS = True  # solve again with each photo's exposure (gain) taken out
MAX_GAIN = 2.0  # a photo's gain is held within this factor either way


def texel_weights(uv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(index (N, 4), weight (N, 4)): the texels of a `size` x `size` texture that bilinear
    sampling at `uv` (N, 2) reads (grid_sample's, align_corners=False, edges clamped)."""
    x, y = uv[:, 0] * size - 0.5, uv[:, 1] * size - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    xs = np.clip(np.stack([x0, x0 + 1, x0, x0 + 1], -1), 0, size - 1).astype(np.int64)
    ys = np.clip(np.stack([y0, y0, y0 + 1, y0 + 1], -1), 0, size - 1).astype(np.int64)
    weight = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], -1)
    return ys * size + xs, weight


def view_rows(vertices: torch.Tensor, faces: torch.Tensor, uv: np.ndarray, camera: Camera,
              size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pixels of one view that count (see the module docstring): (pixel (P,) flat indices,
    then row (N,), texel (N,), weight (N,): the texture's weights in the P pixels, rows
    numbered 0..P-1)."""
    k = SUPERSAMPLE
    h, w = camera.height, camera.width
    raster = rasterise(vertices, faces, camera.resized(w * k, h * k))
    face = raster.face.numpy().reshape(h, k, w, k).transpose(0, 2, 1, 3).reshape(h * w, k * k)
    bary = raster.bary.numpy().reshape(h, k, w, k, 3).transpose(0, 2, 1, 3, 4)
    pixel = np.flatnonzero((face >= 0).all(-1))
    f = face[pixel].reshape(-1)  # (P k^2,)
    weights = bary.reshape(h * w, k * k, 3)[pixel].reshape(-1, 3)
    at = (weights[..., None] * uv[faces.numpy()[f]]).sum(1)
    texel, weight = texel_weights(at, size)
    row = np.repeat(np.arange(len(pixel)), k * k * 4)
    return pixel, row, texel.reshape(-1), weight.reshape(-1) / (k * k)


def system(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, photos: Photos,
           size: int, estimated: bool = False
           ) -> tuple[sparse.csr_matrix, np.ndarray, np.ndarray]:
    """(A (P, size^2), colour (P, 3), photo (P,)): every counted pixel of every photo (those its
    mask calls the object's only, where the masks are `estimated`), its texel weights, its
    colour and the index of its photo."""
    v = torch.as_tensor(vertices, dtype=torch.float32)
    f = torch.as_tensor(faces, dtype=torch.int64)
    rows, texels, weights, targets, counts, first = [], [], [], [], [], 0
    for camera, image, alpha in zip(photos.cameras, photos.images, photos.alphas):
        pixel, row, texel, weight = view_rows(v, f, uv, camera, size)
        target = image.reshape(-1, 3)[pixel]
        if alpha is not None:
            a = alpha.reshape(-1)[pixel]
            if estimated:
                counted = a >= MASK_LEVEL
                renumber = np.cumsum(counted) - 1  # rows are numbered by counted pixel
                keep = counted[row]
                row, texel, weight = renumber[row[keep]], texel[keep], weight[keep]
                pixel, target = pixel[counted], target[counted]
            else:  # the room behind a real object is no colour of it: white there
                target = target * a[:, None] + (1.0 - a[:, None])
        rows.append(row + first)
        texels.append(texel)
        weights.append(weight)
        targets.append(target)
        first += len(pixel)
        counts.append(len(pixel))
    a = sparse.csr_matrix((np.concatenate(weights), (np.concatenate(rows),
                                                      np.concatenate(texels))),
                          shape=(first, size * size))
    return (a, np.concatenate(targets).astype(np.float64),
            np.repeat(np.arange(len(counts)), counts))


def conjugate_gradients(apply, rhs: np.ndarray, iterations: int) -> np.ndarray:
    """x (N, C) solving apply(x) = `rhs` (N, C), `apply` symmetric positive definite, each
    column its own conjugate-gradient run, `iterations` steps from zero. (scipy's cg takes one
    column a call: three passes over the sparse system instead of one, 10% more refine time on
    lego.)"""
    x = np.zeros_like(rhs)
    r = rhs.copy()
    p = r.copy()
    rr = (r * r).sum(0)
    for _ in range(iterations):
        q = apply(p)
        step = rr / np.maximum((p * q).sum(0), 1e-30)
        x += step * p
        r -= step * q
        new = (r * r).sum(0)
        p = r + (new / np.maximum(rr, 1e-30)) * p
        rr = new
    return x


def refine_texture(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, image: np.ndarray,
                   photos: Photos, estimated: bool = False,
                   texel_faces: np.ndarray | None = None) -> np.ndarray:
    """(S, S, 3) float32: the texture `image` (S, S, 3) in [0, 1] of the mesh `vertices` (V, 3),
    `faces` (F, 3), `uv` (V, 2) (glTF's), refined against `photos`, whose masks are
    `estimated` from them or given with them (see the module docstring); `texel_faces` (S, S)
    the face under each texel, when the bake has it (texture.Unwrapped.texel_faces)."""
    size = image.shape[0]
    a, target, photo = system(vertices, faces, uv, photos, size, estimated)
    used = np.flatnonzero(np.asarray(a.getnnz(0)) > 0)  # texels no pixel reads stay as baked
    a = a[:, used].tocsr()
    start = image.reshape(-1, 3).astype(np.float64)
    smooth = None
    if SMOOTH > 0:
        differences = chart_differences(uv, faces, size, used, texel_faces)
        smooth = (SMOOTH * (differences.T @ differences)).tocsr()

    def solve(drawing: sparse.csr_matrix) -> np.ndarray:
        """The used texels' colours (U, 3) for pixels drawn by `drawing` (P, U)."""
        at = drawing.T.tocsr()
        # A^T A once (lego 400: 1 s, 4.5M entries against A's 19M): each step is then one
        # product with it (9 ms) instead of one with A and one with A^T (350 ms)
        normal = (at @ drawing).tocsr()
        if smooth is not None:
            normal = (normal + smooth).tocsr()
        residual = target - drawing @ start[used]
        return start[used] + conjugate_gradients(lambda x: normal @ x + WEIGHT * x,
                                                 at @ residual, ITERATIONS)

    texels = solve(a)
    if GAINS:
        gain = exposures(a @ texels, target, photo, len(photos.cameras))
        texels = solve((sparse.diags(gain[photo]) @ a).tocsr())
    out = start.copy()
    out[used] = texels
    return np.clip(out, 0.0, 1.0).reshape(image.shape).astype(np.float32)


def exposures(drawn: np.ndarray, colour: np.ndarray, photo: np.ndarray, count: int
              ) -> np.ndarray:
    """(count,) each photo's gain: the factor by which the texture `drawn` (P, 3) at its pixels
    best matches their `colour` (P, 3) (least squares; `photo` (P,) the pixels' photos), held to
    MAX_GAIN either way and scaled so that the photos that see the mesh have a median of 1 (the
    texture keeps the exposure most photos have)."""
    both = np.bincount(photo, (drawn * colour).sum(1), minlength=count)
    drawn_only = np.bincount(photo, (drawn * drawn).sum(1), minlength=count)
    seen = drawn_only > 0  # a photo that sees none of the mesh has no pixels and no say
    gain = np.ones(count)
    gain[seen] = np.clip(both[seen] / drawn_only[seen], 1.0 / MAX_GAIN, MAX_GAIN)
    return gain / (np.median(gain[seen]) if seen.any() else 1.0)


def chart_differences(uv: np.ndarray, faces: np.ndarray, size: int, used: np.ndarray,
                      texel_faces: np.ndarray | None = None) -> sparse.csr_matrix:
    """D (pairs, len(used)), +1 and -1 a row: the differences between side-by-side `used` texels
    (flat indices into the `size` x `size` texture) whose centres lie on one chart, the faces
    (F, 3) an unwrapped mesh joins through shared vertices (texture.unwrap splits them where
    charts meet, so texels side by side in two charts lie apart on the surface); `texel_faces`
    (size, size) the face under each texel's centre, rasterised here when not given."""
    from windowshop.export.texture import rasterise

    corners = len(uv)
    links = sparse.coo_matrix((np.ones(2 * len(faces)),
                               (np.repeat(faces[:, 0], 2), faces[:, 1:].reshape(-1))),
                              shape=(corners, corners))
    vertex_chart = csgraph.connected_components(links, directed=False)[1]
    ids = rasterise(uv, faces, size) if texel_faces is None else texel_faces
    chart = np.where(ids >= 0, vertex_chart[faces[np.maximum(ids, 0), 0]], -1)
    column = np.full(size * size, -1)
    column[used] = np.arange(len(used))
    column = column.reshape(size, size)
    pairs = []
    for a, b, chart_a, chart_b in ((column[:, :-1], column[:, 1:], chart[:, :-1], chart[:, 1:]),
                                   (column[:-1], column[1:], chart[:-1], chart[1:])):
        keep = (a >= 0) & (b >= 0) & (chart_a >= 0) & (chart_a == chart_b)
        pairs.append(np.stack([a[keep], b[keep]]))
    first, second = np.concatenate(pairs, 1)
    rows = np.arange(len(first))
    return sparse.csr_matrix((np.repeat([1.0, -1.0], len(first)),
                              (np.tile(rows, 2), np.concatenate([first, second]))),
                             shape=(len(first), len(used)))
