"""Stencil loops with periodic neighbours vectorise (issue 25, snow_phaseField's get_rate): the row loop runs
the columns no neighbour test changes on in a copy of the body with those tests folded (codegen/cpu.py
`_column_split`), so neighbour addresses are affine: vector loads, where before LLVM could neither bound the
selected addresses for an overlap check ("cannot identify array bounds") nor vectorise the loop; an if/else
storing the same element on both sides stores it once after the IF (passes/store_select.py), where LLVM had
made one side's zero-vector store a memset it cannot predicate.
Results are checked against numpy, bit for bit where the arithmetic is exact."""

from __future__ import annotations

import re

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir import numeric
from simgrad.ir import vecmath as vm
from simgrad.runtime.jit import get_jit


def _task(kernel, args=(), k: int = 1) -> str:
    opt = str(get_jit()._optimized(kernel._instance_for(args, "").llvm_text, 0))
    return opt.split(f"define internal void @sg_kernel_task{k}(")[1].split("\n}")[0]


def _stencil(n: int, m: int, dtype):
    """snow_phaseField's first loop without its math: central differences of periodic neighbours, a zero
    vector stored where the gradient is flat, the scaled gradient elsewhere; the second loop a 9-point
    periodic Laplacian with a boundary test on the column."""
    phi = ti.field(dtype, shape=(n, m))
    g = ti.Vector.field(2, dtype, shape=(n, m))
    norm = ti.field(dtype, shape=(n, m))
    lap = ti.field(dtype, shape=(n, m))

    @ti.func
    def nb(i, j):
        im = i - 1 if i - 1 >= 0 else n - 1
        jm = j - 1 if j - 1 >= 0 else m - 1
        ip = i + 1 if i + 1 < n else 0
        jp = j + 1 if j + 1 < m else 0
        return im, jm, ip, jp

    @ti.kernel
    def grad():
        for i, j in phi:
            im, jm, ip, jp = nb(i, j)
            d = ti.Vector([(phi[ip, j] - phi[im, j]) * 0.5, (phi[i, jp] - phi[i, jm]) * 0.5])
            s = d[0] * d[0] + d[1] * d[1]
            if s < 1e-8:
                g[i, j] = ti.Vector([0.0, 0.0])
                norm[i, j] = 0.0
            else:
                norm[i, j] = s
                g[i, j] = d * (1.0 / s)

    @ti.kernel
    def laplace():
        for i, j in phi:
            im, jm, ip, jp = nb(i, j)
            v = 2 * (phi[im, j] + phi[i, jm] + phi[ip, j] + phi[i, jp]) \
                + (phi[im, jm] + phi[im, jp] + phi[ip, jm] + phi[ip, jp]) - 12 * phi[i, j]
            if 0 < j < m - 1:
                v += norm[i, j]
            lap[i, j] = v

    return phi, g, norm, lap, grad, laplace


