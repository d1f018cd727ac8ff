"""GLB (binary glTF 2.0) through pygltflib: one mesh, its normals and texture coordinates (or
vertex colours), and a metal-free PBR material whose base colour is the baked texture (PNG,
inside the file). The scene's `extras` hold `windowshop.orbit` (export/orbit.py): the side to
open on and, for a capture that did not go all round, the arc a viewer may turn through
(viewer.js honours it; the model-viewer attributes that say the same are in it too).

pygltflib writes the file as the asset holds it, and imports in 0.1 s: trimesh, which wrote it
before, took 0.7-1.1 s to import (networkx, scipy.spatial) and PNG-encoded the texture at zlib's
default level (Asset.texture_png: once for both formats, at level 1), a tenth of the export of
a 20-photo capture (bench/RESULTS.md, stop 55)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from windowshop.export.asset import Asset

FLOAT, UNSIGNED_INT, UNSIGNED_BYTE = 5126, 5125, 5121  # glTF's componentType
TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


def write_glb(asset: Asset, path: Path) -> None:
    """Write `asset` to `path` as GLB."""
    from pygltflib import (GLTF2, Accessor, Attributes, Buffer, BufferView, Material, Mesh, Node,
                           PbrMetallicRoughness, Primitive, Scene, Texture, TextureInfo)
    from pygltflib import Asset as About
    from pygltflib import Image as Picture

    gltf = GLTF2(asset=About(generator="windowshop", version="2.0"))
    blob = bytearray()

    def view(data: bytes) -> int:
        blob.extend(b"\0" * (-len(blob) % 4))  # each view starts on a 4-byte boundary
        gltf.bufferViews.append(BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob.extend(data)
        return len(gltf.bufferViews) - 1

    def accessor(values: np.ndarray, component: int, bounds: bool = False,
                 normalized: bool = False) -> int:
        rows = np.ascontiguousarray(values).reshape(len(values), -1)
        gltf.accessors.append(Accessor(
            bufferView=view(rows.tobytes()), componentType=component, count=len(rows),
            type=TYPES[values.shape[1] if values.ndim > 1 else 1], normalized=normalized or None,
            min=rows.min(0).tolist() if bounds else None,
            max=rows.max(0).tolist() if bounds else None))
        return len(gltf.accessors) - 1

    attributes = Attributes(POSITION=accessor(asset.vertices.astype(np.float32), FLOAT, bounds=True),
                            NORMAL=accessor(asset.normals.astype(np.float32), FLOAT))
    colour = PbrMetallicRoughness(metallicFactor=0.0, roughnessFactor=asset.roughness)
    if asset.texture is not None:
        attributes.TEXCOORD_0 = accessor(asset.uv.astype(np.float32), FLOAT)  # glTF's v, as asset
        gltf.images.append(Picture(bufferView=view(asset.texture_png), mimeType="image/png"))
        gltf.textures.append(Texture(source=0))
        colour.baseColorTexture = TextureInfo(index=0)
    else:
        attributes.COLOR_0 = accessor(asset.vertex_colours.astype(np.uint8), UNSIGNED_BYTE,
                                      normalized=True)
    gltf.materials.append(Material(name="baked", pbrMetallicRoughness=colour))
    indices = accessor(asset.faces.reshape(-1).astype(np.uint32), UNSIGNED_INT, bounds=True)
    gltf.meshes.append(Mesh(primitives=[Primitive(attributes=attributes, indices=indices,
                                                  material=0)]))
    gltf.nodes.append(Node(mesh=0))
    extras = {"windowshop": {"orbit": asset.info["orbit"]}} if asset.info.get("orbit") else {}
    gltf.scenes.append(Scene(nodes=[0], extras=extras))
    gltf.buffers.append(Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(bytes(blob))
    path.write_bytes(b"".join(gltf.save_to_bytes()))


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
