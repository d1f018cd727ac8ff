"""A trained run's object as a model file shops accept (`windowshop export`): GLB, USDZ, PLY.

    level.py    the density at which the surface lies, chosen from the field's own silhouettes
    mesh.py     density volume -> marching cubes -> the object's largest pieces -> decimated mesh
    frame.py    the model's frame (+Y up, standing at the origin, a real height) and its matrix
    texture.py  UVs (xatlas) and the base-colour texture baked from the field's colour
    glb.py, usdz.py, ply.py  the file formats
    command.py  the whole export, shared by the CLI and `windowshop video`
"""
