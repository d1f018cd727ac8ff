"""The vertices of a PLY point cloud (ASCII or binary), as nerfstudio's `ply_file_path` names one:
its sparse COLMAP points, in the transforms.json frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from windowshop.errors import UserError

# PLY property types -> numpy types (both spellings of each)
TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
         "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
         "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
ENDIAN = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "<"}


def _header(data: bytes, path: Path) -> tuple[str, int, list[tuple[str, str]], int]:
    """(format, vertex count, vertex properties, offset of the body); vertices must come first."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise UserError(f"{path}: not a PLY file")
    body = data.index(b"\n", end) + 1
    fmt, count, props, element = "", 0, [], None
    for line in data[:end].decode("ascii", "replace").splitlines():
        words = line.split()
        if words[:1] == ["format"]:
            fmt = words[1]
        elif words[:1] == ["element"]:
            element = words[1]
            if element == "vertex":
                count = int(words[2])
            elif not props:
                raise UserError(f"{path}: the vertices must be the first element")
        elif words[:1] == ["property"] and element == "vertex":
            if words[1] == "list" or words[1] not in TYPES:
                raise UserError(f"{path}: unsupported vertex property {' '.join(words[1:])}")
            props.append((words[2], TYPES[words[1]]))
    if fmt not in ENDIAN or not {"x", "y", "z"} <= {name for name, _ in props}:
        raise UserError(f"{path}: expected a PLY point cloud with x, y, z vertices")
    return fmt, count, props, body


def read_ply_points(path: Path) -> np.ndarray:
    """(N, 3) float64 vertex positions of the PLY file at `path`."""
    try:
        data = path.read_bytes()
        fmt, count, props, body = _header(data, path)
        if fmt == "ascii":
            rows = np.loadtxt(data[body:].decode("ascii").splitlines()[:count], ndmin=2)
            names = [name for name, _ in props]
            return rows[:, [names.index(a) for a in "xyz"]].astype(np.float64)
        dtype = np.dtype([(name, ENDIAN[fmt] + kind) for name, kind in props])
        vertices = np.frombuffer(data, dtype=dtype, count=count, offset=body)
    except (OSError, ValueError, UnicodeDecodeError) as err:
        raise UserError(f"{path}: cannot read the point cloud ({err})") from err
    return np.stack([vertices[a] for a in "xyz"], axis=-1).astype(np.float64)
