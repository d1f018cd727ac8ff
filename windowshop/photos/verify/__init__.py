"""The verifier: scores a posed, masked scene (a hypothesis) before any training, with no learned
weights, so that a wrong reconstruction is retried or refused instead of trained and delivered.

Each check is one function `check(hypothesis) -> Check | None` (None: it does not apply, e.g.
no masks to compare) in a module of its own:

    pairs        the model's relative rotations against each strongly matched pair's own (the
                 two-view geometry its matches give): a folded or misplaced photo contradicts
                 the pairs that tie it to its true neighbours (Heinly et al. 2014)
    silhouettes  each mask against the visual hull the *other* views carve (silhouette
                 coherence, Hernandez et al. 2007): a wrong pose carves the object away
    upright      the support plane's normal against the photos' own up (photos are taken
                 level, so their right axes are horizontal)
    viewpoints   distinct photos, far apart in shooting order, stacked on one viewpoint (a few
                 photos of an object whose sides look alike, folded)

`verify` runs them all; windowshop.photos.hypotheses decides what to try next.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # prepare imports this package; only the type is needed here
    from windowshop.photos.prepare import Located
    from windowshop.photos.sfm import SfmResult


@dataclass(frozen=True)
class Check:
    """One check's verdict on a hypothesis."""

    name: str
    score: float  # higher is better
    threshold: float  # the score a hypothesis needs
    detail: str  # what was measured, in words, for the report
    advice: str = ""  # what to reshoot or change when it fails
    suspects: tuple[str, ...] = ()  # image names the check blames
    passed: bool | None = None  # None: score >= threshold decides

    def __post_init__(self):
        if self.passed is None:
            object.__setattr__(self, "passed", self.score >= self.threshold)

    def as_report(self) -> dict:
        return {"name": self.name, "passed": self.passed, "score": round(self.score, 3),
                "threshold": self.threshold, "detail": self.detail,
                "suspects": sorted(self.suspects)}


@dataclass
class Hypothesis:
    """A posed scene to verify: the cameras and sparse model of one strategy, and (after
    prepare.locate) the object found in it."""

    label: str  # the strategy that made it
    sfm: SfmResult
    found: Located | None = None
    seconds: float = 0.0  # what making and checking it cost (finding its object included) ...
    check_seconds: float = 0.0  # ... of which the checks themselves
    up: str = "plane"  # how prepare.locate finds up: "plane" or "photos" ...
    by_points: bool = True  # ... and the object: by its sparse points, or where the cameras look


@dataclass
class Verdict:
    checks: list[Check] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def failed(self) -> list[Check]:
        return [c for c in self.checks if not c.passed]

    @property
    def suspects(self) -> set[str]:
        return {name for c in self.failed for name in c.suspects}

    def rank(self) -> tuple[int, int, int]:
        """Sort key among hypotheses: fewer failed checks, then more checks made (one that got
        as far as its object beats one that did not), then fewer photos blamed. Scores are in
        different units (shares, degrees), so their margins are not added."""
        return (-len(self.failed), len(self.checks), -len(self.suspects))

    def as_report(self) -> list[dict]:
        return [c.as_report() for c in self.checks]


def verify(hypothesis: Hypothesis) -> Verdict:
    """Every check that applies to `hypothesis`."""
    from windowshop.photos.verify import pairs, silhouettes, upright, viewpoints

    checks = (check(hypothesis) for check in (pairs.check, silhouettes.check, upright.check,
                                               viewpoints.check))
    return Verdict([c for c in checks if c is not None])
