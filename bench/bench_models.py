"""The delivered 3D model of every shared real capture at the defaults (issue 37), as JSON lines.

    python bench/bench_models.py [--rows dtu_skull beer_can kermit fruit] [--photos 20]
                                 [--whole beer_can] [--work /work/exp37] [--reuse]
                                 [--pictures docs/models] [--export KEY=VALUE ...]

Per capture: `windowshop video` at the defaults on the photos bench_real.py picks, or on all of
a capture's photos for those named by --whole (beer_can: 20 photos spread over its walk round a
can printed alike on two sides fold, and the verifier refuses them; all 70 place right). A
capture the pipeline refuses is a row with its reason (its run folder
kept under --work/<capture>; --reuse re-exports that run with the current export instead of
running the video again, with ExportOptions overridden by --export, e.g. close_unseen=false), then the delivered GLB, read back with trimesh and put in the scene's
frame through its side file, drawn with windowshop.export.raster at the run's held-out photos:
- psnr_glb / psnr_field: PSNR inside the prepared mask (alpha > 0.5) over white (pixels the
  GLB misses count as white), and the field's own there;
- psnr_glb_ssaa2: psnr_glb with the GLB drawn at 2 x 2 samples a pixel, averaged, as a viewer
  draws it (multisampled edges, filtered textures; bench_export's SSAA2 on lego): one sample a
  pixel aliases the texture's detail and the outline into speckle the photos do not have
  (a 4 x 4 drawing adds 0.06-0.08 dB more);
- psnr_field_averaged: the field's, its view dependence averaged out (each ray's colour decoded
  along every training camera's direction to the object's centre, averaged): about what one
  texture, the same from every side, could hold (a metal can's highlights, a rig's lights that
  move with the camera, are not in it);
- iou: the GLB's silhouette against the mask; field_iou: the field's own silhouette (opacity
  over one half) against it, where the masks, made photo by photo, agree with one another;
  iou_one_pixel_off: each mask against itself one pixel thinner, what an outline off by one
  pixel all round would score (a small object in the photo scores under 0.95 that way);
- refined: psnr_glb, psnr_field, gap_db, iou and field_iou again with each held-out camera
  first refined against the field (as the held-out check does), so that structure from
  motion's pose error of the held-out photo, a shift of the whole outline, counts against
  neither;
- faces_outside: faces whose centre lies outside the covered region's hull plus a margin: the
  convex hull of the delivered faces some training photo saw (as below), grown by MARGIN of the
  box's diagonal (shards on the side no photo saw stand outside it); outside_mask_hull: the same
  against the convex hull of the training masks' visual hull (a voxel outside a photo counts as
  background there);
- unseen_share: the share of the delivered surface's area that no training photo saw (a face is
  seen when its centre faces a training camera, projects into its photo and is the nearest
  surface there), and unseen_angle / seen_angle: the mean angle (degrees) between neighbouring
  faces there and on the seen part; unseen_torn / seen_torn: the share of the edge length
  between faces meeting at over TORN degrees there; unseen_shards / seen_shards: the share of
  the area lying in shards, the pieces the surface falls into when cut at those edges that hold
  under SHARD_SHARE of its area (a crease, where a hull's flat face meets the photographed
  surface or the base meets the sides, bounds large pieces; a torn surface falls into small
  ones: how torn the unseen side is, crease or not);
- area_over_hull: the surface's area over its convex hull's: how crumpled it is (a convex
  object's is 1; a surface bumpy at the lattice's scale hides much of its own area in its folds,
  which no photo sees and which unseen_share then counts);
- psnr_lit: the same PSNR with the GLB drawn lit as a viewer's default light does (half from the
  camera, half ambient) with glTF's metal-free GGX specular at each of ROUGHNESS, its exposure
  fitted: whether the material adds a highlight the baked texture already holds;
- the GLB's bytes and triangles, the export's seconds (and its stages), the covered arc;
- a 2x2 picture of the GLB from four sides (the best-photographed side first, then 90 degrees
  apart), lit from the camera, into --pictures/<capture>.png.
"""

from __future__ import annotations

