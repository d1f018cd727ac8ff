"""Typed configuration of every stage, as frozen dataclasses, and the named presets.

Each stage's module reads its own dataclass; the CLI builds them from flags and run folders store
them as JSON (`dataclasses.asdict`), so a checkpoint rebuilds itself.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SceneOptions:
    """How a posed-image source is loaded (every reader honours all of these)."""

    downscale: float = 1.0  # divide the stored resolution by this factor
    max_side: int | None = None  # or: resize so the longer side is at most this many pixels
    views: int | None = None  # keep N training views spread evenly around the object
    test_views: int | None = None  # keep K evenly spaced held-out views
    background: str = "white"  # for sources with alpha: "white", "black" or "alpha" (kept)
    normalize: bool = True  # centre, up = +z, object box scaled into [-1, 1]^3
