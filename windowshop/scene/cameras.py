"""Camera geometry, the one home for it: pose conventions (every source's camera axes converted to
OpenGL camera-to-world, and checks), look-at, the point the cameras look at, and a capture's up."""

from __future__ import annotations

from typing import Literal

import numpy as np

from windowshop.errors import UserError

# OpenCV/COLMAP camera axes (x right, y down, z forward) -> OpenGL (x right, y up, z backward).
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def checked_rotation(rot: np.ndarray, where: str, tol: float = 1e-2) -> np.ndarray:
    """`rot` (3, 3) re-orthonormalised, or a UserError naming `where` if it is not a rotation."""
    rot = np.asarray(rot, dtype=np.float64)
    if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
        raise UserError(f"{where}: the pose's rotation is not a finite 3x3 matrix")
    err = np.abs(rot.T @ rot - np.eye(3)).max()
    if err > tol or np.linalg.det(rot) < 0:
        raise UserError(f"{where}: the pose is not a rotation (R^T R deviates from I by {err:.3g}, "
                        f"det {np.linalg.det(rot):.3g}); fix or re-export the camera poses")
    u, _, vt = np.linalg.svd(rot)
    return u @ vt


def c2w_matrix(c2w: np.ndarray, where: str) -> np.ndarray:
    """A (4, 4) camera-to-world from a (3, 4) or (4, 4) matrix, its rotation checked."""
    c2w = np.asarray(c2w, dtype=np.float64)
    if c2w.shape not in ((3, 4), (4, 4)):
        raise UserError(f"{where}: a pose must be a 3x4 or 4x4 matrix, got shape {c2w.shape}")
    out = np.eye(4)
    out[:3, :3] = checked_rotation(c2w[:3, :3], where)
    out[:3, 3] = c2w[:3, 3]
    if not np.all(np.isfinite(out)):
        raise UserError(f"{where}: the pose has non-finite entries")
    return out


def opencv_w2c_to_gl_c2w(rot: np.ndarray, t: np.ndarray, where: str) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) from an OpenCV world-to-camera rotation (3, 3) and t (3,)."""
    rot = checked_rotation(rot, where)
    c2w = np.eye(4)
    c2w[:3, :3] = rot.T
    c2w[:3, 3] = -rot.T @ np.asarray(t, dtype=np.float64)
    return c2w @ CV_TO_GL


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) of a camera at `eye` (3,) looking at `target` with `up`."""
    back = eye - target
    back = back / np.linalg.norm(back)
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-8:  # looking straight along `up`: any horizontal right works
        right = np.cross([0.0, 1.0, 0.0] if abs(up[1]) < 0.9 else [1.0, 0.0, 0.0], back)
    right = right / np.linalg.norm(right)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, np.cross(back, right), back, eye
    return c2w


def nearest_point_to_axes(c2ws: np.ndarray, prior: np.ndarray | None = None,
                          weight: float = 1e-6) -> np.ndarray:
    """(3,) the point nearest, in least squares, to every camera's optical axis; c2ws (N, 4, 4).

    Parallel axes (one camera, or a forward-facing capture) leave the point along them open:
    with a `prior` (3,), a weak pull of `weight` towards it decides it (moving a converging
    capture's answer negligibly; the turntable's orbit); without, nearly parallel axes give the
    mean camera centre one unit ahead of the mean viewing direction (the scene readers).
    """
    dirs = -c2ws[:, :3, 2]
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = c2ws[:, :3, 3]
    proj = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]  # (N, 3, 3) off-axis projectors
    lhs, rhs = proj.sum(0), np.einsum("nij,nj->i", proj, origins)
    if prior is not None:
        pull = weight * len(dirs)
        return np.linalg.solve(lhs + pull * np.eye(3), rhs + pull * np.asarray(prior))
    if np.linalg.cond(lhs) > 1e8:
        return origins.mean(0) + dirs.mean(0)
    return np.linalg.solve(lhs, rhs)


