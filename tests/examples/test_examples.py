"""Each example at reduced size: it runs headless and its loss goes down."""

import os
import sys

import pytest

import simgrad as ti

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_mass_spring_simple_loss_decreases(tmp_path):
    import mass_spring_simple

    losses, _ = mass_spring_simple.train(iters=8, out=str(tmp_path), steps=200)
    assert losses[-1] < 0.5 * losses[0]
    assert (tmp_path / "loss.png").exists()


def test_diffmpm_simple_loss_decreases(tmp_path):
    import diffmpm_simple

    losses, _ = diffmpm_simple.train(iters=4, out=str(tmp_path), n_side=12, n_grid=32, steps=64, lr=20.0)
    assert losses[-1] < losses[0]
    assert (tmp_path / "loss.png").exists()
    assert (tmp_path / "trajectory.png").exists()


@pytest.mark.parametrize("script", ["laplace"])
def test_seed_examples_run(script):
    import laplace

    assert laplace.main() < 1e-5


def test_fractal_writes_png(tmp_path, monkeypatch):
    import fractal

    monkeypatch.setattr(sys, "argv", ["fractal.py", "--out", str(tmp_path)])
    fractal.main()
    assert (tmp_path / "fractal_0000.png").stat().st_size > 1000
    ti.reset()
