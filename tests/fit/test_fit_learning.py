"""A small NeRF learns lego_tiny: held-out PSNR well above predicting the mean colour."""


import pytest

from windowshop.config import FitConfig
from windowshop.fit.evaluate import held_out_views, mean_color_psnr
from windowshop.fit.trainer import fit
from windowshop.model import model_config
from shared_data import DATA

LEGO_TINY = DATA / "lego_tiny.npz"


@pytest.mark.skipif(not LEGO_TINY.is_file(), reason="shared test data not present")
def test_small_nerf_beats_the_mean_colour_by_5_db(tmp_path):
    from windowshop.scene import load_scene

    scene = load_scene(LEGO_TINY)
    floor = mean_color_psnr(scene.split("train"), held_out_views(scene), scene.background)
    # the tiny preset shrunk to train in ~20 s on 2 quiet cores; a higher learning rate makes up
    # for the short schedule, and softplus densities cannot die at "nothing anywhere", which this
    # dark-background scene pulls a ReLU field towards (it did for 1 seed in 7). Measured on 2
    # threads: +8.0 to +8.6 dB over 7 seeds.
    config = model_config("nerf", "tiny", depth=4, width=64, n_coarse=32, lr=5e-3, lr_final=5e-4,
                          density_activation="softplus")
    metrics = fit(scene, "nerf", config, FitConfig(iters=800, batch_rays=512, seed=0), tmp_path, "cpu",
                  show_progress=False)
    assert metrics["test_views"] == 6
    assert metrics["psnr"] >= floor + 5.0, (metrics["psnr"], floor)
