"""Hypotheses of a posed scene, a verifier (windowshop.photos.verify) and a choice.

Structure from motion gives one model; prepare no longer trusts it blindly. The model is
verified; while it fails, the strategies below make other hypotheses from the best one so far,
cheapest first, each verified in turn, until one passes. Once the time limit
(`PrepareOptions.verify_seconds`) is spent, no strategy that maps again (MAPS_AGAIN) starts;
those that reuse a model already made cost one verification (a second or two) and still run:

    where they look   no object stood out among the sparse points: the object is where the
                      photos look, found by its masks (the visual hull of GrabCut's outlines)
    photos' up        the upright check failed: up from the photos' level instead of the plane
    another start     the silhouettes or scale check failed (a model whose photos' outlines or
                      distances deny it, though no pair contradicts it): mapped again from the
                      strongest verified pairs in turn, as the mapper's own start grew it wrong
    pruned            the pairs or background check failed: the contradicting pairs dropped
                      from the matches (pair pruning, as Cui & Tan 2015), mapped again
    global            the same matches through pycolmap's global mapper (rotation averaging,
                      held to the phone's gravity when capture.json gives it)
    without suspects  the photos the checks blame left out, to be reshot (then photos' up
                      again, for what is left)

The first that passes is kept; when none does, the best-ranked one is kept only under
`--force` (and marked unverified), otherwise prepare fails with what was wrong and what to
reshoot. Each strategy is one function `(Search, Hypothesis, Verdict) -> Hypothesis | None`.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import pycolmap

from windowshop.config import PrepareOptions
from windowshop.errors import UserError
from windowshop.photos import sfm as sfm_
from windowshop.photos.verify import Check, Hypothesis, Verdict, background, verify
from windowshop.photos.verify.pairs import disagreements, strong_pairs


@dataclass
class Search:
    """What the strategies work with."""

    image_dir: Path
    work: Path  # scratch
    names: list[str]  # image file names, shooting order
    pixels: dict[str, object]  # image file name -> (H, W, 3) uint8
    options: PrepareOptions
    settings: sfm_.SfmSettings
    locate: Callable  # prepare.locate(sfm, pixels, options, up=...)
    check_placed: Callable  # (SfmResult) -> None, UserError when too few are placed
    deadline: float  # time.perf_counter() after which no strategy in MAPS_AGAIN starts
    evidence: Path  # the database of every verified pair, which every hypothesis is held to
    # the phone's up in each photo's camera frame by image file name (capture.json), and so
    # where a new hypothesis takes up from: "gravity" with it, else "plane"
    gravity: dict | None = None

    @property
    def up(self) -> str:
        return "gravity" if self.gravity else "plane"


@dataclass
class Tried:
    hypothesis: Hypothesis
    verdict: Verdict

    def as_report(self) -> dict:
        return {"label": self.hypothesis.label, "passed": self.verdict.passed,
                "placed": len(self.hypothesis.sfm.placed),
                "seconds": round(self.hypothesis.seconds, 2),
                "check_seconds": round(self.hypothesis.check_seconds, 2),
                "checks": self.verdict.as_report()}


@dataclass
class Choice:
    chosen: Tried
    tried: list[Tried] = field(default_factory=list)

    @property
    def verified(self) -> bool:
        return self.chosen.verdict.passed


def evaluate(search: Search, hypothesis: Hypothesis) -> Verdict:
    """Verify the poses; if they pass, find the object (prepare.locate) and verify the scene.
    A failure to find the object, or too few photos placed, is a failed check of its own."""
    start = time.perf_counter()
    hypothesis.gravity = search.gravity
    verdict = _timed(hypothesis)
    if verdict.passed:
        try:
            search.check_placed(hypothesis.sfm)
            hypothesis.found = search.locate(hypothesis.sfm, search.pixels, search.options,
                                             hypothesis.up, hypothesis.by_points)
            verdict = _timed(hypothesis)
        except UserError as err:
            verdict.checks.append(Check("object", 0.0, 1.0, str(err)))
    hypothesis.seconds += time.perf_counter() - start
    return verdict


def _timed(hypothesis: Hypothesis) -> Verdict:
    """verify(), its time added to the hypothesis's `check_seconds` (the verifier's own cost)."""
    start = time.perf_counter()
    verdict = verify(hypothesis)
    hypothesis.check_seconds += time.perf_counter() - start
    return verdict


def photos_up(search: Search, best: Hypothesis, verdict: Verdict) -> Hypothesis | None:
    """The plane's up failed against the photos' level: up from that level. (Up from the
    cameras fails only where the photos agree on no level: nothing to try.)"""
    if not any(c.name == "upright" for c in verdict.failed) or best.found.up_source == "cameras":
        return None
    return Hypothesis(f"photos' up ({best.label})", best.sfm, up="photos",
                      by_points=best.by_points)


def looked_at(search: Search, best: Hypothesis, verdict: Verdict) -> Hypothesis | None:
    """No object stood out among the sparse points (a plain object on a richly textured table
    has nearly none of its own): the object is where every photo looks, found by its masks."""
    if not any(c.name == "object" and "no object found" in c.detail for c in verdict.failed):
        return None
    return Hypothesis(f"where the photos look ({best.label})", best.sfm, up=best.up,
                      by_points=False)


def _remapped(search: Search, best: Hypothesis, label: str, database: Path, mapper: str,
              pair: tuple[int, int] | None = None) -> sfm_.SfmResult | None:
    """A new SfmResult from `database`'s matches by the incremental ("relaxed"; started from the
    images `pair` when given) or global mapper."""
    out = search.work / f"sparse_{label}"
    out.mkdir(parents=True, exist_ok=True)
    if mapper == "global":
        options = pycolmap.GlobalPipelineOptions()
        options.random_seed = search.settings.seed
        if search.gravity:  # rotation averaging held to the phone's gravity (Pan et al. 2024)
            sfm_.write_gravity(database, search.gravity, search.settings.turned)
            options.mapper.rotation_averaging.use_gravity = True
        models = pycolmap.global_mapping(database, search.image_dir, out, options)
        model = max(models.values(), key=lambda r: r.num_reg_images()) if models else None
    else:
        model = sfm_.map_once(database, search.image_dir, out, search.settings, True,
                              lambda n: None, pair=pair)
    if model is None:
        return None
    placed = sorted(im.name for im in model.images.values() if im.has_pose)
    # checked against every verified pair, not only the ones it was mapped from: a model that
    # agrees with a pruned set (a fold, once the pairs across its seam are gone) can be wrong
    return sfm_.SfmResult(reconstruction=model, placed=placed,
                          unplaced=sorted(set(search.names) - set(placed)),
                          keypoints=best.sfm.keypoints,  # the same features, matched again
                          database=search.evidence, turned=best.sfm.turned)


# the checks that say a model's geometry is wrong where its pairs need not contradict it
RESTARTED_ON = ("silhouettes", "scale")
STARTS = 2  # the strongest pairs tried as another start, at most


def strongest_pairs(database: Path) -> list[tuple[int, int, str, str]]:
    """(id, id, name, name) of the database's verified pairs, the most inliers first."""
    with pycolmap.Database.open(database) as db:
        names = {image.image_id: image.name for image in db.read_all_images()}
        ids, geometries = db.read_two_view_geometries()
    found = sorted(((len(g.inlier_matches),) + pycolmap.pair_id_to_image_pair(i)
                    for i, g in zip(ids, geometries)), reverse=True)
    return [(a, b, names[a], names[b]) for _, a, b in found]


