"""billiards at a reduced iteration count: it runs headless, its loss goes down, its pictures exist."""

import os
import sys

import numpy as np

import simgrad as ti

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_billiards_loss_decreases(tmp_path):
    import billiards

    losses, _ = billiards.train(iters=10, out=str(tmp_path), steps=1024)
    assert losses[-1] < 0.7 * losses[0]
    assert (tmp_path / "loss.png").exists()
    assert (tmp_path / "optimized.gif").exists()
    assert any(p.name.startswith("initial_") for p in tmp_path.iterdir())
    assert not (tmp_path / "frames").exists()  # the GIF's frame PNGs are cleaned up


def test_billiards_toi_gradient_matches_finite_differences():
    """With the time-of-impact correction the final position is smooth in the cue velocity, so the
    reverse-mode gradient agrees with a central difference."""
    import billiards

    table = billiards.build(steps=1024)
    table.rack()

    def loss(vx):
        table.cue_x[None] = [0.1, 0.5]
        table.cue_v[None] = [vx, 0.0]
        table.forward()
        return float(table.loss[None])

    table.cue_x[None] = [0.1, 0.5]
    table.cue_v[None] = [0.3, 0.0]
    with ti.ad.Tape(loss=table.loss):
        table.forward()
    g = float(table.cue_v.grad[None][0])
    h = 1e-3
    fd = (loss(0.3 + h) - loss(0.3 - h)) / (2 * h)
    assert np.isclose(g, fd, rtol=0.1, atol=1e-3), (g, fd)
