"""Whole small simulations differentiated through many kernel launches, against finite differences of
the loss: a 3-particle mass-spring system and a tiny 2-D MLS-MPM (examples/diffmpm_simple.py)."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
from ad_util import f64, fd_grad, rel_err

import simgrad as ti
from simgrad.testing import check_grads

EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "..", "examples")


def _mass_spring(steps=120, dt=0.01, real=ti.f64):
    n = 3
    pairs = [(0, 1), (1, 2), (0, 2)]
    x0 = ti.Vector.field(2, dtype=real, shape=n, needs_grad=True)
    v0 = ti.Vector.field(2, dtype=real, shape=n, needs_grad=True)
    k = ti.field(real, shape=len(pairs), needs_grad=True)
    rest = ti.field(real, shape=len(pairs))
    sa = ti.field(ti.i32, shape=len(pairs))
    sb = ti.field(ti.i32, shape=len(pairs))
    x = ti.Vector.field(2, dtype=real, shape=(steps, n), needs_grad=True)
    v = ti.Vector.field(2, dtype=real, shape=(steps, n), needs_grad=True)
    loss = ti.field(real, shape=(), needs_grad=True)
    target = ti.Vector([0.9, 0.4])

    @ti.kernel
    def init():
        for i in range(n):
            x[0, i] = x0[i]
            v[0, i] = v0[i]

    @ti.kernel
    def step(t: ti.i32):
        for i in range(n):
            force = ti.Vector([0.0, -0.5])
            for s in range(len(pairs)):
                a, b = sa[s], sb[s]
                if a == i or b == i:
                    j = b if a == i else a
                    d = x[t - 1, i] - x[t - 1, j]
                    length = d.norm()
                    force += -k[s] * (length - rest[s]) * d / length
            v[t, i] = v[t - 1, i] * 0.995 + dt * force  # semi-implicit Euler
            x[t, i] = x[t - 1, i] + dt * v[t, i]

    @ti.kernel
    def compute_loss():
        for i in range(n):
            d = x[steps - 1, i] - target
            loss[None] += d.dot(d) * (i + 1)
        loss[None] += 0.1 * (x[steps // 2, 1] - x[steps // 2, 2]).norm()

    x0.from_numpy(np.array([[0.2, 0.3], [0.5, 0.35], [0.35, 0.6]]))
    v0.from_numpy(np.array([[0.3, 0.1], [-0.2, 0.4], [0.1, -0.3]]))
    k.from_numpy(np.array([20.0, 30.0, 25.0]))
    rest.from_numpy(np.array([0.25, 0.3, 0.28]))
    sa.from_numpy(np.array([p[0] for p in pairs], dtype=np.int32))
    sb.from_numpy(np.array([p[1] for p in pairs], dtype=np.int32))

    def forward():
        loss[None] = 0
        init()
        for t in range(1, steps):
            step(t)
        compute_loss()

    return forward, loss, x0, v0, k


def test_mass_spring_gradients_match_finite_differences():
    f64()
    forward, loss, x0, v0, k = _mass_spring()
    with ti.ad.Tape(loss=loss):
        forward()
    grads = {name: fld.grad.to_numpy().copy() for name, fld in (("x0", x0), ("v0", v0), ("k", k))}
    for g in grads.values():
        assert np.all(np.isfinite(g)) and np.any(g)

    def loss_value():
        forward()
        return loss[None]

    for name, fld in (("x0", x0), ("v0", v0), ("k", k)):
        fd = fd_grad(loss_value, fld, eps=1e-6)
        err = rel_err(grads[name], fd, floor=1e-6)
        assert err < 1e-6, f"d loss / d {name}: relative error {err:.2e}"


def test_mass_spring_check_grads_all_inputs_at_once():
    f64()
    forward, loss, x0, v0, k = _mass_spring(steps=100)
    check_grads(forward, [x0, v0, k], [loss], rtol=1e-6, atol=1e-10, directions=2)


def test_mass_spring_f32_gradient_close_to_f64():
    f64()
    forward, loss, x0, v0, k = _mass_spring(steps=100)
    with ti.ad.Tape(loss=loss):
        forward()
    ref = k.grad.to_numpy().copy()
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    forward32, loss32, x032, v032, k32 = _mass_spring(steps=100, real=ti.f32)
    with ti.ad.Tape(loss=loss32):
        forward32()
    assert rel_err(k32.grad.to_numpy(), ref, floor=1e-3) < 1e-2


@pytest.fixture
def diffmpm():
    sys.path.insert(0, os.path.abspath(EXAMPLES))
    try:
        import diffmpm_simple
    finally:
        sys.path.pop(0)
    saved = diffmpm_simple.real
    diffmpm_simple.real = ti.f64
    yield diffmpm_simple
    diffmpm_simple.real = saved


def test_tiny_mpm_init_v_gradient_matches_finite_differences(diffmpm):
    f64()
    sim = diffmpm.build(n_side=4, n_grid=16, steps=24)
    sim.reset()
    sim.init_v[None] = [0.3, -0.2]
    with ti.ad.Tape(loss=sim.loss):
        sim.forward()
    g = sim.init_v.grad.to_numpy().copy()
    assert np.all(np.isfinite(g)) and np.any(g)

    def loss_value():
        sim.forward()
        return sim.loss[None]

    fd = fd_grad(loss_value, sim.init_v, eps=1e-6)
    err = rel_err(g, fd, floor=1e-8)
    assert err < 1e-5, f"MPM d loss / d init_v: AD {g} vs FD {fd} (relative error {err:.2e})"
