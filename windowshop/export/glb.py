"""GLB (binary glTF 2.0) through trimesh: one mesh, its normals and texture coordinates, and a
metal-free PBR material whose base colour is the baked texture (PNG, inside the file). The scene's
`extras` hold `windowshop.orbit` (export/orbit.py): the side to open on and, for a capture that
did not go all round, the arc a viewer may turn through (viewer.js honours it; the model-viewer
attributes that say the same are in it too)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from windowshop.export.asset import Asset


def to_trimesh(asset: Asset):
    """The asset as a `trimesh.Trimesh` in model coordinates, textured (or vertex-coloured)."""
    import trimesh
    from trimesh.visual import ColorVisuals, TextureVisuals
    from trimesh.visual.material import PBRMaterial

    if asset.texture is not None:
        material = PBRMaterial(name="baked", baseColorTexture=Image.fromarray(asset.texture),
                               metallicFactor=0.0, roughnessFactor=asset.roughness)
        # trimesh's uv has v = 0 at the image's bottom (OpenGL); glTF's at its top
        visual = TextureVisuals(uv=np.stack([asset.uv[:, 0], 1.0 - asset.uv[:, 1]], -1),
                                material=material)
    else:
        visual = ColorVisuals(vertex_colors=asset.vertex_colours)
    return trimesh.Trimesh(vertices=asset.vertices, faces=asset.faces, vertex_normals=asset.normals,
                           visual=visual, process=False)


def write_glb(asset: Asset, path: Path) -> None:
    """Write `asset` to `path` as GLB."""
    import trimesh

    scene = trimesh.Scene(to_trimesh(asset))
    if asset.info.get("orbit"):
        scene.metadata["windowshop"] = {"orbit": asset.info["orbit"]}
    path.write_bytes(scene.export(file_type="glb"))


def read_extras(path: Path) -> dict:
    """The scene's `extras` of the GLB at `path` (the JSON chunk's), {} when none."""
    import json
    import struct

    data = path.read_bytes()
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != 0x4E4F534A:  # "JSON"
        return {}
    tree = json.loads(data[20:20 + length])
    return (tree.get("scenes") or [{}])[tree.get("scene", 0)].get("extras", {}) or {}
