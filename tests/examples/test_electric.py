"""examples/electric.py at reduced size: the ball learns to follow the goal."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_electric_fixed_path_loss_decreases(tmp_path):
    import electric

    losses, _ = electric.train(iters=30, out=str(tmp_path), steps=256, seg_size=128, n_hidden=16, lr=0.3, tasks=1,
                               n_val=0, frame_every=16)
    assert losses[-1] < 0.5 * losses[0]
    assert (tmp_path / "loss.png").exists()
    assert (tmp_path / "trained.gif").exists()
    assert (tmp_path / "initial.gif").exists()
    assert any(p.name.startswith("trained_") and p.suffix == ".png" for p in tmp_path.iterdir())


def test_electric_random_paths_generalise(tmp_path):
    import electric

    # the paper's setting: a new path every iteration; held-out paths measure the controller
    electric.train(iters=40, out=str(tmp_path), steps=128, seg_size=64, n_hidden=16, lr=0.1, tasks=0, n_val=4,
                   frames=False)
    assert electric.train.val_after < electric.train.val_before
    assert (tmp_path / "loss.png").exists()
