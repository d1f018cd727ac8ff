"""A picture of a scene: camera frusta around the object box, and a strip of thumbnails."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from windowshop.scene.cameras import box_corners
from windowshop.scene.types import Camera, Scene

SPLIT_COLOURS = {"train": "tab:blue", "val": "tab:orange", "test": "tab:red"}
THUMBNAILS = 8


def frustum_lines(camera: Camera, depth: float) -> list[np.ndarray]:
    """Line segments (2, 3) drawing `camera` as a pyramid `depth` deep (world units)."""
    corners = np.array([[0, 0], [camera.width, 0], [camera.width, camera.height], [0, camera.height]],
                       dtype=np.float64)
    local = np.stack([(corners[:, 0] - camera.cx) / camera.fx, -(corners[:, 1] - camera.cy) / camera.fy,
                      -np.ones(4)], -1) * depth
    world = local @ camera.c2w[:3, :3].T + camera.center
    lines = [np.stack([camera.center, w]) for w in world]
    lines += [np.stack([world[i], world[(i + 1) % 4]]) for i in range(4)]
    return lines


def box_lines(aabb: np.ndarray) -> list[np.ndarray]:
    """The 12 edges (2, 3) of an axis-aligned box (2, 3)."""
    corners = box_corners(aabb)
    return [np.stack([corners[a], corners[b]]) for a in range(8) for b in range(a + 1, 8)
            if np.sum(corners[a] != corners[b]) == 1]


def plot_scene(scene: Scene, out: Path) -> Path:
    """Draw `scene` (normalised frame) into the PNG `out`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(10, 8))
    ax = fig.add_axes([0.0, 0.22, 1.0, 0.76], projection="3d")
    for line in box_lines(np.asarray(scene.aabb)):
        ax.plot(*line.T, color="k", lw=1)
    depth = 0.15 * float(np.median([np.linalg.norm(v.camera.center) for v in scene.views]))
    for view in scene.views:
        for line in frustum_lines(view.camera, depth):
            ax.plot(*line.T, color=SPLIT_COLOURS.get(view.split, "gray"), lw=0.6)
    centres = np.stack([v.camera.center for v in scene.views])
    reach = max(np.abs(centres).max(), 1.0) * 1.1
    ax.set(xlim=(-reach, reach), ylim=(-reach, reach), zlim=(-reach, reach), xlabel="x", ylabel="y",
           zlabel="z", title=f"{scene.format}: {scene.source} ({len(scene.views)} views)")
    ax.set_box_aspect((1, 1, 1))
    picks = np.unique(np.linspace(0, len(scene.views) - 1, min(THUMBNAILS, len(scene.views))).astype(int))
    for k, index in enumerate(picks):
        thumb = fig.add_axes([k / THUMBNAILS, 0.01, 1.0 / THUMBNAILS, 0.19])
        thumb.imshow(np.clip(scene.views[index].image, 0, 1))
        thumb.set_title(scene.views[index].split, fontsize=7)
        thumb.axis("off")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