def up_vector(c2ws: np.ndarray, method: Literal["mean", "level"] = "mean") -> np.ndarray:
    """(3,) unit "up" of a capture, cameras `c2ws` (N, 4, 4).

    "mean" (normalising a scene): the mean camera up, or the normal of the camera ring when the
    ups cancel out (a gantry whose lower views are upside down, photos at mixed rolls), signed so
    that the cameras stand above the point they look at.
    "level" (the turntable's orbit): the direction most perpendicular to every camera's right
    axis, since photos are taken with the camera level, signed like the mean up; the mean up
    when the right axes do not spread over a plane (cameras at a single azimuth).
    """
    return _level_up(c2ws) if method == "level" else _mean_up(c2ws)


def _mean_up(c2ws: np.ndarray) -> np.ndarray:
    ups = c2ws[:, :3, 1]
    mean = ups.mean(0)
    if np.linalg.norm(mean) > 0.5 or len(c2ws) < 3:
        return mean / max(np.linalg.norm(mean), 1e-12)
    centres = c2ws[:, :3, 3]
    normal = np.linalg.svd(centres - centres.mean(0))[2][-1]
    # signed so that the cameras stand above what they look at, as round an object on a table
    # (photos at mixed rolls, their EXIF lost, have no majority up: 0/90/180/270-degree beer_can
    # frames came out 130 degrees off by the ups' signs)
    return normal * _above_sign(c2ws, normal)


def _above_sign(c2ws: np.ndarray, up: np.ndarray) -> float:
    """+1 when the cameras stand above the point they look at along `up` (3,), else -1: by
    the median camera, as one placed far off (thousands of units, in 12 rolled beer_can frames)
    would outweigh the rest in a mean."""
    heights = (c2ws[:, :3, 3] - nearest_point_to_axes(c2ws)) @ up
    return 1.0 if np.median(heights) >= 0 else -1.0


def _level_up(c2ws: np.ndarray) -> np.ndarray:
    mean_up = c2ws[:, :3, 1].mean(0)
    if np.linalg.norm(mean_up) < 1e-6:
        mean_up = np.array([0.0, 0.0, 1.0])
    level, _, turned = _level_of(c2ws[:, :3, 0])
    up = level if turned > TURNED else mean_up
    up = up if up @ mean_up >= 0 else -up
    return up / np.linalg.norm(up)


LEVEL_SPREAD_DEG = 6.0  # photos whose level axes lie within this (RMS) of one level agree on up
TURNED = 0.02  # the level axes' second eigenvalue above this: they spread over a plane
QUARTER_SEEDS = 600  # directions tried as up for photos at quarter-turn rolls (about 6 deg apart)
QUARTER_REFINES = 6
MAX_STEEP_DEG = 70.0  # an up the cameras look along more steeply than this (median) is no up
QUARTER_KEEP = 0.9  # the share of photos whose level axes decide a quarter-turn up
UPSIDE_DOWN_DEG = 135.0  # a photo rolled further than this about up is upside down
UPRIGHT_SHARE = 2.0 / 3.0  # photos upright among some upside down that still tell the level
# The up axes of photos all turned sideways must turn round their level this much (about 60
# degrees of arc): upright photos over a narrow arc, misread as sideways about the arc's
# tangent, turn theirs by 0.022-0.023 (a fruit and a dtu_skull subset, 80-88 deg off);
# temple's sideways photos by 0.19-0.47 over 90 degrees or more
SIDEWAYS_TURNED = 0.1
# ... and the cameras keep their height about it within this (degrees, standard deviation), as
# a walk round does: fruit's photos at random quarters, all sideways about a wrong level 55-58
# deg off, swept 11-36 deg up and down about it; temple's 0.1-0.5
SIDEWAYS_STEADY_DEG = 5.0


