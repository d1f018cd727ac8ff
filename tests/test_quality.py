"""The capture's quality report: camera angles, empty arcs, advice and the coverage plot."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from windowshop.quality import advice, camera_angles, coverage_plot, empty_arcs, quality_report
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera, Scene, View


def ring(azimuths_deg, elevation_deg=20.0, distance=3.0) -> list[Camera]:
    cams = []
    for az in np.radians(azimuths_deg):
        el = np.radians(elevation_deg)
        eye = distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        cams.append(Camera(fx=50, fy=50, cx=32, cy=32, width=64, height=64,
                           c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))))
    return cams


def test_angles_are_measured_from_the_first_photo_about_up():
    az, el = camera_angles(ring([30, 120, 300], elevation_deg=40), np.zeros(3))
    assert az == pytest.approx([0, 90, 270], abs=1e-6) and el == pytest.approx([40, 40, 40], abs=1e-6)


def test_empty_arcs_wrap_around_the_circle():
    assert empty_arcs(np.array([0, 30, 60, 90, 200, 230])) == [(90.0, 200.0), (230.0, 0.0)]
    assert empty_arcs(np.arange(0, 360, 30)) == []  # photos every 30°: nothing to walk again


def test_advice_names_the_photos_and_the_side_to_reshoot():
    tips = advice({"unplaced": ["IMG_7.jpg"], "dropped": {"IMG_3.jpg": "blurred (sharpness 2% of "
                   "the median)", "IMG_4.jpg": "duplicate of IMG_2.jpg", "IMG_9.jpg": "too blurred"},
                   "empty_arcs": [(120.0, 200.0)], "placed": 8, "elevations": [5.0, 6.0],
                   "masks": "segmented", "held_out_psnr": 25.0})
    assert "photo IMG_7.jpg could not be placed" in tips[0]
    assert "photos IMG_3.jpg and IMG_9.jpg are blurred" in tips[1]
    assert "no photos between 120° and 200° around the object: walk that side again" in tips
    assert any("only 8 photos" in t for t in tips) and any("higher up" in t for t in tips)
    assert advice({"placed": 30, "elevations": [10, 35], "masks": "segmented", "empty_arcs": [],
                   "held_out_psnr": 28.0}) == []  # a good capture gets no advice


def test_a_still_phone_is_told_to_turn_the_object_not_to_walk():
    tips = advice({"unplaced": ["IMG_7.jpg"], "empty_arcs": [(120.0, 200.0)], "placed": 30,
                   "elevations": [10, 35], "masks": "still", "held_out_psnr": 28.0})
    assert tips == ["photo IMG_7.jpg could not be placed: retake so each photo shares most of its "
                    "view with the photo before it (turn the object in smaller steps)",
                    "no photos between 120° and 200° around the object: turn that side of it "
                    "to the phone"]


def test_a_held_phones_photo_left_unsteadied_is_told_apart_from_one_that_shared_too_little():
    tips = advice({"unplaced": ["IMG_7.jpg", "IMG_9.jpg"], "swung": ["IMG_9.jpg"],
                   "empty_arcs": [], "placed": 30, "elevations": [10, 35], "masks": "still",
                   "held_out_psnr": 28.0})
    assert tips == ["photo IMG_7.jpg could not be placed: retake so each photo shares most of its "
                    "view with the photo before it (turn the object in smaller steps)",
                    "photo IMG_9.jpg could not be placed: the phone moved too far for it while "
                    "the others kept the room still: retake holding the phone where it was for "
                    "the others"]


def test_report_of_a_one_sided_capture(tmp_path):
    cams = ring(np.linspace(0, 140, 8))
    views = [View(c, np.zeros((64, 64, 3), np.float32), "train", f"v{i}") for i, c in enumerate(cams)]
    scene = Scene(views=views, format="hand", source=tmp_path, aabb=np.array([[-1.0] * 3, [1.0] * 3]),
                  near=1, far=5)
    render = {"swing": True, "covered_span_degrees": 140.0}
    report = quality_report(scene, {"psnr": 18.5, "test_views": 1}, render, None)
    assert report["empty_arcs"] == [(140.0, 0.0)] and report["placed"] == 8
    assert "swings across that arc" in report["note"]
    assert any("140° and 0°" in t for t in report["advice"])
    assert any("18.5 dB" in t for t in report["advice"])
    plot = coverage_plot(tmp_path / "coverage.png", report)
    assert Image.open(plot).size[0] > 100


def test_trust_names_the_arc_and_heights_the_photos_cover_without_the_doubted_ones():
    from windowshop.quality import trust

    names = [f"p{i}.jpg" for i in range(8)]
    azimuths = np.array([0, 20, 40, 60, 80, 100, 120, 250.0])
    elevations = np.array([10, 12, 14, 16, 18, 20, 22, 60.0])
    part = trust(names, azimuths, elevations, {"p7.jpg": "pairs"}, True)
    assert part["level"] == "part" and part["arc"] == [0.0, 120.0] and part["arc_degrees"] == 120.0
    assert part["elevations"] == [10.0, 22.0]  # p7, high up and doubted, does not widen them
    assert "trust the side the photos show, 0° to 120°" in part["summary"]
    assert "p7.jpg (pairs)" in part["summary"]
    round_ = trust(names, np.arange(0, 360, 45.0), elevations, {}, True)
    assert round_["level"] == "whole" and round_["summary"].startswith("checked: trust it all round")
    forced = trust(names, np.arange(0, 360, 45.0), elevations, {}, False)
    assert forced["level"] == "none" and forced["summary"].startswith("UNVERIFIED")
    given = trust(names, azimuths, elevations, {}, None)
    assert not given["checked"] and given["summary"].startswith("not checked")


def test_dark_photos_are_named_or_the_light_blamed():
    from windowshop.quality import advice

    one = advice({"dark": ["IMG_2.jpg"], "photos": 12, "placed": 12})
    assert any(t.startswith("photo IMG_2.jpg is dark: more light") for t in one)
    most = advice({"dark": [f"IMG_{i}.jpg" for i in range(7)], "photos": 12, "placed": 12})
    assert any(t.startswith("the photos are dark: more light") for t in most)
    assert not any("dark" in t for t in advice({"dark": [], "photos": 12, "placed": 12}))


def test_a_photo_alone_across_an_empty_arc_is_left_out_of_the_trusted_arc():
    from windowshop.quality import advice, empty_arcs, trust

    # a user's ten photos of fruit, seven placed: a run from 325 deg round to 150 deg, and one
    # photo at 253 deg, 103 and 72 deg from its neighbours
    names = [f"p{i}.jpg" for i in range(7)]
    azimuths = np.array([0.0, 26.4, 54.1, 105.1, 149.8, 252.6, 325.0])
    elevations = np.array([20, 22, 24, 26, 28, 70, 30.0])
    part = trust(names, azimuths, elevations, {}, True)
    assert part["arc"] == [325.0, 149.8] and part["arc_degrees"] == 184.8
    assert part["elevations"] == [20.0, 30.0]  # p5, alone and high up, does not widen them
    # the advice asks to walk both empty arcs; neither lies inside the arc the report trusts
    tips = advice({"empty_arcs": empty_arcs(azimuths), "placed": 7})
    assert any("150° and 253°" in t for t in tips) and any("253° and 325°" in t for t in tips)
    inside = (np.array([150.0, 253.0, 300.0]) - 325.0) % 360.0 < part["arc_degrees"]
    assert not inside.any()


def test_report_doubts_the_photos_the_chosen_hypothesis_and_the_held_out_check_blamed(tmp_path):
    from windowshop.photos.verify.heldout import MIN_PSNR

    cams = ring(np.arange(0, 360, 36.0))
    views = [View(c, np.zeros((64, 64, 3), np.float32), "test" if i == 9 else "train", f"dir/v{i}.jpg")
             for i, c in enumerate(cams)]
    scene = Scene(views=views, format="hand", source=tmp_path, aabb=np.array([[-1.0] * 3, [1.0] * 3]),
                  near=1, far=5)
    blame = {"name": "silhouettes", "passed": True, "suspects": ["v3.jpg"]}
    prepared = {"used": 10, "placed": 10, "verification": {
        "verified": True, "chosen": "as mapped",
        "tried": [{"label": "pruned", "checks": [{**blame, "suspects": ["v5.jpg"]}]},
                  {"label": "as mapped", "checks": [blame]}]}}
    metrics = {"psnr": 20.0, "test_views": 1,
               "per_view": [{"name": "dir/v9.jpg", "psnr": 12.0, "psnr_refined": MIN_PSNR - 1}]}
    report = quality_report(scene, metrics, {"covered_span_degrees": 324.0}, prepared)
    assert report["trust"]["doubtful"] == {"v3.jpg": "silhouettes", "v9.jpg": "held-out"}
    assert report["trust"]["level"] == "part" and report["trust"]["checked"]
    # by the user's own file names where prepare worked under others ("v 3.png" as v_3, v3)
    prepared["views"] = [{"name": f"v{i}", "photo": f"in/v {i}.png", "shown": f"v {i}.png"}
                         for i in range(10)]
    report = quality_report(scene, metrics, {"covered_span_degrees": 324.0}, prepared)
    assert report["trust"]["doubtful"] == {"v 3.png": "silhouettes", "v 9.png": "held-out"}
    assert "doubted: v 3.png (silhouettes), v 9.png (held-out)" in report["trust"]["summary"]


def test_report_tells_which_unplaced_photos_steadying_left_out(tmp_path):
    from windowshop.photos.report import SWUNG, reshoot

    views = [View(c, np.zeros((64, 64, 3), np.float32), "train", f"v{i}.jpg")
             for i, c in enumerate(ring(np.arange(0, 360, 36.0)))]
    scene = Scene(views=views, format="hand", source=tmp_path,
                  aabb=np.array([[-1.0] * 3, [1.0] * 3]), near=1, far=5)
    shown = [f"v{i}.jpg" for i in range(12)]
    prepared = {"used": 12, "placed": 10, "unplaced": ["v10.jpg", "v11.jpg"],
                "reshoot": reshoot(shown, ["v10.jpg", "v11.jpg"]) | {"v11.jpg": SWUNG},
                "steadied": {"box": [4, 3, 60, 61], "left_out": ["v11"], "moves": {}}}
    report = quality_report(scene, {"psnr": 25.0, "test_views": 1}, {}, prepared)
    assert report["swung"] == ["v11.jpg"]
    assert sum("moved too far" in tip for tip in advice(report)) == 1
