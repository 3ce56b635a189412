"""examples/diffmpm3d.py at reduced size: the 3-D soft robot walks further after a few iterations."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_diffmpm3d_robot_loss_decreases(tmp_path):
    import diffmpm3d

    timings = {}
    losses, seconds = diffmpm3d.train(
        iters=3, out=str(tmp_path), n_grid=24, steps=100, per_cell=1.5, frames=3, gif_frames=6, timings=timings
    )
    assert len(losses) == 3 and all(abs(v) < 1 for v in losses)
    assert losses[-1] < losses[0] - 1e-4  # the robot moves right: the loss is -(x-displacement)
    assert seconds > 0 and timings["n_particles"] > 0
    assert (tmp_path / "loss.png").exists()
    assert (tmp_path / "diffmpm3d.gif").stat().st_size > 1000
    assert len(list(tmp_path.glob("iter0002_*.png"))) == 3