def photos_level(c2ws: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit up (3,), the RMS angle in degrees between each photo's level axis and the horizontal
    that up defines), for camera-to-world matrices (N, 4, 4) with OpenGL axes.

    A photo is taken with the camera level: its right axis is horizontal, or, for a photo turned
    a quarter (a portrait held sideways whose EXIF orientation was lost), its up axis. Up is the
    direction most perpendicular to the right axes, signed like the cameras' mean up, when they
    agree on one; else (photos at mixed quarter rolls) the direction most perpendicular to each
    photo's right or up axis, whichever is nearer level, signed so that the cameras stand above
    what they look at."""
    rights = c2ws[:, :3, 0]
    up, spread, turned = _level_of(rights)
    up = _signed_by_ups(c2ws, up)
    # right axes that do not turn (all along one line: photos from one spot, or every photo
    # turned a quarter, temple's) leave any direction across that line "level": not an answer
    if len(c2ws) < 3 or (spread <= LEVEL_SPREAD_DEG and turned > TURNED
                         and _held_upright(c2ws, up)):
        return up, spread
    up, spread = _quarter_level(c2ws)
    return up * _above_sign(c2ws, up), spread


def upright_level(c2ws: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(unit up (3,), spread in degrees) by the rule of photos held upright alone, photos_level's
    first: when their right axes agree on a level that they turn round, that the cameras do not
    look along (MAX_STEEP_DEG) and that no photo is upside down about (a few among upright ones
    are left out: UPRIGHT_SHARE of the photos upright decide it); or, every photo turned
    sideways (a walk shot so, its EXIF orientation lost: temple's), when their up axes do so;
    else None.

    An up the cameras look along is level for photos at any roll. Photos of one side looking
    down at a table, most of them turned a quarter, have right axes (their true up axes) lying
    across the cameras' view: fruit's photos at quarter rolls over 60 degrees of arc agreed on
    such an up within 3.2 degrees, the cameras looking 73-87 degrees along it, 54 degrees from
    the true up (bench_verify, fruit_rolled/arc60x6@0)."""
    if len(c2ws) < 3:
        return None
    up, spread, turned = _level_of(c2ws[:, :3, 0])
    up = _signed_by_ups(c2ws, up)
    if _agreed_upright(c2ws, up, spread, turned):
        if _held_upright(c2ws, up):
            return up, spread
        # a few photos upside down (their EXIF orientation lost) among upright ones, and none
        # sideways, or the right axes would not agree: the upright ones speak for the level (two
        # of kermit's 11 photos upside down, a weak plane 64 deg off was delivered unchecked)
        upright = np.abs(rolls(c2ws, up)) <= UPSIDE_DOWN_DEG
        if upright.sum() >= max(3.0, UPRIGHT_SHARE * len(c2ws)):
            return upright_level(c2ws[upright])
    # photos all turned sideways are upright ones turned a quarter: their up axes are as level
    # (7 of temple's photos over 100 degrees, a face of the temple taken for the support 80-85
    # deg off, were delivered lying on their side); which way each turned is not known, so up
    # is signed by where the cameras stand
    up, spread, turned = _level_of(c2ws[:, :3, 1])
    up = up * _above_sign(c2ws, up)
    if (turned > SIDEWAYS_TURNED and _elevations(c2ws, up).std() <= SIDEWAYS_STEADY_DEG
            and _agreed_upright(c2ws, up, spread, turned) and _all_sideways(c2ws, up)):
        return up, spread
    return None


def _agreed_upright(c2ws: np.ndarray, up: np.ndarray, spread: float, turned: float) -> bool:
    """Whether level axes `spread` degrees off the unit `up` (3,) and turning round it by
    `turned` (_level_of) agree on it, and the cameras do not look along it."""
    return (spread <= LEVEL_SPREAD_DEG and turned > TURNED
            and _steepness(c2ws, up) <= MAX_STEEP_DEG)


def _all_sideways(c2ws: np.ndarray, up: np.ndarray) -> bool:
    """Whether every photo is turned a quarter either way about the unit `up` (3,), within 45
    degrees."""
    turns = rolls(c2ws, up)
    turns = turns[np.isfinite(turns)]
    return len(turns) > 0 and bool(np.all(np.abs(np.abs(turns) - 90.0) < 45.0))