def another_start(search: Search, best: Hypothesis, verdict: Verdict) -> Hypothesis | None:
    """The first model, started from one of the STARTS strongest pairs, that places as many
    photos as `best` (skull_up's 8 photos looking up: the mapper's own start placed 6, a
    silhouette agreement of 0.00; from the strongest pair all 8 right, median 2 degrees)."""
    if not any(c.name in RESTARTED_ON for c in verdict.failed):
        return None
    for first, second, one, other in strongest_pairs(search.evidence)[:STARTS]:
        if time.perf_counter() > search.deadline:
            break
        result = _remapped(search, best, f"start_{first}_{second}", search.evidence,
                           "incremental", pair=(first, second))
        if result is not None and len(result.placed) >= len(best.sfm.placed):
            return Hypothesis(f"started from {one} and {other}", result, up=search.up)
    return None


# the checks whose contradicting pairs _pruned_database drops
PRUNED_ON = ("pairs", "background")


def _pruned_database(search: Search, best: Hypothesis) -> Path | None:
    """A copy of the best hypothesis's database without the pairs that contradict its model:
    strong pairs whose rotation it denies, and, when it places pairs that match only on the
    object side by side (verify.background: a fold of an object printed alike), every pair
    that matches only on the object."""
    model = best.sfm.reconstruction
    conflicts = [(p.first, p.second) for p, d in
                 disagreements(model, strong_pairs(model, best.sfm.database)) if p.conflicts(d)]
    conflicts += background.fold_pairs(best)
    if not conflicts:
        return None
    copy = search.work / f"database_pruned_{len(list(search.work.glob('database_pruned_*')))}.db"
    shutil.copyfile(search.evidence, copy)
    with pycolmap.Database.open(copy) as db:
        ids = {im.name: im.image_id for im in db.read_all_images()}
        for first, second in set(conflicts):
            db.delete_two_view_geometry(ids[first], ids[second])
    return copy


