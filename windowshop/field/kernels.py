"""The fused CPU kernels (kernels.c): built on first use with the system C compiler, cached, called
through ctypes.

The library has no torch headers, so building it takes well under a second and needs only `cc`;
it is cached per source, flags and CPU under `~/.cache/windowshop` (or `$XDG_CACHE_HOME`). It is
built for the host's vector units unless `WINDOWSHOP_KERNELS_MARCH` names another target (e.g.
`x86-64-v3`, AVX2 as most laptops have: the ordinary-CPU profile of bench/cpu_profile.py). Without
a compiler, on another device than the CPU, or with `WINDOWSHOP_KERNELS=0`, callers use their
pure-PyTorch twins instead (`available()` says which). Every wrapper takes contiguous CPU tensors of
the documented dtypes and writes into the given outputs.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import math
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import torch

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("kernels.c")
MARCH = os.environ.get("WINDOWSHOP_KERNELS_MARCH", "native")
FLAGS = ["-O3", f"-march={MARCH}", "-ffp-contract=off", "-fno-math-errno", "-shared", "-fPIC"]

_P, _I, _F = ctypes.c_void_p, ctypes.c_int64, ctypes.c_float
_SIGNATURES = {
    "trilinear_forward": [_P, _I, _I, _I, _I, _P, _I, _P],
    "trilinear_backward": [_P, _I, _I, _I, _I, _I, _P, _P, _P],
    "touched_rows": [_P, _I, _P],
    "harvest_rows": [_P, _P, _I, _P, _I, _P],
    "march_packed": [_P, _P, _P, _P, _P, _I, _F, _P, _I, _I, _P, _P, _P, _P],
    "march_fill": [_P, _P, _P, _P, _P, _I, _F, _P, _P, _P, _P],
    "adam_rows": [_P, _P, _P, _I, _P, _I, _P, _F, _F, _F, _F, _F],
    "trilinear_rays_forward": [_P, _I, _I, _I, _I, _P, _P, _P, _P, _I, _P, _P, _P],
    "trilinear_rays_backward": [_I, _I, _I, _I, _P, _P, _P, _P, _I, _P, _P, _P, _P, _P, _P],
    "composite_rays_forward": [_P, _I, _I, _I, _I, _P, _P, _P, _P, _P, _P, _P, _I, _P, _P, _P, _P],
    "composite_rays_backward": [_I, _I, _I, _I, _P, _P, _P, _P, _P, _I, _P, _P, _P, _P, _P, _P, _P,
                                _P, _P],
    "ray_weights_forward": [_P, _P, _P, _P, _I, _F, _P, _P, _P],
    "ray_weights_backward": [_P, _P, _P, _P, _P, _I, _F, _P, _P, _P, _P],
    "render_composite": [_P, _P, _P, _P, _P],
    "rasterise_faces": [_P, _P, _P, _I, _I, _I, ctypes.c_double, _P, _P],
}


class _Occupancy(ctypes.Structure):
    """kernels.c's Occupancy: a fine and a coarse occupancy grid over a box."""

    _fields_ = [("occ", _P), ("coarse", _P), ("dims", _I * 3), ("cdims", _I * 3), ("lo", _P),
                ("inv_cell", _P)]


class _RenderMarch(ctypes.Structure):
    """kernels.c's RenderMarch: the arguments of render_composite."""

    _fields_ = [("origins", _P), ("dirs", _P), ("t_min", _P), ("t_max", _P), ("R", _I),
                ("step", _F), ("grid", ctypes.POINTER(_Occupancy)), ("density", _P),
                ("features", _P), ("X", _I), ("Y", _I), ("Z", _I), ("C", _I), ("inv_voxel", _P),
                ("shift", _F), ("scale", _F), ("threshold", _F)]


BLOCK = 4  # kernels.c's BLOCK: cells per side of a coarse occupancy block


def _occupancy(grid: tuple) -> _Occupancy:
    """The kernels' view of `grid` = (occupied (OX, OY, OZ) uint8, coarse uint8, lo (3,),
    inv_cell (3,)); the tensors must outlive its use."""
    occupied, coarse, lo, inv_cell = grid
    return _Occupancy(_ptr(occupied), _ptr(coarse), (_I * 3)(*occupied.shape),
                      (_I * 3)(*coarse.shape), _ptr(lo), _ptr(inv_cell))


def _cpu_id() -> str:
    """What identifies this CPU's instruction set (the library is built for the host's)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
        return next((line for line in text.splitlines() if line.startswith("flags")), text[:2000])
    except OSError:
        return platform.processor() + platform.machine()


def _cache_dir() -> Path:
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "windowshop" / "kernels"


def _build(compiler: str, target: Path) -> None:
    """Compile kernels.c into `target`, with OpenMP when the compiler has it."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        out = Path(tmp) / target.name
        for extra in (["-fopenmp"], []):
            cmd = [compiler, *FLAGS, *extra, str(SOURCE), "-o", str(out), "-lm"]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode == 0:
                os.replace(out, target)  # atomic: concurrent builders never see half a file
                return
        raise RuntimeError(done.stderr.strip()[-2000:])