def rolls(c2ws: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(N,) each camera's roll about the unit `up` (3,) in degrees: 0 when `up` points to the
    top of its photo, 180 upside down; NaN for a camera looking within 20 degrees along it."""
    x, y = c2ws[:, :3, 0] @ up, c2ws[:, :3, 1] @ up
    roll = np.degrees(np.arctan2(x, y))
    return np.where(np.hypot(x, y) >= np.sin(np.radians(20.0)), roll, np.nan)


def _held_upright(c2ws: np.ndarray, up: np.ndarray) -> bool:
    """Whether no photo is upside down (rolled over UPSIDE_DOWN_DEG) about the unit `up` (3,).
    Right axes agree on a level for photos upright or upside down alike; an upside-down one
    says their EXIF orientation was lost, so they may be turned by quarters too, and the
    quarter rule decides. fruit's photos at random quarters (fruit_rolled/arc60x6@120: two
    upright, one upside down, two looking 80-83 deg along the level) agreed within 3.4 deg on
    an up 59 deg off; the quarter rule found one 5 deg off. On the true poses of two draws of
    random subsets and arcs of the captures (748 and 877), no upright capture's level changed;
    on fruit's photos at random quarters the agreed level was over 15 deg off in 20 and 18
    instead of 24 and 19, the upright rule's in none instead of 4 and 3 (bench/RESULTS.md,
    stop 50)."""
    return not bool(np.any(np.abs(rolls(c2ws, up)) > UPSIDE_DOWN_DEG))


def _signed_by_ups(c2ws: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The unit `up` (3,) signed like the cameras' summed up axes."""
    return up if up @ c2ws[:, :3, 1].sum(0) >= 0 else -up


