"""examples/liquid.py at reduced size: the robot under a slab of liquid walks further after a few iterations."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_liquid_robot_loss_decreases(tmp_path):
    import liquid

    timings = {}
    losses, seconds = liquid.train(
        iters=3, out=str(tmp_path), n_grid=24, steps=100, per_cell=1.5, lr=30.0, frames=3, gif_frames=6, timings=timings
    )
    assert len(losses) == 3 and all(abs(v) < 1 for v in losses)
    assert losses[-1] < losses[0] - 1e-4  # the robot moves right: the loss is -(x-displacement)
    assert timings["n_particles"] > 0
    assert (tmp_path / "loss.png").exists()
    assert (tmp_path / "liquid.gif").stat().st_size > 1000
    assert len(list(tmp_path.glob("iter0002_*.png"))) == 3