@functools.lru_cache(maxsize=1)
def library() -> ctypes.CDLL | None:
    """The loaded kernel library, or None when it cannot be had (see the module docstring)."""
    if os.environ.get("WINDOWSHOP_KERNELS", "1") == "0":
        return None
    compiler = shutil.which(os.environ.get("CC", "cc"))
    if compiler is None:
        log.warning("no C compiler found: the fast model uses its (slower) pure-PyTorch path")
        return None
    source = SOURCE.read_bytes()
    key = hashlib.sha256(b"\0".join([source, " ".join(FLAGS).encode(), compiler.encode(),
                                     _cpu_id().encode()])).hexdigest()[:16]
    target = _cache_dir() / f"windowshop_kernels_{key}.so"
    try:
        if not target.is_file():
            _build(compiler, target)
        lib = ctypes.CDLL(str(target))
    except (OSError, RuntimeError) as err:
        log.warning("building the fast kernels failed, using pure PyTorch: %s", err)
        return None
    for name, argtypes in _SIGNATURES.items():
        getattr(lib, name).argtypes = argtypes
        getattr(lib, name).restype = _I if name in ("touched_rows", "march_packed") else None
    return lib


def available(device: torch.device | str) -> bool:
    """Whether tensors on `device` can use the fused kernels."""
    return torch.device(device).type == "cpu" and library() is not None


def _profiled(fn):
    """Name each kernel call in torch.profiler traces (calls through ctypes are invisible there)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with torch.profiler.record_function(f"kernels.{fn.__name__}"):
            return fn(*args, **kwargs)
    return wrapper


def _ptr(t: torch.Tensor) -> int:
    assert t.is_contiguous() and t.device.type == "cpu", "kernels take contiguous CPU tensors"
    return t.data_ptr()


@_profiled
def trilinear_forward(values: torch.Tensor, shape: tuple[int, int, int], points: torch.Tensor
                      ) -> torch.Tensor:
    """Interpolate `values` (X*Y*Z, C) float32 at `points` (N, 3) in grid units: (N, C)."""
    n, c = points.shape[0], values.shape[1]
    out = torch.empty(n, c, dtype=torch.float32)
    library().trilinear_forward(_ptr(values), *shape, c, _ptr(points), n, _ptr(out))
    return out


@_profiled
def trilinear_backward(points: torch.Tensor, shape: tuple[int, int, int], grad_out: torch.Tensor,
                       accum: torch.Tensor, touched: torch.Tensor) -> None:
    """accum (V, C) += d(interpolation)/d(values) . grad_out (N, C); touched (V,) uint8 marks rows."""
    library().trilinear_backward(_ptr(points), points.shape[0], *shape, accum.shape[1],
                                 _ptr(grad_out), _ptr(accum), _ptr(touched))


@_profiled
def trilinear_rays_forward(values: torch.Tensor, shape: tuple[int, int, int], rays: tuple,
                           lo: torch.Tensor, inv_voxel: torch.Tensor) -> torch.Tensor:
    """Interpolate `values` (V, C) at ray samples `rays` = (origins (R, 3), directions (R, 3),
    t (N,), ray (N,) int64), mapped to grid units by (x - lo) * inv_voxel: (N, C)."""
    origins, directions, t, ray = rays
    out = torch.empty(t.shape[0], values.shape[1], dtype=torch.float32)
    library().trilinear_rays_forward(_ptr(values), *shape, values.shape[1], _ptr(origins),
                                     _ptr(directions), _ptr(t), _ptr(ray), t.shape[0], _ptr(lo),
                                     _ptr(inv_voxel), _ptr(out))
    return out


@_profiled
def trilinear_rays_backward(shape: tuple[int, int, int], rays: tuple, lo: torch.Tensor,
                            inv_voxel: torch.Tensor, grad_out: torch.Tensor, accum: torch.Tensor,
                            touched: torch.Tensor) -> None:
    """accum (V, C) += the values' gradient of trilinear_rays_forward; touched (V,) marks rows."""
    origins, directions, t, ray = rays
    points = torch.empty(t.shape[0], 3, dtype=torch.float32)
    library().trilinear_rays_backward(*shape, accum.shape[1], _ptr(origins), _ptr(directions),
                                      _ptr(t), _ptr(ray), t.shape[0], _ptr(lo), _ptr(inv_voxel),
                                      _ptr(grad_out), _ptr(accum), _ptr(touched), _ptr(points))


