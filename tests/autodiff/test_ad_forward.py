"""Forward mode (ti.ad.FwdMode, needs_dual / lazy_dual): Jacobian-vector products checked against central
differences in float64, and against reverse mode through the identity u . (J v) == (J^T u) . v."""

import numpy as np
import pytest
from ad_util import f64

import simgrad as ti


def _kernels(n):
    """(name, forward-only setup) pairs: kernels y = f(x) exercising loops, branches, locals and atomics."""
    x = ti.field(ti.f64, shape=n, needs_grad=True, needs_dual=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True, needs_dual=True)

    @ti.func
    def soft(a):
        return a / (1.0 + ti.abs(a))

    @ti.kernel
    def control_flow():
        for i in range(n):
            acc = 0.0
            k = 0
            while k < 6:
                k += 1
                if k == 2:
                    continue
                if acc > 3.0:
                    break
                acc += soft(x[(i + k) % n]) * ti.sin(x[i]) + x[i] ** 2
            y[i] = acc if x[i] > 0.3 else ti.exp(-acc)

    @ti.kernel
    def vectors_and_atomics():
        for i in range(n):
            v = ti.Vector([x[i], x[(i + 1) % n], 0.5 * x[(i + 2) % n]])
            m = ti.Matrix([[x[i], 0.2], [x[(i + 1) % n], 1.0 + x[i] ** 2]])
            u, s, vt = ti.svd(m)
            y[i] += v.norm() * v.normalized()[1] + ti.max(x[i], 0.5) * ti.min(x[i], 0.4) + s[0, 0]
            y[(i + 3) % n] += ti.atan2(x[i], 1.5) * ti.sqrt(x[i] + 2.0) + u[0, 1] * vt[1, 0]
            sym = m + m.transpose()
            w, q = ti.sym_eig(sym)
            ev, _vecs = ti.eig(sym)
            rot, _stretch = ti.polar_decompose(m)
            y[(i + 1) % n] += w[0] * q[0, 1] + 0.5 * ev[1, 0] + rot[1, 0]

    return x, y, {"control_flow": control_flow, "vectors_and_atomics": vectors_and_atomics}


@pytest.mark.parametrize("name", ["control_flow", "vectors_and_atomics"])
def test_forward_mode_matches_finite_differences_and_reverse_mode(name):
    f64()
    n = 6
    x, y, kernels = _kernels(n)
    ti.root.lazy_dual()
    kernel = kernels[name]
    rng = np.random.default_rng(3)
    x0 = rng.uniform(0.1, 0.9, n)
    v = rng.normal(size=n)
    u = rng.normal(size=n)

    def run(at):
        x.from_numpy(at)
        y.fill(0)
        kernel()
        return y.to_numpy()

    run(x0)
    with ti.ad.FwdMode(loss=y, param=x, seed=list(v)):
        y.fill(0)
        kernel()
    jv = y.dual.to_numpy()
    eps = 1e-6
    fd = (run(x0 + eps * v) - run(x0 - eps * v)) / (2 * eps)
    np.testing.assert_allclose(jv, fd, rtol=1e-6, atol=1e-8)
    assert np.abs(x.dual.to_numpy()).max() == 0  # the seed is cleared on exit

    run(x0)
    x.grad.fill(0)
    y.grad.from_numpy(u)
    kernel.grad()
    jtu = x.grad.to_numpy()
    assert np.dot(u, jv) == pytest.approx(np.dot(jtu, v), rel=1e-10)


def test_forward_mode_through_kernels_in_sequence_and_local_min():
    f64()
    a = ti.field(ti.f64, shape=(), needs_dual=True)
    mid = ti.field(ti.f64, shape=4, needs_dual=True)
    out = ti.field(ti.f64, shape=(), needs_dual=True)

    @ti.kernel
    def first():
        for i in range(4):
            mid[i] = a[None] * (i + 1)

    @ti.kernel
    def second():
        lo = 100.0
        for i in range(4):
            lo = ti.min(lo, ti.cos(mid[i]))  # an atomic min on a local
        out[None] = lo

    a[None] = 0.7
    with ti.ad.FwdMode(loss=out, param=a):
        first()
        second()
    k = int(np.argmin(np.cos(0.7 * np.arange(1, 5))))
    assert out.dual[None] == pytest.approx(-np.sin(0.7 * (k + 1)) * (k + 1), rel=1e-12)


def test_forward_mode_errors_are_loud():
    x = ti.field(ti.f32, shape=3)
    y = ti.field(ti.f32, shape=3, needs_dual=True)
    with pytest.raises(ti.SimgradError, match="has no dual"):
        with ti.ad.FwdMode(loss=y, param=x, seed=[1, 0, 0]):
            pass
    z = ti.field(ti.f32, shape=3, needs_dual=True)
    with pytest.raises(ti.SimgradError, match="seed"):
        with ti.ad.FwdMode(loss=y, param=z):
            pass

    @ti.kernel
    def biggest():
        for i in range(3):
            ti.atomic_max(y[0], z[i])

    with pytest.raises(ti.GradientError, match="atomic 'max'"):
        with ti.ad.FwdMode(loss=y, param=z, seed=[1, 0, 0]):
            biggest()
    with pytest.raises(ti.SimgradError, match="has no dual"):
        ti.field(ti.f32, shape=2).dual[0]


def test_hessian_vector_products_by_forward_mode_over_the_adjoint():
    """Inside FwdMode, kernel.grad() carries tangents: x.grad.dual = H v, checked against central
    differences of the gradient, for a kernel whose adjoint replays without a tape and for one whose adjoint
    keeps loop-carried values on the tape (each value pushed with its tangent)."""
    f64()
    n = 5
    x = ti.field(ti.f64, shape=n, needs_grad=True, needs_dual=True)
    E = ti.field(ti.f64, shape=(), needs_grad=True, needs_dual=True)

    @ti.kernel
    def energy():
        for i in range(n):
            d = x[(i + 1) % n] - x[i]
            E[None] += ti.sin(x[i]) * x[(i + 1) % n] ** 2 + 0.5 * x[i] ** 3 + ti.exp(-d * d)

    @ti.kernel
    def taped():  # a loop carrying a local value: its adjoint keeps values on the tape
        for i in range(n):
            s = 0.0
            for _k in range(3):
                s = ti.sin(s + x[i] * x[(i + 1) % n])
            E[None] += s * s

    def gradient(kernel):
        E.fill(0)
        kernel()
        x.grad.fill(0)
        E.grad[None] = 1
        kernel.grad()
        return x.grad.to_numpy()

    def grad_at(kernel, p):
        x.from_numpy(p)
        return gradient(kernel)

    rng = np.random.default_rng(5)
    x0, v = rng.random(n), rng.standard_normal(n)
    eps = 1e-6
    for kernel in (energy, taped):
        x.from_numpy(x0)
        with ti.ad.FwdMode(loss=x.grad, param=x, seed=list(v)):
            gradient(kernel)
        hv = x.grad.dual.to_numpy()
        fd = (grad_at(kernel, x0 + eps * v) - grad_at(kernel, x0 - eps * v)) / (2 * eps)
        np.testing.assert_allclose(hv, fd, rtol=1e-6, atol=1e-8)
    assert any(inst.ir.uses_tape for inst in taped._caches["gradfwd"].values())  # the tape path is covered
