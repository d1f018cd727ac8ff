"""After the fit: the photos held out of training (every 8th) against the model's renders of
them, each camera first refined against the model (windowshop.fit.pose_refine, at most 3
degrees), so that a held-out camera's small pose error is not counted against the model. A model that reproduces the photos it never saw this poorly learned wrong
cameras or a wrong outline (a cloud, a leaning object with the wall behind it baked in).
"""

from __future__ import annotations

from windowshop.photos.verify.types import Check

# Held-out PSNR after refinement (the fit's "psnr_refined") a delivered capture needs. Measured
# (bench/RESULTS.md, "Right or refused"): the shared captures' right fits at the defaults reach
# 19-31 dB (kermit, fruit, dtu_skull, beer_can), the statue that leaned in issue 34 13.3 dB
MIN_PSNR = 15.0
ADVICE = ("the model does not reproduce the photos it was not trained on, so some cameras or "
          "the object's outline are probably wrong: photograph the object alone on a plain "
          "surface, walking all round it in small steps")


def check(metrics: dict) -> Check | None:
    """The held-out check of a fit's `metrics` (windowshop.fit.evaluate), None without any."""
    value = metrics.get("psnr_refined")
    if value is None:
        return None
    detail = (f"the {metrics.get('test_views', 0)} held-out photos are reproduced at {value:.1f} dB "
              f"({metrics.get('psnr', value):.1f} dB before refining their cameras)")
    return Check("held-out", value, MIN_PSNR, detail, ADVICE)
