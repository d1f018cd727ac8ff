"""`windowshop export`: a run folder -> the object as GLB, USDZ or PLY, with its side file.

    build_asset(run)  =  the training photos, read again from the run's scene (photos.training_photos)
                      -> density lattice over the object's box (mesh.sample_volume)
                      -> the surface's level from the field's silhouettes (level.choose_level)
                      -> the lattice carved by the photos' masks, where they have any (carve)
                      -> the side no photo saw closed by the hull of the seen part (unseen),
                         a contact shadow's slab and the floor layers cut away (support)
                      -> marching cubes, largest pieces, decimation (mesh.object_mesh), the
                         base put flat on the floor (support.flatten_base)
                      -> moved to where the photos agree (settle)
                      -> UVs and the base colour baked from the photos, the field's where no
                         bake photo sees the surface, grey on the side none saw (texture, photos)
                      -> moved again to match all the photos and their masks (tune), then
                         smoothed back to no rougher than before it (mesh.taubin), held within the
                         hull of the faces the photos see (unseen.held_to_covered)
                      -> that texture refined by least squares against all the photos (refine)
                      -> the model frame: +Y up, standing at the origin (frame.model_frame),
                         and the orbit a viewer may take: the covered arc (orbit)
    write_asset(asset, path)  -> GLB / USDZ / PLY, and FILE.json beside it (frame.write_side_file)

`windowshop video` calls `export_models` to write GLB and USDZ from one asset.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from windowshop.config import ExportOptions
from windowshop.errors import UserError
from windowshop.export.asset import Asset
from windowshop.export.photos import spread

FORMATS = ("glb", "usdz", "ply")
BAKE_DEPTHS = (0.5, 1.5)  # colours are read this many lattice cells under the surface, averaged


def output_format(out: Path, fmt: str | None) -> str:
    """The format asked for: `fmt`, else the output's extension."""
    fmt = (fmt or out.suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise UserError(f"{out}: say --format {'|'.join(FORMATS)} or name the file .glb, .usdz "
                        f"or .ply")
    return fmt


def check_options(options: ExportOptions) -> None:
    """Refuse settings that cannot make a model, before any work."""
    if options.triangles < 4:
        raise UserError(f"--triangles {options.triangles}: a closed surface needs at least 4")
    if options.texture != 0 and not 64 <= options.texture <= 8192:
        raise UserError(f"--texture {options.texture}: give 64 to 8192 pixels, or 0 (vertex colours)")
    if options.size_cm is not None and options.size_cm <= 0:
        raise UserError(f"--size-cm {options.size_cm}: the height must be positive")
    if options.resolution < 8:
        raise UserError(f"--resolution {options.resolution}: give at least 8 cells")


def build_asset(run_dir: str | Path, options: ExportOptions = ExportOptions(),
                device: torch.device | str = "cpu", vertex_colours: bool = False) -> Asset:
    """The object of the run at `run_dir` as an Asset (see the module docstring); vertex
    colours are baked too when asked for (PLY) or when there is no texture."""
    from windowshop.export import texture as tex
    from windowshop.export.carve import CARVE_VIEWS, ESTIMATED, TOLERANCE, carve_volume
    from windowshop.export.frame import Z_UP_TO_Y_UP, apply, model_frame
    from windowshop.export.level import choose_level
    from windowshop.export.mesh import (Mesh, face_pairs, lattice_resolution, neighbour_angles,
                                        object_mesh, sample_volume, taubin, vertex_normals)
    from windowshop.export.support import flatten_base, plane_found, prepared_report
    from windowshop.export.unseen import held_to_covered, weight_at
    from windowshop.export.orbit import covered_orbit
    from windowshop.export.photos import training_photos
    from windowshop.export.refine import refine_texture
    from windowshop.export.settle import settle
    from windowshop.export.tune import tune_surface
    from windowshop.fit.checkpoint import load_run

    check_options(options)
    clock, seconds = time.perf_counter(), {}

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        seconds[stage], clock = round(now - clock, 3), now

    run = load_run(run_dir, device)
    photos = training_photos(run)
    lap("photos")
    aabb = np.asarray(run.bounds.aabb, dtype=np.float64)
    resolution = lattice_resolution(run.model, aabb, options.resolution)
    volume = sample_volume(run.model, aabb, resolution)
    lap("volume")
    box = torch.as_tensor(aabb, dtype=torch.float32, device=volume.device)
    level, iou = choose_level(run.model, volume, box, run.train_cameras, options.level_views)
    lap("level")
    masked = None if photos is None else photos.masked().spread(CARVE_VIEWS)
    prepared = prepared_report(run.scene_source)
    estimated = prepared is not None  # a prepared capture's masks were segmented from its photos
    if masked is not None and masked.cameras and np.isfinite(level):
        volume = carve_volume(volume, box, level, masked.cameras, masked.alphas,
                              ESTIMATED if estimated else TOLERANCE)
        lap("carve")
    grid, unseen, unseen_share, cut = closed_lattice(volume.cpu().numpy(), level, aabb,
                                                     run.train_cameras, options, estimated, lap)
    volume = torch.as_tensor(grid, device=volume.device)
    mesh = object_mesh(volume, level, aabb, options.triangles, options.keep_share)
    cell = float((aabb[1] - aabb[0]).max()) / resolution
    if cut is not None:
        mesh = Mesh(flatten_base(mesh.vertices, *cut, cell), mesh.faces)
    lap("mesh")
    every_photo = photos if options.bake_views > 0 else None  # the refinement takes them all
    photos = photos.spread(options.bake_views) if photos and options.bake_views > 0 else None
    if photos is not None and options.settle:
        mesh = settle(mesh, photos, cell)
        lap("settle")
    depths = tuple(d * cell for d in BAKE_DEPTHS)
    # mean angle between neighbouring faces (degrees): how rough the surface is; the vertices
    # move from here on, the faces stay
    angles, pairs = {}, face_pairs(mesh.faces)

    def mean_angle(mesh: Mesh) -> float:
        return round(float(neighbour_angles(mesh, pairs).mean()), 2)

    uv = texture = None
    fade = None if unseen is None or not unseen.any() else (
        lambda points: weight_at(unseen, aabb, points))  # the unseen side's colour fades to grey
    if options.texture > 0:
        unwrapped = tex.unwrap(mesh, options.texture)
        lap("unwrap")
        image = tex.bake_image(run.model, unwrapped, options.texture, depths, photos, cell,
                               unseen=fade)
        lap("bake")
        if every_photo is not None and options.tune:
            angles["before tune"] = mean_angle(mesh)
            mesh = tune_surface(mesh, unwrapped.uv[unwrapped.faces], image, every_photo, cell)
            angles["tuned"] = mean_angle(mesh)
            # the tune roughens the surface: smooth it back to no rougher than it came
            mesh = taubin(mesh, options.smooth,
                          enough=lambda smoothed: mean_angle(smoothed) <= angles["before tune"])
            if cut is not None:
                mesh = Mesh(flatten_base(mesh.vertices, *cut, cell), mesh.faces)
            unwrapped = tex.moved(unwrapped, mesh)
            lap("tune")
        if options.close_unseen:
            mesh = held_to_covered(mesh, run.train_cameras, aabb)
            unwrapped = tex.moved(unwrapped, mesh)
            lap("hold")
        if every_photo is not None and options.refine:
            image = refine_texture(unwrapped.vertices, unwrapped.faces, unwrapped.uv, image,
                                   every_photo, estimated=estimated,
                                   texel_faces=unwrapped.texel_faces(image.shape[0]))
            lap("refine")
        texture = tex.finish_texture(image)
        surface = unwrapped
        vertices, faces, normals, uv = (unwrapped.vertices, unwrapped.faces, unwrapped.normals,
                                        unwrapped.uv)
    else:
        if options.close_unseen:
            mesh = held_to_covered(mesh, run.train_cameras, aabb)
            lap("hold")
        surface, normals = mesh, vertex_normals(mesh)
        vertices, faces = mesh.vertices, mesh.faces
    frame = model_frame(mesh.vertices, run.transform, options.size_cm)
    lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
    orbit = covered_orbit(run.train_cameras, (lo + hi) / 2)
    colours = None
    if vertex_colours or texture is None:
        occluders = None if photos is None else tex.surface_samples(surface)
        colours = np.round(255 * tex.surface_colour(run.model, vertices, normals, depths, photos,
                                                    cell, occluders, unseen=fade))
        lap("vertex colours")
    info = {"run": str(Path(run_dir).resolve()), "lattice_cells": resolution, "level": level,
            "silhouette_iou": round(iou, 4),
            "triangles": int(len(faces)), "texture": 0 if texture is None else texture.shape[0],
            "photos": 0 if photos is None else len(photos.cameras),
            "unseen_share": round(unseen_share, 4), "support_cut": cut is not None,
            "support_plane": plane_found(prepared),
            "neighbour_angle": {**angles, "delivered": mean_angle(mesh)},
            "orbit": orbit, "seconds": seconds}
    return Asset(vertices=apply(frame.to_model, vertices).astype(np.float32), faces=faces,
                 normals=(normals @ Z_UP_TO_Y_UP.T).astype(np.float32),
                 uv=None if uv is None else uv.astype(np.float32), texture=texture,
                 vertex_colours=None if colours is None else colours.astype(np.uint8),
                 roughness=options.roughness, frame=frame, info=info)


def closed_lattice(grid: np.ndarray, level: float, aabb: np.ndarray, cameras: list,
                   options: ExportOptions, prepared: bool, lap
                   ) -> tuple[np.ndarray, np.ndarray | None, float, tuple[float, float] | None]:
    """(densities `grid` (X, Y, Z) over `aabb` with the side no photo saw closed (unseen.py) and,
    for a `prepared` capture, the support's slab cut (support.py), as `options` ask; the unseen
    weight (X, Y, Z) or None, the share of the lattice's surface points no photo saw, (cut z,
    floor z) or None). The training `cameras` see the surface; `lap(stage)` times each step."""
    from windowshop.export.support import cut_support
    from windowshop.export.unseen import (close_unseen, hull_occupancy, surface_visibility,
                                          unseen_weight)

    if not np.isfinite(level) or float(grid.max()) <= level:
        return grid, None, 0.0, None  # marching cubes says what is wrong
    unseen, share, cut = None, 0.0, None
    if options.close_unseen:
        views = [cameras[i] for i in spread(options.bake_views or 24, len(cameras))]
        # the hull is of the seen parts the model keeps (keep_share, as mesh.keep_largest)
        visibility = surface_visibility(grid > level, aabb, views, keep_share=options.keep_share)
        unseen, share = unseen_weight(visibility, grid.shape), visibility.unseen_share
        grid = close_unseen(grid, level, unseen, hull_occupancy(visibility, grid.shape, aabb, unseen))
        lap("unseen")
    if options.cut_support and prepared:
        grid, cut_z, floor_z = cut_support(grid, level, aabb)
        cut = (cut_z, floor_z)
        lap("support")
    return grid, unseen, share, cut


def write_asset(asset: Asset, path: Path, fmt: str) -> None:
    """`asset` to `path` in format `fmt` (glb, usdz, ply), and the side file `path`.json."""
    from windowshop.export.frame import write_side_file

    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "glb":
        from windowshop.export.glb import write_glb

        write_glb(asset, path)
    elif fmt == "usdz":
        from windowshop.export.usdz import write_usdz

        write_usdz(asset, path)
    else:
        from windowshop.export.ply import write_ply

        write_ply(asset, path)
    write_side_file(side_file(path), asset.frame, {"format": fmt, **asset.info})


def side_file(path: Path) -> Path:
    """FILE.json beside FILE (`model.glb` -> `model.glb.json`)."""
    return path.with_name(path.name + ".json")


def export_models(run_dir: str | Path, paths: list[Path], options: ExportOptions = ExportOptions(),
                  device: torch.device | str = "cpu") -> Asset:
    """One asset of the run at `run_dir`, written to every path of `paths` (format from each
    extension)."""
    formats = [output_format(Path(p), None) for p in paths]
    if set(formats) == {"ply"}:
        options = replace(options, texture=0)  # PLY holds vertex colours only
    asset = build_asset(run_dir, options, device, vertex_colours="ply" in formats)
    # one format after the other: written side by side in threads (0.3-0.5 s saved), one run of
    # bench_real in seven hung with its main thread waiting on a lock; those threads, importing
    # trimesh and usd-core's pxr (C++ plugins, a thread pool of its own) at once, were the
    # likeliest cause (bench/RESULTS.md, stop 53)
    for path, fmt in zip(paths, formats):
        write_asset(asset, Path(path), fmt)
    return asset


def export_command(run_dir: str, out: str, fmt: str | None, options: ExportOptions,
                   device: torch.device | str = "cpu") -> Asset:
    """The CLI: export, then say what was written."""
    out_path = Path(out)
    fmt = output_format(out_path, fmt)
    if fmt == "ply":
        options = replace(options, texture=0)  # PLY holds vertex colours only
    start = time.perf_counter()
    asset = build_asset(run_dir, options, device, vertex_colours=fmt == "ply")
    write_asset(asset, out_path, fmt)
    size = out_path.stat().st_size / 1e6
    print(f"wrote {out_path} ({size:.1f} MB, {asset.info['triangles']} triangles, height "
          f"{asset.frame.height:.3g} {asset.frame.units}) and {side_file(out_path).name} in "
          f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
    return asset