import argparse
import os
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
import trimesh
from PIL import Image
from scipy import ndimage
from scipy.spatial import Delaunay

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_export import load_glb, supersampled  # noqa: E402
from bench_isolation import iou  # noqa: E402
from bench_real import captures, masked_psnr  # noqa: E402
from provenance import machine  # noqa: E402
from windowshop.config import ExportOptions, PipelineConfig  # noqa: E402
from windowshop.errors import UserError  # noqa: E402
from windowshop.export.command import export_models, side_file  # noqa: E402
from windowshop.export.raster import rasterise, render_mesh  # noqa: E402
from windowshop.fit.checkpoint import load_run  # noqa: E402
from windowshop.fit.pose_refine import refine_camera  # noqa: E402
from windowshop.fit.evaluate import held_out_views, target_image  # noqa: E402
from windowshop.metrics import psnr  # noqa: E402
from windowshop.render.frames import render_camera  # noqa: E402
from windowshop.scene import load_scene  # noqa: E402
from windowshop.scene.cameras import look_at  # noqa: E402
from windowshop.scene.hull import hull_points  # noqa: E402
from windowshop.scene.types import Camera  # noqa: E402

MARGIN = 0.03  # of the box's diagonal: how far outside the covered hull a face may lie
SEEN_SIDE = 320  # training photos are drawn this many pixels on their longer side for visibility
PICTURE_SIDE = 200  # pixels a side of each of the picture's four views
TORN = 60.0  # degrees between neighbouring faces that make their edge a tear
SHARD_SHARE = 0.002  # a piece of the surface cut at its tears under this share of its area: a shard
ROUGHNESS = (0.5, 0.8, 1.0)  # the material's roughness, drawn lit at the held-out photos


