"""PLY for the tools that want it: the mesh with a colour per vertex (binary, through trimesh)."""

from __future__ import annotations

from pathlib import Path

from windowshop.export.asset import Asset


def write_ply(asset: Asset, path: Path) -> None:
    """Write `asset`'s mesh with its vertex colours to `path` as binary PLY."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=asset.vertices, faces=asset.faces, vertex_normals=asset.normals,
                           vertex_colors=asset.vertex_colours, process=False)
    path.write_bytes(mesh.export(file_type="ply", encoding="binary"))
