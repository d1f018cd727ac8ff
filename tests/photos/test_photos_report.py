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