def view_averaged_psnr(run, scene) -> float | None:
    """masked_psnr of the field with its colour decoded along every training camera's direction
    to the object's centre and averaged (None for a model without a `decode` of directions)."""
    model = run.model
    if not hasattr(model, "decode"):
        return None
    lo, hi = np.asarray(run.bounds.aabb, dtype=float)
    towards = np.stack([(lo + hi) / 2 - v.camera.c2w[:3, 3] for v in scene.split("train")])
    towards = torch.as_tensor(towards / np.linalg.norm(towards, axis=1, keepdims=True),
                              dtype=torch.float32)
    decode = model.decode

    def averaged(features: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        return torch.stack([decode(features, d.to(directions).expand_as(directions))
                            for d in towards]).mean(0)

    model.decode = averaged  # this instance only, for the one measure
    try:
        return masked_psnr(run, scene)
    finally:
        del model.decode


def refined_scores(run, scene, vertices, faces, uv, texture) -> dict:
    """The GLB's and the field's PSNR in the mask and silhouette IoU at the held-out photos with
    each camera first refined against the field (windowshop.fit.pose_refine, at most 3 degrees,
    as the held-out check does; kept where the field's PSNR in the mask rises), both drawn at
    that one camera: what is left once structure from motion's pose error of the held-out
    photo is not counted against either."""
    rows = []
    for view in held_out_views(scene):
        inside, truth = view.alpha > 0.5, target_image(view, scene.background)
        moved = refine_camera(run.model, view.camera, truth, (1.0, 1.0, 1.0),
                              run.fit_config.memory_budget).camera
        # kept only where the field matches the photo better there (fit.evaluate's rule)
        frame, camera = max(((render_camera(run.model, c, (1.0, 1.0, 1.0)), c)
                             for c in (view.camera, moved)),
                            key=lambda fc: psnr(fc[0].rgb[inside], truth[inside]))
        image, drawn = render_mesh(vertices, faces, camera, (1.0, 1.0, 1.0), uv=uv, texture=texture)
        seen = frame.opacity > 0.5
        rows.append((psnr(image[inside], truth[inside]), psnr(frame.rgb[inside], truth[inside]),
                     iou(inside, drawn), iou(inside, seen)))
    glb, field, glb_iou, field_iou = np.mean(np.array(rows, dtype=float), axis=0)
    return {"psnr_glb": round(glb, 2), "psnr_field": round(field, 2),
            "gap_db": round(field - glb, 2), "iou": round(glb_iou, 4), "field_iou": round(field_iou, 4)}


def field_silhouette_iou(run, scene) -> float:
    """The mean IoU of the field's silhouette (opacity > 0.5) with the mask at the held-out photos."""
    ious = []
    for view in held_out_views(scene):
        inside = view.alpha > 0.5
        drawn = render_camera(run.model, view.camera, (1.0, 1.0, 1.0)).opacity > 0.5
        ious.append(iou(inside, drawn))
    return float(np.mean(ious))


def lit(image: np.ndarray, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
        camera: Camera, roughness: float) -> tuple[np.ndarray, np.ndarray]:
    """(the mesh's base colour `image` (H, W, 3) lit as a viewer's default light does: a light at
    the camera (half of it) over an even ambient half, with glTF's metal-free GGX specular (F0
    0.04) at `roughness`; the mask of drawn pixels)."""
    raster = rasterise(torch.as_tensor(vertices), torch.as_tensor(faces, dtype=torch.int64), camera)
    face, bary = raster.face.numpy(), raster.bary.numpy()
    hit = face >= 0
    n = np.einsum("pk,pkc->pc", bary[hit], normals[faces[face[hit]]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    points = np.einsum("pk,pkc->pc", bary[hit], vertices[faces[face[hit]]])
    v = camera.center - points
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    cos = np.clip(np.abs(np.einsum("pc,pc->p", n, v)), 1e-4, 1.0)  # light = view: h = n.v
    a2 = roughness ** 4
    d = a2 / (np.pi * (cos * cos * (a2 - 1) + 1) ** 2)
    k = (roughness + 1) ** 2 / 8
    g = (cos / (cos * (1 - k) + k)) ** 2
    specular = 0.04 * d * g / (4 * cos * cos) * cos  # times n.l, light of radiance 1
    out = image.copy()
    out[hit] = image[hit] * (0.5 + 0.5 * cos)[:, None] * 0.96 + 0.5 * np.pi * specular[:, None]
    return np.clip(out, 0, 1), hit


def small(camera: Camera, side: int) -> Camera:
    scale = side / max(camera.width, camera.height)
    return camera.resized(max(1, round(camera.width * scale)), max(1, round(camera.height * scale)))


def seen_faces(vertices: np.ndarray, faces: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """(F,) bool: faces whose centre some camera sees (faces it, in its image, nearest there)."""
    v = torch.as_tensor(vertices, dtype=torch.float64)
    f = torch.as_tensor(faces, dtype=torch.int64)
    tri = vertices[faces]
    centres = tri.mean(1)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    seen = np.zeros(len(faces), bool)
    tolerance = 0.01 * float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    for camera in cameras:
        cam = small(camera, SEEN_SIDE)
        raster = rasterise(v, f, cam)
        face = raster.face.numpy()
        hit = face >= 0
        bary = raster.bary.numpy()
        points = np.zeros((cam.height, cam.width, 3))
        points[hit] = np.einsum("pk,pkc->pc", bary[hit], tri[face[hit]])
        eye = cam.center
        depth = np.full((cam.height, cam.width), np.inf)
        depth[hit] = np.linalg.norm(points[hit] - eye, axis=-1)
        w2c = np.linalg.inv(cam.c2w)
        local = centres @ w2c[:3, :3].T + w2c[:3, 3]
        z = -local[:, 2]
        front = (z > 1e-6) & (np.einsum("fc,fc->f", normals, eye - centres) > 0)
        u = np.floor(cam.fx * local[:, 0] / np.maximum(z, 1e-9) + cam.cx).astype(int)
        r = np.floor(-cam.fy * local[:, 1] / np.maximum(z, 1e-9) + cam.cy).astype(int)
        inside = front & (u >= 0) & (r >= 0) & (u < cam.width) & (r < cam.height)
        idx = np.nonzero(inside)[0]
        near = np.linalg.norm(centres[idx] - eye, axis=-1) <= depth[r[idx], u[idx]] + tolerance
        seen[idx[near]] = True
    return seen


def neighbour_angles(vertices: np.ndarray, faces: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(angles (E,) degrees between the faces across each shared edge, the two faces (E, 2), the
    edges' lengths (E,))."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)  # the texture's seams joined again
    edges = mesh.vertices[mesh.face_adjacency_edges]
    return (np.degrees(mesh.face_adjacency_angles), mesh.face_adjacency,
            np.linalg.norm(edges[:, 0] - edges[:, 1], axis=1))


def shards(area: np.ndarray, pairs: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(F,) bool: faces in a shard (the docstring): the pieces joined across edges of at most
    TORN degrees (`pairs` (E, 2) of faces, `angles` (E,)) holding under SHARD_SHARE of the
    total `area` (F,)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    smooth = pairs[angles <= TORN]
    graph = coo_matrix((np.ones(len(smooth)), (smooth[:, 0], smooth[:, 1])),
                       shape=(len(area), len(area)))
    _, label = connected_components(graph, directed=False)
    piece = np.bincount(label, weights=area)
    return piece[label] < SHARD_SHARE * area.sum()


def covered_hull(run, scene) -> Delaunay | None:
    """The convex hull of the training masks' visual hull, grown by MARGIN of the box's diagonal."""
    train = [v for v in scene.split("train") if v.alpha is not None]
    lo, hi = np.asarray(scene.aabb, dtype=float)
    points = hull_points([v.camera for v in train], [v.alpha for v in train], (lo + hi) / 2,
                         float(np.max(hi - lo)) / 2 * 1.1)
    if points is None:
        return None
    return grown_hull(points, MARGIN * float(np.linalg.norm(hi - lo)))


def grown_hull(points: np.ndarray, grow: float) -> Delaunay:
    """The convex hull of `points` (N, 3), its corners moved `grow` away from its centre."""
    centre = points.mean(0)
    hull = trimesh.convex.convex_hull(points)
    grown = hull.vertices + grow * (hull.vertices - centre) / np.maximum(
        np.linalg.norm(hull.vertices - centre, axis=1, keepdims=True), 1e-9)
    return Delaunay(grown)


def picture(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, texture: np.ndarray,
            start_deg: float, out: Path) -> None:
    """A 2x2 picture of the textured mesh (normalised frame, z up) from azimuths start + 0, 90,
    180, 270 degrees at 20 degrees elevation, lit from the camera."""
    lo, hi = vertices.min(0), vertices.max(0)
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
    tri = vertices[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    tiles = []
    for k in range(4):
        az, el = np.radians(start_deg + 90 * k), np.radians(20.0)
        eye = centre + 3.0 * radius * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                                np.sin(el)])
        focal = PICTURE_SIDE / 2 / np.tan(np.arcsin(1 / 3.0)) * 0.95
        camera = Camera(fx=focal, fy=focal, cx=PICTURE_SIDE / 2, cy=PICTURE_SIDE / 2,
                        width=PICTURE_SIDE, height=PICTURE_SIDE, c2w=look_at(eye, centre, [0, 0, 1]))
        image, _ = render_mesh(vertices, faces, camera, (1.0, 1.0, 1.0), uv=uv, texture=texture)
        face = rasterise(torch.as_tensor(vertices), torch.as_tensor(faces, dtype=torch.int64),
                         camera).face.numpy()
        hit = face >= 0
        light = (eye - centre) / np.linalg.norm(eye - centre)
        lambert = np.abs(normals[face[hit]] @ light)
        image[hit] *= (0.45 + 0.55 * lambert)[:, None]
        tiles.append(np.clip(image * 255 + 0.5, 0, 255).astype(np.uint8))
    grid = np.concatenate([np.concatenate(tiles[:2], 1), np.concatenate(tiles[2:], 1)], 0)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(grid).save(out, optimize=True)


def best_azimuth(scene) -> float:
    """Degrees of azimuth (about +z from +x, through the box's centre) facing most training photos."""
    from windowshop.video.coverage import best_covered_frame

    lo, hi = np.asarray(scene.aabb, dtype=float)
    offsets = np.stack([v.camera.center for v in scene.split("train")]) - (lo + hi) / 2
    azimuths = np.degrees(np.arctan2(offsets[:, 1], offsets[:, 0])) % 360
    candidates = np.arange(0.0, 360.0, 2.0)
    return float(candidates[best_covered_frame(candidates, azimuths)])


def evaluate(name: str, folder: Path, pictures: Path | None, export_seconds: float) -> dict:
    """The figures of the docstring for the GLB at `folder`/spin.glb of the run beside it."""
    glb = folder / "spin.glb"
    run = load_run(folder / "spin_work" / "run")
    scene = load_scene(run.scene_source, run.scene_options)
    side = json.loads(side_file(glb).read_text())
    vertices, faces, uv, texture, normals = load_glb(glb, run)
    cache = folder / "field_psnr.json"
    keys = ("psnr_field", "psnr_field_averaged", "field_iou")
    cached = json.loads(cache.read_text()) if cache.is_file() else {}
    if all(k in cached for k in keys):
        field, averaged, field_iou = (cached[k] for k in keys)
    else:
        field, averaged, field_iou = (masked_psnr(run, scene), view_averaged_psnr(run, scene),
                                      field_silhouette_iou(run, scene))
        cache.write_text(json.dumps(dict(zip(keys, (field, averaged, field_iou)))))
    glb_scores, ssaa_scores, ious, lit_scores = [], [], [], {r: [] for r in ROUGHNESS}
    one_pixel = []  # the IoU of each mask with itself one pixel thinner: what an outline one
    # pixel off all round scores, for the 0.95 goal against the object's size in the photo
    for view in held_out_views(scene):
        image, silhouette = render_mesh(vertices, faces, view.camera, (1.0, 1.0, 1.0), uv=uv,
                                        texture=texture)
        inside = view.alpha > 0.5
        truth = target_image(view, scene.background)
        glb_scores.append(psnr(image[inside], truth[inside]))
        smooth = supersampled(vertices, faces, view.camera, uv, texture, 2)
        ssaa_scores.append(psnr(smooth[inside], truth[inside]))
        for r in ROUGHNESS:  # lit, its exposure fitted to the photo (a viewer's is arbitrary)
            shaded, _ = lit(image, vertices, faces, normals, view.camera, r)
            x, y = shaded[inside].ravel(), truth[inside].ravel()
            gain = float(x @ y / max(x @ x, 1e-12))
            lit_scores[r].append(psnr(np.clip(shaded[inside] * gain, 0, 1), truth[inside]))
        ious.append(iou(inside, silhouette))
        one_pixel.append(float(ndimage.binary_erosion(inside).sum() / max(inside.sum(), 1)))
    hull = covered_hull(run, scene)
    centres = vertices[faces].mean(1)
    outside_mask = -1 if hull is None else int((hull.find_simplex(centres) < 0).sum())
    seen = seen_faces(vertices, faces, [v.camera for v in scene.split("train")])
    lo, hi = np.asarray(scene.aabb, dtype=float)
    outside = int((grown_hull(centres[seen], MARGIN * float(np.linalg.norm(hi - lo)))
                   .find_simplex(centres) < 0).sum())
    surface = trimesh.Trimesh(vertices, faces, process=False)
    area = surface.area_faces
    angles, pairs, lengths = neighbour_angles(vertices, faces)
    unseen_pair = ~seen[pairs].all(1)
    torn = lengths * (angles > TORN)
    shard = shards(area, pairs, angles)
    orbit = side.get("orbit", {})
    if pictures is not None:
        picture(vertices, faces, uv, texture, best_azimuth(scene), pictures / f"{name}.png")
    return {"capture": name, "photos": len(list((folder / "photos").iterdir())),
            "held_out": len(glb_scores),
            "psnr_glb": round(float(np.mean(glb_scores)), 2), "psnr_field": round(field, 2),
            "psnr_field_averaged": None if averaged is None else round(averaged, 2),
            "gap_db": round(field - float(np.mean(glb_scores)), 2),
            "psnr_glb_ssaa2": round(float(np.mean(ssaa_scores)), 2),
            "psnr_lit": {str(r): round(float(np.mean(v)), 2) for r, v in lit_scores.items()},
            "iou": round(float(np.mean(ious)), 4), "iou_min": round(float(np.min(ious)), 4),
            "field_iou": round(field_iou, 4),
            "iou_one_pixel_off": round(float(np.mean(one_pixel)), 4),
            "refined": refined_scores(run, scene, vertices, faces, uv, texture),
            "faces_outside": outside, "outside_mask_hull": outside_mask,
            "unseen_share": round(float(area[~seen].sum() / area.sum()), 4),
            "unseen_angle": round(float(angles[unseen_pair].mean()), 1) if unseen_pair.any() else None,
            "seen_angle": round(float(angles[~unseen_pair].mean()), 1),
            "mean_angle": round(float(angles.mean()), 1),
            "area_over_hull": round(float(area.sum() / surface.convex_hull.area), 2),
            "unseen_torn": round(float(torn[unseen_pair].sum() / max(lengths[unseen_pair].sum(), 1e-12)), 4),
            "seen_torn": round(float(torn[~unseen_pair].sum() / max(lengths[~unseen_pair].sum(), 1e-12)), 4),
            "unseen_shards": round(float(area[~seen & shard].sum() / max(area[~seen].sum(), 1e-12)), 4),
            "seen_shards": round(float(area[seen & shard].sum() / max(area[seen].sum(), 1e-12)), 4),
            "glb_mb": round(glb.stat().st_size / 1e6, 2), "triangles": int(len(faces)),
            "export_seconds": round(export_seconds, 2), "stages": side.get("seconds"),
            "covered_degrees": orbit.get("covered_degrees"), "orbit_limited": orbit.get("limited"),
            "export_angles": side.get("neighbour_angle")}


def produce(name: str, photos: list[Path], work: Path, reuse: bool,
            options: ExportOptions = ExportOptions()) -> float:
    """Run `windowshop video` at the defaults into `work` (or re-export its run with `options`);
    export seconds."""
    from windowshop.pipeline import make_video

    folder = work / name
    if reuse and (folder / "spin_work" / "run").is_dir():
        start = time.perf_counter()
        export_models(folder / "spin_work" / "run", [folder / "spin.glb", folder / "spin.usdz"],
                      options)
        return time.perf_counter() - start
    (folder / "photos").mkdir(parents=True, exist_ok=True)
    for path in photos:
        link = folder / "photos" / path.name
        if not link.exists():
            link.symlink_to(path)
    (folder / "field_psnr.json").unlink(missing_ok=True)
    result = make_video(folder / "photos", folder / "spin.mp4", PipelineConfig(), show=False)
    return result.seconds["export"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", nargs="+", default=["dtu_skull", "beer_can", "kermit", "fruit"])
    parser.add_argument("--photos", type=int, default=20)
    parser.add_argument("--whole", nargs="*", default=["beer_can"],
                        help="captures taken with all their photos")
    parser.add_argument("--work", type=Path, default=Path("/work/exp37"))
    parser.add_argument("--reuse", action="store_true", help="re-export the kept runs")
    parser.add_argument("--pictures", type=Path, default=None, help="folder for <capture>.png")
    parser.add_argument("--export", action="append", default=[], metavar="KEY=VALUE",
                        help="ExportOptions override for --reuse, e.g. close_unseen=false")
    args = parser.parse_args()
    overrides = {}
    for pair in args.export:
        key, _, value = pair.partition("=")
        overrides[key.replace("-", "_")] = json.loads(value)
    options = ExportOptions(**overrides)
    torch.manual_seed(0)
    photos = captures(args.photos)
    every = captures(10 ** 6)
    photos.update({name: every[name] for name in args.whole})
    print(json.dumps(machine()), flush=True)
    for name in args.rows:
        try:
            seconds = produce(name, photos[name], args.work, args.reuse, options)
        except UserError as err:
            print(json.dumps({"capture": name, "photos": len(photos[name]),
                              "refused": str(err)}), flush=True)
            continue
        print(json.dumps(evaluate(name, args.work / name, args.pictures, seconds)), flush=True)
    print(json.dumps({"load_average_end": list(os.getloadavg())}), flush=True)


if __name__ == "__main__":
    main()
