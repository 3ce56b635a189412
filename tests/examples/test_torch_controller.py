"""examples/torch_controller.py at reduced size: the torch MLP, trained through the bridged simulation with
Adam, makes the robot move right (the loss goes down) and the loss plot is written."""

import os
import sys

import pytest

pytest.importorskip("torch")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_the_controller_learns_to_move_right(tmp_path):
    import torch_controller

    losses, _ = torch_controller.train(iters=8, out=str(tmp_path), steps=120, hidden=16)
    assert losses[-1] < losses[0] - 0.003
    assert (tmp_path / "loss.png").exists()
    assert any(p.name.startswith("frame_") for p in tmp_path.iterdir())
