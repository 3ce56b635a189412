"""The smoke example at reduced size: it runs headless, its loss goes down and it writes its pictures."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_smoke_loss_decreases(tmp_path):
    import smoke

    losses, _ = smoke.train(iters=4, out=str(tmp_path), n=32, steps=16, jacobi=3)
    assert losses[-1] < 0.8 * losses[0]
    for name in ("loss.png", "target.png", "ink_initial.png", "ink_final_iter0004.png", "smoke.gif"):
        assert (tmp_path / name).stat().st_size > 0, name
