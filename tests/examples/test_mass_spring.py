"""examples/mass_spring.py at reduced size: the robot learns to move right, and test mode runs it longer."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


@pytest.mark.parametrize("robot_id", [1, 3])
def test_mass_spring_robot_learns_to_move(tmp_path, robot_id):
    import mass_spring

    losses, _ = mass_spring.train(iters=6, out=str(tmp_path), robot_id=robot_id, steps=200, n_hidden=8,
                                     frame_every=25)
    # the loss is -(distance moved): it must go down by a visible amount
    assert losses[-1] < losses[0] - 0.01
    assert (tmp_path / "loss.png").exists()
    assert (tmp_path / f"robot{robot_id}_trained.gif").exists()
    assert any(p.name.startswith(f"robot{robot_id}_trained_") and p.suffix == ".png" for p in tmp_path.iterdir())

    # test mode: reload the saved controller and run twice as long without optimising
    dist = mass_spring.test(str(tmp_path), robot_id=robot_id, steps=200, n_hidden=8, frame_every=25)
    assert dist > -losses[0]
    assert (tmp_path / f"robot{robot_id}_test.gif").exists()


def test_mass_spring_gradient_matches_finite_difference(monkeypatch):
    """The Tape's gradient through contacts and springs equals a central difference (in f64)."""
    import mass_spring

    ti = mass_spring.ti
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    monkeypatch.setattr(mass_spring, "real", ti.f64)
    sim = mass_spring.build(robot_id=2, steps=60, n_hidden=4)
    sim.setup()
    sim.init_weights(1)
    with ti.ad.Tape(loss=sim.loss):
        sim.forward()
    grads = {"bias2": sim.bias2.grad.to_numpy(), "weights1": sim.weights1.grad.to_numpy()}
    for name, index in (("bias2", (0,)), ("bias2", (1,)), ("weights1", (2, 3))):
        field = getattr(sim, name)
        base = field.to_numpy()
        vals = []
        for h in (1e-5, -1e-5):
            p = base.copy()
            p[index] += h
            field.from_numpy(p)
            sim.loss[None] = 0
            sim.forward()
            vals.append(float(sim.loss[None]))
        field.from_numpy(base)
        fd = (vals[0] - vals[1]) / 2e-5
        g = float(grads[name][index])
        assert abs(g) > 1e-6
        assert abs(fd - g) <= 1e-4 * abs(g) + 1e-9, (name, index, g, fd)
