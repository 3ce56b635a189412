"""In-place kernels under a plain Tape: a kernel that reads what it overwrites (`x[i] += x[i] ** 2`,
`v[i] = v[i] * d + dt * f[i]`) is differentiated correctly (the Tape keeps the values from before each such
launch and rolls them back before its adjoint), checked against finite differences and against the
time-indexed formulation in float64. `x[i] += x[i] ** 2` used to give a silently wrong gradient."""

import numpy as np
import pytest
from ad_util import f64, fd_grad, rel_err

import simgrad as ti


def test_an_update_that_reads_its_own_element_has_the_right_gradient():
    f64()
    x = ti.field(ti.f64, shape=3, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def square_in():
        for i in range(3):
            x[i] += x[i] ** 2

    @ti.kernel
    def total():
        for i in range(3):
            loss[None] += ti.sin(x[i])

    x0 = np.array([0.5, 1.0, 2.0])

    def value():
        loss[None] = 0
        square_in()
        total()
        v = loss[None]
        x.from_numpy(x0)
        return v

    x.from_numpy(x0)
    with ti.ad.Tape(loss=loss):
        square_in()
        total()
    np.testing.assert_allclose(x.to_numpy(), x0 + x0**2)  # the final values are back after backward
    got = x.grad.to_numpy()
    x.from_numpy(x0)
    assert rel_err(got, fd_grad(value, x)) < 1e-7
    with pytest.raises(ti.GradientError, match="overwrites an element of field 'x' that it read"):
        square_in.grad()  # alone, its adjoint would replay the read with the new value: refused


def test_in_place_steps_on_a_tape_equal_the_time_indexed_program():
    f64()
    n, steps, dt = 5, 7, 0.05
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    v = ti.field(ti.f64, shape=n, needs_grad=True)
    f = ti.field(ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    X = ti.field(ti.f64, shape=(steps + 1, n), needs_grad=True)
    V = ti.field(ti.f64, shape=(steps + 1, n), needs_grad=True)
    ref = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def force():
        for i in range(n):
            f[i] = -ti.sin(x[i]) - 0.5 * (x[i] - x[(i + 1) % n])

    @ti.kernel
    def update():
        for i in range(n):
            v[i] = v[i] * 0.9 + dt * f[i]
            x[i] += dt * v[i] * v[i]

    @ti.kernel
    def update_own_force():  # in place, reading nothing a later launch overwrites
        for i in range(n):
            v[i] = v[i] * 0.9 - dt * ti.sin(x[i])
            x[i] += dt * v[i] * v[i]

    @ti.kernel
    def compute_loss():
        for i in range(n):
            loss[None] += x[i] ** 2 + v[i]

    @ti.kernel
    def ref_step(t: ti.i32):
        for i in range(n):
            g = -ti.sin(X[t, i])
            V[t + 1, i] = V[t, i] * 0.9 + dt * g
            X[t + 1, i] = X[t, i] + dt * V[t + 1, i] * V[t + 1, i]

    @ti.kernel
    def ref_loss():
        for i in range(n):
            ref[None] += X[steps, i] ** 2 + V[steps, i]

    rng = np.random.default_rng(2)
    x0, v0 = rng.random(n), rng.random(n)
    X.from_numpy(np.vstack([x0, np.zeros((steps, n))]))
    V.from_numpy(np.vstack([v0, np.zeros((steps, n))]))
    with ti.ad.Tape(loss=ref):
        for t in range(steps):
            ref_step(t)
        ref_loss()
    want_x, want_v = X.grad.to_numpy()[0], V.grad.to_numpy()[0]  # the next Tape clears every gradient
    x.from_numpy(x0)
    v.from_numpy(v0)
    with ti.ad.Tape(loss=loss):
        for _ in range(steps):
            update_own_force()
        compute_loss()
    assert loss[None] == pytest.approx(ref[None], rel=1e-13)
    np.testing.assert_allclose(x.grad.to_numpy(), want_x, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(v.grad.to_numpy(), want_v, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(x.to_numpy(), X.to_numpy()[steps], rtol=1e-13)

    # with the forces as a temporary that the next step overwrites, a plain Tape cannot replay update's
    # inputs: refused (ti.ad.checkpoint recomputes them: tests/autodiff/test_ad_checkpoint.py)
    x.from_numpy(x0)
    v.from_numpy(v0)
    with pytest.raises(ti.TaichiAssertionError, match="ti.ad.checkpoint"):
        with ti.ad.Tape(loss=loss):
            for _ in range(steps):
                force()
                update()
            compute_loss()


def test_in_place_kernels_that_are_not_owned_are_refused_on_a_tape():
    u = ti.field(ti.f32, shape=4, needs_grad=True)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)

    @ti.kernel
    def smooth():
        for i in range(4):
            u[i] = 0.5 * (u[(i + 1) % 4] + u[i])

    @ti.kernel
    def total():
        for i in range(4):
            loss[None] += u[i]

    with pytest.raises(ti.GradientError, match="other than the one it overwrites"):
        with ti.ad.Tape(loss=loss):
            smooth()
            total()