def _elevations(c2ws: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(N,) degrees each camera looks up (positive) or down along the unit `up` (3,); with
    `up` (3, S), (N, S) for each of S directions."""
    return np.degrees(np.arcsin(np.clip(-c2ws[:, :3, 2] @ up, -1.0, 1.0)))


def _steepness(c2ws: np.ndarray, up: np.ndarray) -> float:
    """The cameras' median elevation in degrees (its size) about the unit `up` (3,)."""
    return float(np.median(np.abs(_elevations(c2ws, up))))


def _level_of(axes: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(the unit direction most perpendicular to `axes` (N, 3), their RMS angle in degrees from
    the plane it defines, their second eigenvalue: how far they spread over that plane)."""
    eigvals, eigvecs = np.linalg.eigh(axes.T @ axes / len(axes))  # ascending
    spread = float(np.degrees(np.arcsin(np.sqrt(np.clip(eigvals[0], 0.0, 1.0)))))
    return eigvecs[:, 0], spread, float(eigvals[1])


def _level_axes(c2ws: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(N, 3) each camera's right or up axis, whichever is nearer perpendicular to `up`."""
    rights, ups = c2ws[:, :3, 0], c2ws[:, :3, 1]
    return np.where((np.abs(rights @ up) <= np.abs(ups @ up))[:, None], rights, ups)


def _quarter_level(c2ws: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit up (3,), sign open; spread in degrees) for photos at quarter-turn rolls: each seed
    over the sphere picks every photo's level axis, the best seeds are refined by picking and
    solving again, and of the ups the level axes agree on, the one the cameras keep the
    steadiest elevation about wins: walking round an object keeps its height, and a wrong up
    (a horizontal one can turn every photo a quarter and fit as well) sweeps the cameras'
    elevation up and down as they go round. Only the QUARTER_KEEP share of photos nearest level
    decides the fit (a photo placed 40 degrees off tilted 12 rolled beer_can frames' up)."""
    seeds = _sphere(QUARTER_SEEDS)
    rights, ups = c2ws[:, :3, 0], c2ws[:, :3, 1]
    across, along = np.abs(rights @ seeds.T), np.abs(ups @ seeds.T)  # (N, S)
    nearer = across <= along
    off = np.minimum(across, along)  # sines of each photo's level axis off level
    kept = max(3, int(np.ceil(QUARTER_KEEP * len(c2ws))))
    flatness = np.mean(np.sort(off, axis=0)[:kept] ** 2, axis=0)
    axes = np.where(nearer[..., None], rights[:, None], ups[:, None])  # (N, S, 3)
    turned = np.linalg.eigvalsh(np.einsum("nsi,nsj->sij", axes, axes) / len(c2ws))[:, 1]
    elevations = _elevations(c2ws, seeds.T)  # (N, S)
    steadiness, steepness = elevations.std(axis=0), np.median(np.abs(elevations), axis=0)
    order = sorted(range(len(seeds)),
                   key=lambda k: _rank(flatness[k], turned[k], steadiness[k], steepness[k]))
    refined = []
    for seed in seeds[order[:8]]:
        up = seed
        for _ in range(QUARTER_REFINES):
            up, spread, turned_up = _trimmed_level(_level_axes(c2ws, up), kept)
        elevation = _elevations(c2ws, up)
        refined.append((_rank(np.sin(np.radians(spread)) ** 2, turned_up, elevation.std(),
                              np.median(np.abs(elevation))), up, spread))
    _, up, spread = min(refined, key=lambda r: r[0])
    return up, float(spread)


def _trimmed_level(axes: np.ndarray, kept: int) -> tuple[np.ndarray, float, float]:
    """_level_of the `kept` of `axes` (N, 3) nearest the plane it finds (solved twice)."""
    up = _level_of(axes)[0]
    for _ in range(2):
        up, spread, turned = _level_of(axes[np.argsort(np.abs(axes @ up))[:kept]])
    return up, spread, turned


def _rank(flatness: float, turned: float, steadiness: float, steepness: float
          ) -> tuple[int, float]:
    """Sort key of an up whose level axes have eigenvalues `flatness` (off its plane) and
    `turned` (spread round it), the cameras' elevations about it varying by `steadiness`
    degrees, their median size `steepness` degrees: agreed ups first, the steadiest; then the
    flattest. An up along the cameras' own view (every camera looking straight down it) is
    level for photos at any roll, and no answer."""
    if turned <= TURNED or steepness > MAX_STEEP_DEG:
        return (2, flatness)
    agreed = flatness <= np.sin(np.radians(LEVEL_SPREAD_DEG)) ** 2
    return (0, steadiness) if agreed else (1, flatness)


def _sphere(count: int) -> np.ndarray:
    """(count, 3) unit directions spread evenly over the upper half sphere (a Fibonacci lattice):
    up's sign is settled apart."""
    k = np.arange(count) + 0.5
    z = 1.0 - k / count
    angle = np.pi * (3.0 - np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z ** 2)
    return np.stack([r * np.cos(angle), r * np.sin(angle), z], axis=1)


def agreed_level(c2ws: np.ndarray) -> np.ndarray | None:
    """The photos' up (3,) when their level axes agree on one (spread under LEVEL_SPREAD_DEG),
    they turn round it (not all at one azimuth, where any up fits) and the cameras do not look
    along it (MAX_STEEP_DEG), else None."""
    if len(c2ws) < 3:
        return None
    up, spread = photos_level(c2ws)
    # an up the cameras look along is level for photos at any roll, so agreeing on it is no
    # evidence: fruit_rolled seed 1, arc60x6@0 (6 photos over 60 deg at quarter rolls, 7.7 deg
    # median error) agreed within 5.8 deg on an up they looked 82 deg along, 134 deg from the
    # true one. A steep capture with no support plane keeps the cameras' mean up instead.
    turned = _level_of(_level_axes(c2ws, up))[2]
    return up if _agreed_upright(c2ws, up, spread, turned) else None


def box_corners(aabb) -> np.ndarray:
    """The eight corners (8, 3) of the box `aabb` ((3,) min corner, (3,) max corner)."""
    lo, hi = np.asarray(aabb, dtype=np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
