"""GLB (binary glTF 2.0) through trimesh: one mesh, its normals and texture coordinates, and a
metal-free PBR material whose base colour is the baked texture (PNG, inside the file)."""

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
    path.write_bytes(to_trimesh(asset).export(file_type="glb"))
