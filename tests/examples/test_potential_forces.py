"""examples/potential_forces.py at reduced size: autodiff forces equal the analytic ones, U goes down."""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples"))


def test_potential_forces(tmp_path):
    import potential_forces

    losses, _ = potential_forces.train(iters=30, out=str(tmp_path), n=128, sim_steps=40)
    assert potential_forces.train.force_error < 1e-4
    assert potential_forces.train.force_error_final < 1e-3
    # gradient descent and the damped simulation both lower the energy
    assert losses[-1] < losses[0] - 0.01 * abs(losses[0])
    sim_u = potential_forces.train.sim_energies
    assert sim_u[-1] < sim_u[0]
    for name in ("loss.png", "minimum.png", "simulation.gif", "simulation_0000.png"):
        assert (tmp_path / name).exists(), name
