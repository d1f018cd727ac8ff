"""What the verifier works on and says: a hypothesis of the scene, each check's verdict, and
the verdict of them all."""


from __future__ import annotations

from dataclasses import dataclass, field

from windowshop.photos.located import Located
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
    up: str = "plane"  # how prepare.locate finds up: "plane", "gravity" or "photos" ...
    by_points: bool = True  # ... and the object: by its sparse points, or where the cameras look
    # the phone's up in each photo's camera frame by image file name (capture.json), or None
    gravity: dict | None = None


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
