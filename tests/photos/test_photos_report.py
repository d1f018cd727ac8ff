"""The prepare report's advice for photos that could not be placed."""

from __future__ import annotations

from windowshop.photos.report import RING_NOTES, reshoot, summary_lines


def test_reshoot_names_the_placed_neighbours_in_order():
    shown = ["a.jpg", "b.jpg", "c.jpg", "d.jpg", "e.jpg"]
    advice = reshoot(shown, ["c.jpg", "d.jpg", "a.jpg"])
    assert list(advice) == ["a.jpg", "c.jpg", "d.jpg"]
    assert "between it and b.jpg" in advice["a.jpg"]
    assert "between it and b.jpg and e.jpg" in advice["c.jpg"]
    assert "between it and b.jpg and e.jpg" in advice["d.jpg"]
    assert "between" not in reshoot(["a.jpg"], ["a.jpg"])["a.jpg"]


def test_reshoot_tells_photos_that_match_no_placed_one_what_they_may_be():
    shown = ["a.jpg", "b.jpg", "c.jpg", "x.jpg", "y.jpg", "z.jpg"]
    advice = reshoot(shown, ["b.jpg", "x.jpg", "y.jpg", "z.jpg"],
                     {"x.jpg": ["y.jpg"], "y.jpg": ["x.jpg"], "z.jpg": []})
    assert "between it and a.jpg and c.jpg" in advice["b.jpg"]  # linked to the placed: as before
    assert advice["x.jpg"].startswith("it matches only y.jpg, none of the placed photos")
    assert "something else" in advice["z.jpg"]
    assert "no details with any other photo" in advice["z.jpg"]


def test_summary_lists_the_advice():
    report = {"placed": 7, "used": 8, "reprojection_error_px": 0.5, "dropped": {},
              "unplaced": ["c.jpg"], "reshoot": {"c.jpg": "retake it"}, "masks": "none"}
    lines = summary_lines(report)
    assert "could not place: c.jpg" in lines[1] and lines[2].strip() == "c.jpg: retake it"


def test_summary_names_the_photos_the_ring_placed():
    report = {"placed": 6, "used": 8, "reprojection_error_px": 0.5, "dropped": {},
              "unplaced": [], "estimated_from_ring": {"c.jpg": RING_NOTES["paired"],
                                                      "f.jpg": RING_NOTES["guessed"]},
              "reshoot": {"c.jpg": "retake it", "f.jpg": "retake it too"}, "masks": "none"}
    lines = summary_lines(report)
    assert "not measured: c.jpg, f.jpg" in lines[1]
    assert [line.strip() for line in lines[2:]] == ["c.jpg: retake it", "f.jpg: retake it too"]


def test_a_refusal_names_the_light_when_most_photos_are_dark():
    import pytest

    from windowshop.errors import UserError
    from windowshop.media import Refused
    from windowshop.photos.prepare import _light_blamed

    dark = [f"IMG_{i}.jpg" for i in range(8)]
    with pytest.raises(UserError) as refused:
        with _light_blamed(dark, 10):
            raise UserError("only 3 of 10 photos could be placed")
    assert str(refused.value).startswith("only 3 of 10 photos could be placed\n")
    assert "8 of 10 photos are dark: more light" in str(refused.value)
    with pytest.raises(UserError) as refused:
        with _light_blamed(dark[:3], 10):  # a few dark photos are not the likeliest cause
            raise UserError("only 3 of 10 photos could be placed")
    assert str(refused.value) == "only 3 of 10 photos could be placed"
    with pytest.raises(Refused):  # an error of its own kind passes as it is
        with _light_blamed(dark, 10):
            raise Refused("too_big", "the upload is too large")