def pruned(search: Search, best: Hypothesis, verdict: Verdict) -> Hypothesis | None:
    if not any(c.name in PRUNED_ON for c in verdict.failed):
        return None
    database = _pruned_database(search, best)
    result = None if database is None else _remapped(search, best, "pruned", database, "incremental")
    return None if result is None else Hypothesis("pruned", result, up=search.up)


def global_mapper(search: Search, best: Hypothesis, verdict: Verdict) -> Hypothesis | None:
    if not any(c.name in PRUNED_ON for c in verdict.failed):
        return None  # a photo whose gravity alone disagrees is left out (without_suspects)
    database = _pruned_database(search, best)
    if database is None:  # a copy all the same: the phone's gravity is written into it
        database = search.work / "database_global.db"
        shutil.copyfile(search.evidence, database)
    label = "global with gravity" if search.gravity else "global"
    result = _remapped(search, best, "global", database, "global")
    return None if result is None else Hypothesis(label, result, up=search.up)


def without_suspects(search: Search, best: Hypothesis, verdict: Verdict) -> Hypothesis | None:
    posed = set(best.sfm.placed) | set(best.sfm.guessed)
    suspects = verdict.suspects & posed
    if not suspects or suspects == posed:
        return None
    model = pycolmap.Reconstruction(best.sfm.reconstruction)
    for image in model.images.values():
        if image.name in suspects:
            model.deregister_frame(image.frame_id)
    result = replace(best.sfm, reconstruction=model,
                     placed=sorted(set(best.sfm.placed) - suspects),
                     unplaced=sorted(set(best.sfm.unplaced) | suspects),
                     guessed=[n for n in best.sfm.guessed if n not in suspects],
                     ring_method={n: how for n, how in best.sfm.ring_method.items()
                                  if n not in suspects})
    return Hypothesis(f"without suspects ({best.label})", result, up=best.up,
                      by_points=best.by_points)


# the strategies that run the mapper again (seconds each); the others reuse a model already made
MAPS_AGAIN = (another_start, pruned, global_mapper)

# photos' up again last: leaving photos out can leave the rest agreeing on a level the plane
# denies (temple's 8-photo ring without its 3 misplaced photos: the plane 44 degrees off)
STRATEGIES = (looked_at, photos_up, another_start, pruned, global_mapper, without_suspects,
              photos_up)


def choose(search: Search, first: sfm_.SfmResult) -> Choice:
    """The first hypothesis to pass the verifier (module docstring), else the best-ranked."""
    hypothesis = Hypothesis("as mapped", first, up=search.up)
    tried = [Tried(hypothesis, evaluate(search, hypothesis))]
    for strategy in STRATEGIES:
        best = max(tried, key=lambda t: t.verdict.rank())
        if best.verdict.passed:
            break
        if strategy in MAPS_AGAIN and time.perf_counter() > search.deadline:
            continue
        start = time.perf_counter()
        made = strategy(search, best.hypothesis, best.verdict)
        if made is None:
            continue
        made.seconds = time.perf_counter() - start
        tried.append(Tried(made, evaluate(search, made)))
    best = next((t for t in tried if t.verdict.passed), None)
    return Choice(best or fallback(tried), tried)


def fallback(tried: list[Tried]) -> Tried:
    """The best-ranked of hypotheses that all failed; among equals the later, which was made to
    answer the earlier's failure, so that its own failure is the one reported (where the photos
    look failing for its outlines, not the "no object found" it answered)."""
    return max(reversed(tried), key=lambda t: t.verdict.rank())


def refusal(choice: Choice) -> str:
    """What prepare says when no hypothesis passed: what was wrong and what to do."""
    failed = choice.chosen.verdict.failed
    if all(c.name == "object" for c in failed):
        return failed[0].detail  # no object found, or too few photos placed: said as it is
    found = "; ".join(c.detail for c in failed)
    advice = "; ".join(dict.fromkeys(c.advice for c in failed if c.advice))
    tried = ", ".join(t.hypothesis.label for t in choice.tried)
    return (f"the cameras could not be verified ({found})" + (f". {advice[0].upper()}{advice[1:]}"
            if advice else "") + f". Tried: {tried}. --force delivers the best of them anyway, "
            f"marked as unverified")
