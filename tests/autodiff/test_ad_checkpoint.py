"""ti.ad.checkpoint: gradients of an in-place simulation under a snapshot budget equal those of the same
simulation written with time-indexed fields (float64, to rounding), for budgets 1, 2, sqrt(T) and T."""

import math

import numpy as np
import pytest
from ad_util import f64

import simgrad as ti

N, T, DT = 6, 36, 0.02


def _programs():
    x = ti.field(ti.f64, shape=N, needs_grad=True)
    v = ti.field(ti.f64, shape=N, needs_grad=True)
    f = ti.field(ti.f64, shape=N, needs_grad=True)  # a temporary: overwritten before it is read, not in state
    k = ti.field(ti.f64, shape=(), needs_grad=True)  # a parameter: read by every step
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def force():
        for i in range(N):
            f[i] = -k[None] * (2 * x[i] - x[(i + 1) % N] - x[(i + N - 1) % N]) - 0.3 * ti.sin(x[i])

    @ti.kernel
    def update():
        for i in range(N):
            v[i] = v[i] * 0.98 + DT * f[i]  # reads and overwrites the same element (owned)
            x[i] += DT * ti.sin(v[i]) + 0.1 * DT * v[i] ** 2  # reads the new v[i]: nonlinear

    @ti.kernel
    def compute_loss():
        for i in range(N):
            loss[None] += (i + 1) * x[i] ** 2 + v[i] ** 2

    X = ti.field(ti.f64, shape=(T + 1, N), needs_grad=True)
    V = ti.field(ti.f64, shape=(T + 1, N), needs_grad=True)
    F = ti.field(ti.f64, shape=(T, N), needs_grad=True)
    ref_loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def ref_step(t: ti.i32):
        for i in range(N):
            F[t, i] = -k[None] * (2 * X[t, i] - X[t, (i + 1) % N] - X[t, (i + N - 1) % N]) - 0.3 * ti.sin(X[t, i])
            V[t + 1, i] = V[t, i] * 0.98 + DT * F[t, i]
            X[t + 1, i] = X[t, i] + DT * ti.sin(V[t + 1, i]) + 0.1 * DT * V[t + 1, i] ** 2

    @ti.kernel
    def ref_compute_loss():
        for i in range(N):
            ref_loss[None] += (i + 1) * X[T, i] ** 2 + V[T, i] ** 2

    def step(t):
        force()
        update()

    return locals()


@pytest.mark.parametrize("budget", [1, 2, int(math.sqrt(T)), T])
def test_checkpointed_gradients_equal_the_time_indexed_reference(budget):
    f64()
    p = _programs()
    rng = np.random.default_rng(1)
    x0, v0 = rng.random(N), rng.random(N) - 0.5
    p["k"][None] = 2.0
    p["X"].from_numpy(np.vstack([x0, np.zeros((T, N))]))
    p["V"].from_numpy(np.vstack([v0, np.zeros((T, N))]))
    with ti.ad.Tape(loss=p["ref_loss"]):
        for t in range(T):
            p["ref_step"](t)
        p["ref_compute_loss"]()
    want = p["X"].grad.to_numpy()[0], p["V"].grad.to_numpy()[0], p["k"].grad[None]
    final = p["X"].to_numpy()[T]

    x, v = p["x"], p["v"]
    x.from_numpy(x0)
    v.from_numpy(v0)
    with ti.ad.Tape(loss=p["loss"]):
        cp = ti.ad.checkpoint(p["step"], T, state=[x, v], budget=budget)
        p["compute_loss"]()
    assert p["loss"][None] == pytest.approx(p["ref_loss"][None], rel=1e-13)
    np.testing.assert_allclose(x.grad.to_numpy(), want[0], rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(v.grad.to_numpy(), want[1], rtol=1e-11, atol=1e-13)
    assert p["k"].grad[None] == pytest.approx(want[2], rel=1e-11)
    assert cp.peak <= budget
    np.testing.assert_allclose(x.to_numpy(), final, rtol=1e-14)  # the final state is back after backward
    # the binomial schedule: with K snapshots no step runs more than t extra times, C(K + t, t) >= T
    t_max = next(t for t in range(T + 1) if math.comb(budget + t, t) >= T)
    assert cp.recomputed <= t_max * T


def test_in_place_updates_that_are_not_owned_are_refused():
    f64()
    u = ti.field(ti.f64, shape=4, needs_grad=True)
    w = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def neighbour():
        for i in range(4):
            u[i] = u[(i + 1) % 4] * 0.5

    @ti.kernel
    def after_a_branch():
        for i in range(4):
            if u[i] > 0.5:
                w[i] = w[i] * 2.0
            u[i] += ti.sin(w[i])

    @ti.kernel
    def total():
        for i in range(4):
            loss[None] += u[i] + w[i]

    for kernel, what in ((neighbour, "other than the one it overwrites"), (after_a_branch, "after overwriting")):
        u.from_numpy(np.linspace(0.2, 0.9, 4))
        with pytest.raises(ti.GradientError, match=what):
            with ti.ad.Tape(loss=loss):
                ti.ad.checkpoint(lambda t, k=kernel: k(), 3, state=[u, w], budget=1)
                total()


def test_checkpoint_outside_a_tape_is_refused():
    x = ti.field(ti.f32, shape=2, needs_grad=True)
    with pytest.raises(ti.SimgradError, match="inside `with ti.ad.Tape"):
        ti.ad.checkpoint(lambda t: None, 3, state=[x])
