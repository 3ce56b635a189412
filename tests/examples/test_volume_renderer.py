"""The volume renderer at reduced size: it runs headless, its loss goes down and it writes its pictures."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_volume_renderer_loss_decreases(tmp_path):
    import volume_renderer

    losses, _ = volume_renderer.train(iters=5, out=str(tmp_path), res=32, d=16, n_views=3, samples=24)
    assert losses[-1] < 0.5 * losses[0]
    for name in ("loss.png", "views_iter0001.png", "views_iter0005.png", "density_projection.png",
                 "volume_renderer.gif"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_reference_density_is_inside_the_box():
    import volume_renderer

    rho = volume_renderer.reference_density(16)
    assert rho.shape == (16, 16, 16) and rho.min() >= 0 and rho.max() > 1
    assert np.all(rho[0] == 0) and np.all(rho[-1] == 0)  # nothing on the faces of the box