def _numpy(p: np.ndarray, t):
    one = t(1)
    half = t(0.5)
    xp, xm = np.roll(p, -1, 0), np.roll(p, 1, 0)
    yp, ym = np.roll(p, -1, 1), np.roll(p, 1, 1)
    d0, d1 = (xp - xm) * half, (yp - ym) * half
    s = d0 * d0 + d1 * d1
    flat = s < t(1e-8)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = one / s
        g = np.where(flat[..., None], t(0), np.stack([d0 * inv, d1 * inv], -1))
    norm = np.where(flat, t(0), s)
    v = t(2) * (((xm + ym) + xp) + yp) + (((np.roll(xm, 1, 1) + np.roll(xm, -1, 1)) + np.roll(xp, 1, 1))
                                          + np.roll(xp, -1, 1)) - t(12) * p
    cols = np.arange(p.shape[1])
    v = np.where((cols > 0) & (cols < p.shape[1] - 1), v + norm, v)
    return g, norm, v, flat


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
@pytest.mark.parametrize("shape", [(64, 96), (7, 37), (5, 8), (3, 129)])
def test_periodic_stencil_matches_numpy(threads, dtype, shape):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, default_fp=dtype, offline_cache=False)
    t = np.float32 if dtype == ti.f32 else np.float64
    n, m = shape
    phi, g, norm, lap, grad, laplace = _stencil(n, m, dtype)
    rng = np.random.default_rng(n * m)
    p = rng.random((n, m)).astype(t)
    p[:, : m // 2] = 0.5  # flat columns: the zero-vector side is taken inside them, the other side elsewhere
    phi.from_numpy(p)
    grad()
    laplace()
    want_g, want_norm, want_lap, flat = _numpy(p, t)
    assert flat.any() and not flat.all()
    np.testing.assert_array_equal(g.to_numpy(), want_g)
    np.testing.assert_array_equal(norm.to_numpy(), want_norm)
    np.testing.assert_array_equal(lap.to_numpy(), want_lap)


def test_periodic_stencil_loops_vectorise_with_vector_loads():
    ti.init(arch=ti.cpu, offline_cache=False)
    _phi, _g, _norm, _lap, grad, laplace = _stencil(64, 256, ti.f64)
    for kernel in (grad, laplace):
        body = _task(kernel)
        assert re.search(r"fsub [^\n]*<\d+ x double>", body), "the loop is not vectorised"
        assert "masked.gather" not in body, "neighbour loads are gathered"
        assert "llvm.memset" not in body


def test_snow_shaped_loop_vectorises_with_its_math():
    """atan2, cos and sin on each side of the branch, as snow_phaseField's first loop: the vector loop calls
    our vector functions."""
    ti.init(arch=ti.cpu, offline_cache=False)
    n = 128
    phi = ti.field(ti.f64, shape=(n, n))
    g = ti.Vector.field(2, ti.f64, shape=(n, n))
    eps = ti.field(ti.f64, shape=(n, n))

    @ti.kernel
    def k():
        for i, j in phi:
            ip = i + 1 if i + 1 < n else 0
            jp = j + 1 if j + 1 < n else 0
            d = ti.Vector([phi[ip, j] - phi[i, j], phi[i, jp] - phi[i, j]])
            s = (d ** 2).sum()
            if s < 1e-8:
                g[i, j] = ti.Vector([0.0, 0.0])
                eps[i, j] = ti.cos(6 * ti.atan2(d[1], d[0]))
            else:
                a = ti.atan2(d[1], d[0])
                eps[i, j] = ti.cos(6 * a)
                g[i, j] = ti.sin(6 * a) * d / s

    body = _task(k)
    assert re.search(r"call [^\n]*<\d+ x double> @sg_vm_atan2_", body)
    assert "masked.gather" not in body and "llvm.memset" not in body
    # the else side's sin is a masked call: its vector function computes nothing when no lane is on
    masked = k._instance_for((), "").llvm_text.split("@sg_vm_sin_m4(")[1].split("\n}")[0]
    assert "icmp eq i4 %bits, 0" in masked
    rng = np.random.default_rng(1)
    p = rng.random((n, n))
    p[:40] = 1.0
    phi.from_numpy(p)
    k()
    d = np.stack([np.roll(p, -1, 0) - p, np.roll(p, -1, 1) - p], -1)
    s = (d ** 2).sum(-1)
    a = np.arctan2(d[..., 1], d[..., 0])
    flat = s < 1e-8
    np.testing.assert_allclose(eps.to_numpy(), np.cos(6 * a), rtol=1e-13, atol=1e-14)
    want = np.where(flat[..., None], 0.0, np.sin(6 * a)[..., None] * d / np.where(flat, 1.0, s)[..., None])
    np.testing.assert_allclose(g.to_numpy(), want, rtol=1e-12, atol=1e-13)
    assert (g.to_numpy()[flat] == 0).all() and flat.any() and not flat.all()


def test_f64_atan2_of_two_zeros_stays_in_the_vector_path(monkeypatch):
    """A flat field's gradient is (0, 0): each such lane calling libm made snow_phaseField's vector loop
    2x slower. The fast path gives C's values, signs included."""
    calls = []
    real = numeric.libm
    monkeypatch.setattr(numeric, "libm", lambda name, *a: calls.append(name) or real(name, *a))
    algo = {name: fn for _, (name, fn) in vm.FUNCTIONS64.items()}["atan2"]
    y = np.array([0.0, -0.0, 0.0, -0.0, 0.0, -0.0])
    x = np.array([0.0, 0.0, -0.0, -0.0, 1.5, -2.0])
    got = vm.evaluate(algo, y, x, f64=True)
    assert calls == []
    assert (got.view(np.int64) == np.arctan2(y, x).view(np.int64)).all()


@pytest.mark.parametrize("threads,n", [(2, 37), (2, 301), (1, 1500)])
def test_row_loop_split_runs_every_column_once(threads, n):
    """The edge columns and the middle ones, every chunk boundary (2 threads; one thread's chunks of 2**18
    iterations cut row 1291 at column 71), each column written once: a counter per element."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False)
    m = 203
    hits = ti.field(ti.i32, shape=(n, m))
    side = ti.field(ti.i32, shape=(n, m))

    @ti.kernel
    def k():
        for i, j in hits:
            hits[i, j] += 1
            jp = j + 1 if j + 1 < m else 0
            side[i, j] = jp * 2 + (1 if j >= 100 else 0) + (5 if j == 17 else 0)

    hits.fill(0)
    k()
    assert (hits.to_numpy() == 1).all()
    cols = np.arange(m)
    want = (np.where(cols + 1 < m, cols + 1, 0) * 2 + (cols >= 100) + 5 * (cols == 17)).astype(np.int32)
    np.testing.assert_array_equal(side.to_numpy(), np.broadcast_to(want, (n, m)))


@pytest.mark.parametrize("threads", [1, 2])
def test_component_chosen_by_an_argument_is_stored_without_scatters(threads):
    """`r[i, j][k] = v` with a kernel argument k is one IF per component; the element is the iteration's own
    and in bounds, so each becomes a store of a select (passes/store_select.py `_uniform_own`): plain vector
    stores, where the conditional stores were masked scatters. Components other than k keep their values."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, default_fp=ti.f64, offline_cache=False)
    n, m = 24, 80
    x = ti.field(ti.f64, shape=(n, m))
    r = ti.Vector.field(4, ti.f64, shape=(n, m))
    other = ti.Vector.field(4, ti.f64, shape=(n, m))

    @ti.kernel
    def k(c: int, f: int):
        for i, j in x:
            r[i, j][c] = x[i, j] * 2.0
            other[i, j][c] = r[i, j][c] + 1.0
            if f == 1 and i > 0:  # another iteration's element of other[3]: not the own, its store stays a branch
                other[i - 1, j][3] = 7.0

    rng = np.random.default_rng(3)
    xs = rng.random((n, m))
    x.from_numpy(xs)
    rs = rng.random((n, m, 4))
    r.from_numpy(rs)
    other.fill(-1.0)
    want = rs.copy()
    for c in (3, 0, 1, 2):
        k(c, int(c != 3))  # other[i, j][3] from its own iteration, then from the next one's
        want[..., c] = xs * 2.0
    np.testing.assert_array_equal(r.to_numpy(), want)
    o = other.to_numpy()
    np.testing.assert_array_equal(o[..., :3], np.broadcast_to(xs[..., None] * 2.0 + 1.0, (n, m, 3)))
    np.testing.assert_array_equal(o[:-1, :, 3], 7.0)
    np.testing.assert_array_equal(o[-1, :, 3], xs[-1] * 2.0 + 1.0)
    k(5, 0)  # no such component: nothing stored
    np.testing.assert_array_equal(r.to_numpy(), want)


def test_component_store_loop_has_no_scatter():
    ti.init(arch=ti.cpu, default_fp=ti.f64, offline_cache=False)
    x = ti.field(ti.f64, shape=(32, 64))
    r = ti.Vector.field(4, ti.f64, shape=(32, 64))

    @ti.kernel
    def k(c: int):
        for i, j in x:
            r[i, j][c] = x[i, j] * 2.0

    body = _task(k, (1,))
    assert re.search(r"<\d+ x double>", body)
    # LLVM may version the loop per component (a strided store is a scatter with every lane on), but no store
    # is masked by the condition
    assert not re.search(r"masked\.scatter[^\n]*<\d+ x i1> (?!splat \(i1 true\))", body)


def test_paired_stores_move_only_where_nothing_on_the_side_reads_them_after():
    """Both sides store x[i] and y[i]; the first side reads x[i] back after storing it, so that store stays
    on its side, and y's pair becomes one store after the IF."""
    ti.init(arch=ti.cpu, offline_cache=False)
    n = 100
    c = ti.field(ti.i32, shape=n)
    x = ti.field(ti.f32, shape=n)
    y = ti.field(ti.f32, shape=n)

    @ti.kernel
    def k():
        for i in c:
            if c[i] > 0:
                x[i] = 1.0
                y[i] = x[i] + 1.0
            else:
                x[i] = 2.0
                y[i] = 5.0

    cs = (np.arange(n) % 3 == 0).astype(np.int32)
    c.from_numpy(cs)
    x.fill(-1.0)
    k()
    np.testing.assert_array_equal(x.to_numpy(), np.where(cs > 0, 1.0, 2.0))
    np.testing.assert_array_equal(y.to_numpy(), np.where(cs > 0, 2.0, 5.0))
    text = k._instance_for((), "").llvm_text
    assert text.count("alloca float") >= 1  # y's local
