"""`windowshop export` on a briefly trained run: the files validate, the caps hold, the side file's
matrix puts the model where the photos saw the object, bad input fails clearly."""

import json
import zipfile

import numpy as np
import pytest
import torch
import trimesh

from export_helpers import object_scene
from windowshop.cli import main
from windowshop.config import ExportOptions
from windowshop.errors import UserError
from windowshop.export.command import export_models, side_file
from windowshop.export.frame import apply
from windowshop.export.mesh import Mesh, drop_fins, lattice_resolution, open_edges
from windowshop.rays import project

SMALL = ExportOptions(triangles=1500, texture=256, resolution=48)


@pytest.fixture(scope="module")
def exported(object_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("exported")
    paths = [out / "model.glb", out / "model.usdz", out / "model.ply"]
    asset = export_models(object_run, paths, SMALL)
    return asset, paths


def test_glb_validates_in_pygltflib_and_trimesh(exported):
    from pygltflib import GLTF2

    _, (glb, _, _) = exported
    gltf = GLTF2().load(str(glb))
    blob = gltf.binary_blob()
    assert len(gltf.buffers) == 1 and gltf.buffers[0].byteLength <= len(blob)
    for view in gltf.bufferViews:
        assert view.buffer == 0 and (view.byteOffset or 0) + view.byteLength <= len(blob)
    for accessor in gltf.accessors:
        assert 0 <= accessor.bufferView < len(gltf.bufferViews)
    (primitive,) = gltf.meshes[0].primitives
    attributes = primitive.attributes
    assert None not in (attributes.POSITION, attributes.NORMAL, attributes.TEXCOORD_0)
    assert gltf.accessors[primitive.indices].count <= 3 * SMALL.triangles
    material = gltf.materials[primitive.material]
    texture = gltf.textures[material.pbrMetallicRoughness.baseColorTexture.index]
    image = gltf.images[texture.source]
    assert image.mimeType == "image/png" and image.bufferView < len(gltf.bufferViews)
    assert material.pbrMetallicRoughness.metallicFactor == 0.0
    loaded = trimesh.load(glb, force="mesh")
    assert loaded.visual.material.baseColorTexture.size == (256, 256)
    assert loaded.visual.uv.shape == (len(loaded.vertices), 2)


def test_triangle_cap_is_honoured_and_the_surface_is_closed(exported):
    asset, (glb, _, _) = exported
    loaded = trimesh.load(glb, force="mesh", process=False)
    assert SMALL.triangles // 2 < len(loaded.faces) <= SMALL.triangles
    welded = trimesh.Trimesh(asset.vertices, asset.faces)  # merges the UV seams' copies
    # closed: no edge with one face (decimation may pinch an edge between four faces)
    assert open_edges(Mesh(welded.vertices, welded.faces)) == 0
    assert welded.volume > 0  # faces wind counter-clockwise seen from outside


def test_usdz_is_an_uncompressed_aligned_zip_led_by_its_usdc(exported):
    from pxr import Usd, UsdGeom

    _, (_, usdz, _) = exported
    with zipfile.ZipFile(usdz) as archive:
        entries = archive.infolist()
        assert entries[0].filename.endswith(".usdc")
        assert any(e.filename.endswith(".png") for e in entries)
        raw = usdz.read_bytes()
        for entry in entries:
            assert entry.compress_type == zipfile.ZIP_STORED
            name_len = int.from_bytes(raw[entry.header_offset + 26:entry.header_offset + 28], "little")
            extra_len = int.from_bytes(raw[entry.header_offset + 28:entry.header_offset + 30], "little")
            assert (entry.header_offset + 30 + name_len + extra_len) % 64 == 0
    stage = Usd.Stage.Open(str(usdz))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Model/Mesh"))
    assert len(mesh.GetFaceVertexCountsAttr().Get()) <= SMALL.triangles


def test_the_model_stands_at_the_origin_with_y_up(exported):
    asset, _ = exported
    lo, hi = asset.vertices.min(0), asset.vertices.max(0)
    assert lo[1] == pytest.approx(0.0, abs=1e-5)
    assert (lo[[0, 2]] + hi[[0, 2]]) / 2 == pytest.approx([0.0, 0.0], abs=1e-5)
    # the scene's up (normalised +z) is the model's +y
    up = asset.frame.to_model[:3, :3] @ np.array([0.0, 0.0, 1.0])
    assert up / np.linalg.norm(up) == pytest.approx([0.0, 1.0, 0.0])


def test_side_file_maps_the_model_onto_the_source_cameras(exported):
    asset, (glb, _, _) = exported
    record = json.loads(side_file(glb).read_text())
    to_source = np.array(record["model_to_source"])
    loaded = trimesh.load(glb, force="mesh", process=False)
    source_points = apply(to_source, np.asarray(loaded.vertices))
    for view in object_scene().split("test"):
        uv, depth = project(source_points, view.stored_camera)  # the source's own cameras
        assert np.all(depth > 0)
        pixel = np.clip(np.floor(uv).astype(int), 0, view.alpha.shape[0] - 1)
        on_object = view.alpha[pixel[:, 1], pixel[:, 0]] > 0.5
        assert on_object.mean() > 0.9
    # a known point: the model's origin is the bottom of the object, under its footprint's centre
    normalised = np.linalg.inv(asset.frame.to_model) @ np.array([0.0, 0.0, 0.0, 1.0])
    assert to_source @ [0, 0, 0, 1] == pytest.approx(np.linalg.inv(object_scene().transform)
                                                     @ normalised)


def test_ply_has_a_colour_per_vertex(exported):
    _, (_, _, ply) = exported
    loaded = trimesh.load(ply, process=False)
    colours = loaded.visual.vertex_colors
    assert len(colours) == len(loaded.vertices) and colours[:, :3].std() > 0


def test_size_cm_scales_to_the_real_height(object_run, tmp_path):
    out = tmp_path / "tall.glb"
    assert main(["export", str(object_run), "--out", str(out), "--size-cm", "25",
                 "--texture", "0", "--triangles", "500", "--resolution", "32"]) == 0
    loaded = trimesh.load(out, force="mesh")
    assert loaded.extents[1] == pytest.approx(0.25, rel=1e-4)
    assert json.loads(side_file(out).read_text())["units"] == "metres"
    # vertex colours under a metal-free material: without one, glTF's default is a metal
    from pygltflib import GLTF2

    gltf = GLTF2().load(str(out))
    (primitive,) = gltf.meshes[0].primitives
    colour = gltf.accessors[primitive.attributes.COLOR_0]
    assert colour.normalized and colour.count == gltf.accessors[primitive.attributes.POSITION].count
    assert gltf.materials[primitive.material].pbrMetallicRoughness.metallicFactor == 0.0


def test_a_path_that_is_not_a_run_fails_clearly(tmp_path, capsys):
    assert main(["export", str(tmp_path), "--out", str(tmp_path / "m.glb")]) == 2
    assert "run folder" in capsys.readouterr().err


def test_an_empty_field_fails_clearly(object_run, tmp_path):
    state = torch.load(object_run / "checkpoint.pt", weights_only=True)
    state["model_state"]["density_grid.values"].fill_(-40.0)  # nothing anywhere
    (tmp_path / "empty").mkdir()
    torch.save(state, tmp_path / "empty" / "checkpoint.pt")
    with pytest.raises(UserError, match="no object"):
        export_models(tmp_path / "empty", [tmp_path / "m.glb"], SMALL)


def test_folded_fins_cancel_in_pairs_and_leave_the_surface_closed():
    tetra = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    # a triple on one face's vertices (a fin meeting the surface) and a fin pair off it
    faces = np.concatenate([tetra, [[0, 1, 2], [1, 0, 2]], [[0, 1, 4], [1, 0, 4]]])
    kept = drop_fins(faces)
    assert len(kept) == 4 and not np.isin(4, kept)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    assert open_edges(Mesh(vertices, kept)) == 0


def test_the_lattice_resolves_the_field_voxels_and_no_finer():
    from windowshop.field.fast import FastModel
    from windowshop.config import FastConfig
    from windowshop.model import Bounds

    aabb = np.array([[-1.0, -0.5, -0.25], [1.0, 0.5, 0.25]])
    model = FastModel(FastConfig(voxels=16 * 8 * 4, growth=()),
                      Bounds(aabb=tuple(map(tuple, aabb)), near=0.1, far=10.0))
    voxel = 2.0 / (model.density_grid.shape[0] - 1)  # the grid's vertices span the box
    assert float(model.density_grid.voxel.min()) == pytest.approx(voxel)
    assert lattice_resolution(model, aabb, 256) == int(np.ceil(1.5 * 2.0 / voxel))
    assert lattice_resolution(model, aabb, 12) == 12  # the option caps it
    assert lattice_resolution(torch.nn.Linear(1, 1), aabb, 100) == 100  # no grid: the option
