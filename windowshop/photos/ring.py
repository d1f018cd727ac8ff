"""The known-turntable prior: photos taken on a ring around one object, in shooting order.

When structure from motion places some of a few photos but not all, the placed cameras tell the
ring: its centre (the point their optical axes pass nearest), its axis (the normal of the plane
of their centres, pointing along their up), its radius and its height above the centre. A photo
left over is then put on the ring between its placed neighbours in shooting order, looking at
the centre: a guess, not a measurement, that the report names as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from windowshop.scene.cameras import look_at, nearest_point_to_axes

MIN_PLACED = 3  # cameras needed to fit a ring
# Shooting order closes the ring (the last photo is followed by the first) when the step across
# the wrap is within this factor of the typical step between placed neighbours.
CLOSED_FACTOR = 2.0


@dataclass(frozen=True)
class Ring:
    """A circle of cameras around an object: all (3,) vectors in the cameras' world frame."""

    centre: np.ndarray  # the point the cameras look at
    axis: np.ndarray  # unit normal of the ring's plane, along the cameras' up
    radius: float  # distance of the cameras from the axis
    height: float  # offset of the ring's plane from the centre, along the axis

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors spanning the ring's plane, (e1, e2, axis) right-handed."""
        seed = np.eye(3)[int(np.argmin(np.abs(self.axis)))]
        e1 = np.cross(self.axis, seed)
        e1 /= np.linalg.norm(e1)
        return e1, np.cross(self.axis, e1)

    def azimuth(self, points: np.ndarray) -> np.ndarray:
        """(N,) angles (radians) of `points` (N, 3) about the axis."""
        e1, e2 = self.basis()
        offsets = points - self.centre
        return np.arctan2(offsets @ e2, offsets @ e1)

    def camera(self, azimuth: float) -> np.ndarray:
        """OpenGL camera-to-world (4, 4) on the ring at `azimuth`, looking at the centre, upright
        (its up in the plane of the axis and its view)."""
        e1, e2 = self.basis()
        eye = (self.centre + self.height * self.axis
               + self.radius * (np.cos(azimuth) * e1 + np.sin(azimuth) * e2))
        return look_at(eye, self.centre, self.axis)


def fit_ring(c2ws: np.ndarray) -> Ring:
    """The ring through cameras `c2ws` (N, 4, 4) OpenGL camera-to-world, N >= MIN_PLACED."""
    if len(c2ws) < MIN_PLACED:
        raise ValueError(f"a ring needs {MIN_PLACED} cameras, got {len(c2ws)}")
    centres = c2ws[:, :3, 3]
    centre = nearest_point_to_axes(c2ws, prior=centres.mean(0))
    axis = np.linalg.svd(centres - centres.mean(0))[2][2]
    if axis @ c2ws[:, :3, 1].sum(0) < 0:  # along the cameras' up (OpenGL +y)
        axis = -axis
    offsets = centres - centre
    along = offsets @ axis
    radius = float(np.linalg.norm(offsets - along[:, None] * axis, axis=1).mean())
    return Ring(centre=centre, axis=axis, radius=radius, height=float(along.mean()))


def _wrapped(angle: np.ndarray | float) -> np.ndarray | float:
    """`angle` in [0, 2 pi)."""
    return np.mod(angle, 2 * np.pi)


def fill_azimuths(count: int, known: dict[int, float]) -> dict[int, float]:
    """Azimuths (radians) of the photos 0..count-1 (shooting order) missing from `known`
    (index -> azimuth, at least 2): between their known neighbours in proportion to the order,
    across the wrap when the order closes the ring, else beyond the ends by the typical step."""
    order = sorted(known)
    steps = np.array([known[b] - known[a] for a, b in zip(order, order[1:])])
    sense = 1.0 if np.sin(steps).sum() >= 0 else -1.0  # which way round the photos go
    spans = [_wrapped(sense * s) for s in steps]
    per_photo = float(np.median([s / (b - a) for s, a, b in zip(spans, order, order[1:])]))
    wrap_gap = count - order[-1] + order[0]
    wrap_span = _wrapped(sense * (known[order[0]] - known[order[-1]]))
    closed = per_photo / CLOSED_FACTOR <= wrap_span / wrap_gap <= per_photo * CLOSED_FACTOR
    # each known photo with the next one round, and the angle between them
    links = [(a, b, b - a, span) for a, b, span in zip(order, order[1:], spans)]
    if closed:
        links.append((order[-1], order[0] + count, wrap_gap, wrap_span))
    filled = {}
    for i in range(count):
        if i in known:
            continue
        for start, stop, gap, span in links:
            for j in (i, i + count):
                if start < j < stop:
                    filled[i] = known[start] + sense * span * (j - start) / gap
        if i not in filled:  # beyond the ends of an open arc
            end = order[0] if i < order[0] else order[-1]
            filled[i] = known[end] + sense * per_photo * (i - end)
    return filled


def guess_poses(c2ws: dict[int, np.ndarray], count: int) -> dict[int, np.ndarray]:
    """OpenGL camera-to-world (4, 4) guesses for the photos 0..count-1 (shooting order) missing
    from `c2ws` (index -> the placed cameras' c2w, at least MIN_PLACED)."""
    ring = fit_ring(np.stack(list(c2ws.values())))
    azimuths = ring.azimuth(np.stack([c[:3, 3] for c in c2ws.values()]))
    known = dict(zip(c2ws, azimuths))
    return {i: ring.camera(a) for i, a in fill_azimuths(count, known).items()}
