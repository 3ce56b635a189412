"""examples/mass_spring_checkpoint.py at reduced size: the loss goes down, and its checkpointed gradient equals
central differences of the whole in-place simulation (float64)."""

import os
import sys

import numpy as np

import simgrad as ti

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_trains_with_checkpointing(tmp_path, monkeypatch):
    import mass_spring_checkpoint

    monkeypatch.setattr(sys, "argv", ["x", "--iters", "8", "--steps", "300", "--budget", "4", "--out",
                                      str(tmp_path)])
    losses = mass_spring_checkpoint.main()
    # the controller's optimisation is chaotic at this learning rate: float atomics summed in another
    # order on two threads change the 4th digit of the first gradient and the later losses by far more,
    # so the test asks that training got below the start, not where the last iteration landed
    assert min(losses[1:]) < 0.8 * losses[0]
    assert (tmp_path / "loss.png").exists()


def test_checkpointed_gradient_matches_finite_differences():
    import mass_spring_checkpoint

    ti.init(arch=ti.cpu, default_fp=ti.f64)
    sim = mass_spring_checkpoint.build(n=6, real=ti.f64)
    steps = 120
    rng = np.random.default_rng(0)
    v0 = rng.standard_normal((6, 2)) * 0.3

    def loss_at(p):
        sim["init_v"].from_numpy(p)
        sim["start"]()
        for t in range(steps):
            sim["step"](t)
        sim["compute_loss"]()
        return sim["loss"][None]

    sim["init_v"].from_numpy(v0)
    with ti.ad.Tape(loss=sim["loss"]):
        sim["start"]()
        ti.ad.checkpoint(sim["step"], steps, state=[sim["x"], sim["v"]], budget=3)
        sim["compute_loss"]()
    grad = sim["init_v"].grad.to_numpy()
    d = rng.standard_normal((6, 2))
    eps = 1e-6
    fd = (loss_at(v0 + eps * d) - loss_at(v0 - eps * d)) / (2 * eps)
    assert abs(np.sum(grad * d) - fd) <= 1e-6 * max(1.0, abs(fd))
