"""A trained run's object as a model file shops accept (`windowshop export`): GLB, USDZ, PLY.

    level.py    the density at which the surface lies, chosen from the field's own silhouettes
    mesh.py     density lattice -> marching cubes -> the object's largest pieces -> decimated mesh
    frame.py    the model's frame (+Y up, standing at the origin, a real height) and its matrix
    texture.py  UVs (charts by facing axis) and the base-colour texture baked from the field
    asset.py    the textured mesh in model coordinates that every format writes
    glb.py, usdz.py, ply.py  the file formats
    command.py  the whole export, shared by the CLI and `windowshop video`
    raster.py   a small rasteriser to compare an exported mesh with photos (bench, tests)
"""
