"""USDZ for AR Quick Look, through usd-core: a `.usdc` stage (upAxis Y, metres per unit 1) with
one mesh and a UsdPreviewSurface material reading the baked texture, packaged by
`UsdUtils.CreateNewARKitUsdzPackage` the way Apple asks (an uncompressed zip, the `.usdc` first,
every file 64-byte aligned)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from windowshop.export.asset import Asset

TEXTURE = "basecolor.png"


def _material(stage, asset: Asset, root: str):
    """The UsdPreviewSurface of `asset`: textured base colour (or the vertex colours)."""
    from pxr import Sdf, UsdShade

    material = UsdShade.Material.Define(stage, f"{root}/Material")
    surface = UsdShade.Shader.Define(stage, f"{root}/Material/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(asset.roughness))
    surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    if asset.texture is not None:
        reader = UsdShade.Shader.Define(stage, f"{root}/Material/UV")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
        image = UsdShade.Shader.Define(stage, f"{root}/Material/BaseColor")
        image.CreateIdAttr("UsdUVTexture")
        image.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(TEXTURE)
        image.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
        image.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
            reader.ConnectableAPI(), "result")
        image.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
        surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
            image.ConnectableAPI(), "rgb")
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    return material


def write_stage(asset: Asset, usdc: Path) -> None:
    """The `.usdc` stage of `asset` (and its texture beside it)."""
    from pxr import Sdf, Usd, UsdGeom, UsdShade, Vt

    stage = Usd.Stage.CreateNew(str(usdc))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Model")
    stage.SetDefaultPrim(root.GetPrim())
    mesh = UsdGeom.Mesh.Define(stage, "/Model/Mesh")
    points = asset.vertices.astype(np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points))
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([points.min(0), points.max(0)])))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(asset.faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(asset.faces.reshape(-1).astype(np.int32)))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(asset.normals.astype(np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)  # counter-clockwise faces the front
    primvars = UsdGeom.PrimvarsAPI(mesh)
    if asset.texture is not None:
        st = primvars.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
        # USD's t = 0 at the texture's bottom row, glTF's v = 0 at its top
        st.Set(Vt.Vec2fArray.FromNumpy(np.stack([asset.uv[:, 0], 1.0 - asset.uv[:, 1]], -1)
                                       .astype(np.float32)))
        (usdc.parent / TEXTURE).write_bytes(asset.texture_png)
    else:
        colours = primvars.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                         UsdGeom.Tokens.vertex)
        colours.Set(Vt.Vec3fArray.FromNumpy((asset.vertex_colours[:, :3] / 255.0).astype(np.float32)))
    material = _material(stage, asset, "/Model")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    stage.GetRootLayer().Save()


def write_usdz(asset: Asset, path: Path) -> None:
    """Write `asset` to `path` as a USDZ package AR Quick Look plays."""
    from pxr import Sdf, UsdUtils

    with tempfile.TemporaryDirectory(prefix="windowshop-usdz-") as tmp:
        usdc = Path(tmp) / f"{path.stem or 'model'}.usdc"
        write_stage(asset, usdc)
        if path.exists():
            path.unlink()
        if not UsdUtils.CreateNewARKitUsdzPackage(Sdf.AssetPath(str(usdc)), str(path)):
            raise RuntimeError(f"usd-core could not package {path}")
