"""rigid_body at reduced size: it runs headless, its loss goes down, its pictures exist."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


@pytest.mark.parametrize("robot", [0, 1])
def test_rigid_body_loss_decreases(tmp_path, robot):
    import rigid_body

    losses, _ = rigid_body.train(iters=5, out=str(tmp_path), robot=robot, steps=1024, frames=robot == 0)
    # the loss is minus the distance moved right: it must move at least 3 cm further than at the start
    assert losses[-1] < losses[0] - 0.03, losses
    assert (tmp_path / "loss.png").exists()
    if robot == 0:
        assert (tmp_path / "optimized.gif").exists()
        assert any(p.name.startswith("optimized_") and p.suffix == ".png" for p in tmp_path.iterdir())