@_profiled
def composite_rays_forward(values: torch.Tensor, shape: tuple[int, int, int], rays: tuple,
                           weights: torch.Tensor, counts: torch.Tensor, lo: torch.Tensor,
                           inv_voxel: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-ray sums (R, C) of weights (N,) times the values interpolated at the ray samples
    (sorted by ray, `counts` (R,) per ray); also returns those interpolated values (N, C)."""
    origins, directions, t, ray = rays
    c = values.shape[1]
    starts = (torch.cumsum(counts, 0) - counts).contiguous()
    features = torch.empty(t.shape[0], c, dtype=torch.float32)
    out = torch.empty(counts.shape[0], c, dtype=torch.float32)
    library().composite_rays_forward(_ptr(values), *shape, c, _ptr(origins), _ptr(directions),
                                     _ptr(t), _ptr(ray), _ptr(weights), _ptr(starts), _ptr(counts),
                                     counts.shape[0], _ptr(lo), _ptr(inv_voxel), _ptr(features),
                                     _ptr(out))
    return out, features


@_profiled
def composite_rays_backward(shape: tuple[int, int, int], rays: tuple, weights: torch.Tensor,
                            lo: torch.Tensor, inv_voxel: torch.Tensor, features: torch.Tensor,
                            grad_out: torch.Tensor, accum: torch.Tensor, touched: torch.Tensor
                            ) -> torch.Tensor:
    """The gradient of the weights (N,) of composite_rays_forward; accum += the values'."""
    origins, directions, t, ray = rays
    c = accum.shape[1]
    grad_w = torch.empty(t.shape[0], dtype=torch.float32)
    points = torch.empty(t.shape[0], 3, dtype=torch.float32)
    grad_samples = torch.empty(t.shape[0], c, dtype=torch.float32)
    library().composite_rays_backward(*shape, c, _ptr(origins), _ptr(directions), _ptr(t),
                                      _ptr(ray), _ptr(weights), t.shape[0], _ptr(lo),
                                      _ptr(inv_voxel), _ptr(features), _ptr(grad_out),
                                      _ptr(grad_w), _ptr(accum), _ptr(touched), _ptr(points),
                                      _ptr(grad_samples))
    return grad_w


@_profiled
def ray_weights_forward(sigma: torch.Tensor, t: torch.Tensor, starts: torch.Tensor,
                        counts: torch.Tensor, dt: float
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Compositing weights (N,) of packed samples with densities `sigma` (N,) at distances `t`
    (N,) over intervals `dt`, ray r's from starts[r] for counts[r]; and per ray (R,) their sum
    (opacity) and their sum times t (depth)."""
    r = counts.shape[0]
    w = torch.empty_like(sigma)
    opacity, depth = torch.empty(r, dtype=torch.float32), torch.empty(r, dtype=torch.float32)
    library().ray_weights_forward(_ptr(sigma), _ptr(t), _ptr(starts), _ptr(counts), r, dt,
                                  _ptr(w), _ptr(opacity), _ptr(depth))
    return w, opacity, depth


@_profiled
def ray_weights_backward(sigma: torch.Tensor, t: torch.Tensor, w: torch.Tensor,
                         starts: torch.Tensor, counts: torch.Tensor, dt: float,
                         grads: tuple[torch.Tensor, torch.Tensor, torch.Tensor]) -> torch.Tensor:
    """The gradient (N,) of `sigma` of ray_weights_forward, given `grads` of its three outputs."""
    grad_sigma = torch.empty_like(sigma)
    library().ray_weights_backward(_ptr(sigma), _ptr(t), _ptr(w), _ptr(starts), _ptr(counts),
                                   counts.shape[0], dt, *(_ptr(g) for g in grads), _ptr(grad_sigma))
    return grad_sigma


@_profiled
def harvest(accum: torch.Tensor, touched: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The touched rows (M,) int64 in increasing order and their accumulated values (M, C).

    Clears those rows of `accum` and of `touched`, so the buffers are ready for the next step.
    """
    lib = library()
    rows = torch.empty(touched.shape[0], dtype=torch.int64)
    m = lib.touched_rows(_ptr(touched), touched.shape[0], _ptr(rows))
    rows = rows[:m].clone()
    values = torch.empty(m, accum.shape[1], dtype=torch.float32)
    lib.harvest_rows(_ptr(accum), _ptr(touched), accum.shape[1], _ptr(rows), m, _ptr(values))
    return rows, values


MARCH_PARTS = 32  # runs of rays that threads march in one pass, each into its own room
_samples_per_ray = [32.0]  # room per ray for the next march: what the last one needed


@_profiled
def march(origins: torch.Tensor, directions: torch.Tensor, t_min: torch.Tensor,
          t_max: torch.Tensor, offsets: torch.Tensor, step: float, grid: tuple
          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Occupied samples t_min + (k + offset) step < t_max of rays (R, 3) through `grid` (see
    _occupancy); returns t (S,), ray (S,) int64 and counts (R,) int64 as occupancy.march."""
    lib = library()
    r = origins.shape[0]
    occupancy = _occupancy(grid)
    common = [_ptr(origins), _ptr(directions), _ptr(t_min), _ptr(t_max), _ptr(offsets), r, step,
              ctypes.byref(occupancy)]
    counts = torch.empty(r, dtype=torch.int64)
    parts = max(1, min(MARCH_PARTS, r))
    room = math.ceil(r / parts * _samples_per_ray[0] * 1.25) + 16
    t = torch.empty(parts * room, dtype=torch.float32)
    ray = torch.empty(parts * room, dtype=torch.int64)
    used = torch.empty(parts, dtype=torch.int64)
    total = lib.march_packed(*common, parts, room, _ptr(t), _ptr(ray), _ptr(counts), _ptr(used))
    # the next batch's room: as many samples a ray as the busiest run of rays had this time
    _samples_per_ray[0] = float(used.max()) / math.ceil(r / parts) if r else _samples_per_ray[0]
    if total >= 0:
        return t[:total], ray[:total], counts
    ends = torch.cumsum(counts, 0)  # a run overflowed its room: fill from the counts
    starts = (ends - counts).contiguous()
    total = int(ends[-1])
    t = torch.empty(total, dtype=torch.float32)
    ray = torch.empty(total, dtype=torch.int64)
    lib.march_fill(*common, _ptr(starts), _ptr(t), _ptr(ray))
    return t, ray, counts


@_profiled
def adam_rows(param: torch.Tensor, exp_avg: torch.Tensor, exp_avg_sq: torch.Tensor,
              rows: torch.Tensor, grad: torch.Tensor, lr: float, betas: tuple[float, float],
              eps: float, step: int) -> None:
    """Adam step `step` (from 1) on `rows` (M,) of (V, C) tensors, in place; see optim.GridAdam."""
    beta1, beta2 = betas
    lr_c = lr / (1.0 - beta1 ** step)
    sqrt_c2 = (1.0 - beta2 ** step) ** 0.5
    library().adam_rows(_ptr(param), _ptr(exp_avg), _ptr(exp_avg_sq), param.shape[1], _ptr(rows),
                        rows.shape[0], _ptr(grad), lr_c, beta1, beta2, eps, sqrt_c2)


@_profiled
def render_composite(origins: torch.Tensor, directions: torch.Tensor, t_min: torch.Tensor,
                     t_max: torch.Tensor, step: float, grid: tuple, density: torch.Tensor,
                     features: torch.Tensor, shape: tuple[int, int, int], inv_voxel: torch.Tensor,
                     shift: float, scale: float, threshold: float) -> tuple[torch.Tensor, ...]:
    """March rays (R, 3) at offsets 0.5 with early termination and composite their features in
    one pass (see kernels.c render_ray).

    `grid` is the occupancy (see _occupancy); `density` (X*Y*Z,) the raw one-channel grid and
    `features` (X*Y*Z, C) the feature grid, both of `shape` over the same box, points mapping to
    grid units by (x - lo) * inv_voxel. Returns per ray the sum (R, C) of weight times features
    over its samples of weight >= threshold, their number (R,) int64, and the opacity (R,) and
    depth (R,) of all samples marched.
    """
    r, c = origins.shape[0], features.shape[1]
    occupancy = _occupancy(grid)
    args = _RenderMarch(_ptr(origins), _ptr(directions), _ptr(t_min), _ptr(t_max), r, step,
                        ctypes.pointer(occupancy), _ptr(density), _ptr(features), *shape, c,
                        _ptr(inv_voxel), shift, scale, threshold)
    out, opacity, depth = torch.empty(r, c), torch.empty(r), torch.empty(r)
    counts = torch.empty(r, dtype=torch.int64)
    library().render_composite(ctypes.byref(args), _ptr(out), _ptr(opacity), _ptr(depth), _ptr(counts))
    return out, counts, opacity, depth


@_profiled
def rasterise_faces(xy: torch.Tensor, depth: torch.Tensor, faces: torch.Tensor, width: int,
                    height: int, near: float) -> torch.Tensor:
    """(H*W,) int64: the nearest of `faces` (F, 3) int64 at each pixel centre, -1 where none, of
    vertices at pixel coordinates `xy` (V, 2) and depths `depth` (V,) float64 (see kernels.c)."""
    face = torch.empty(width * height, dtype=torch.int64)
    zbuf = torch.empty(width * height, dtype=torch.float64)
    library().rasterise_faces(_ptr(xy), _ptr(depth), _ptr(faces), faces.shape[0], width, height,
                              near, _ptr(zbuf), _ptr(face))
    return face
