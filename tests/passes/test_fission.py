"""Loop fission of scatters (passes/fission.py): a parallel loop that computes and then scatters runs W iterations'
computing part, then their scatters. At one thread every result must be bit for bit the one of the unsplit loop
(ti.init(fission_lanes=0)), with fast_math off (under fast_math a vectorised part 0 calls codegen/vecmath.py's
exp/log, not libm's): P2G-shaped loops in 2-D and 3-D, particle counts no multiple of W, branches on particle
data, stores to the particle's own element (conditional ones too), field and ndarray scatters, f32 and f64.
Gradients of a split adjoint against central differences; loops that must not be split are left alone; part 0 is
vector code in the optimised LLVM IR."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.ops import Op
from simgrad.runtime.jit import get_jit


def _both(build, threads=1, widths=(0, 8, -1), **init):
    """build() defines fields and kernels, runs them and returns (arrays, kernel, args); run unsplit and split
    (W = 8, the host's width): the arrays must agree bit for bit. Returns the last run's (arrays, kernel, args)."""
    init.setdefault("fast_math", False)
    out = []
    for width in widths:
        ti.init(arch=ti.cpu, cpu_max_num_threads=threads, fission_lanes=width, **init)
        arrays, kernel, args = build()
        out.append(([np.ascontiguousarray(a) for a in arrays], kernel, args))
    for run in out[1:]:
        for a, b in zip(out[0][0], run[0]):
            assert a.dtype == b.dtype and a.shape == b.shape
            np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8))
    return out[-1]


def _split_loops(kernel, args, suffix=""):
    return [s for s in kernel._instance_for(args, suffix).ir.body.stmts
            if s.op is Op.RANGE_FOR and s.attrs.get("fission")]


def _p2g_2d(n=1001, n_grid=32, dtype=ti.f32, seed=0):
    """mpm99's P2G: F update, SVD, plasticity by material, a conditional store of F[p], 3x3 scatters."""
    dx, inv_dx, dt = 1 / n_grid, float(n_grid), 1e-4
    p_vol = (dx * 0.5) ** 2
    p_mass = p_vol
    mu_0, lambda_0 = 416.6, 277.7
    x = ti.Vector.field(2, dtype, shape=n)
    v = ti.Vector.field(2, dtype, shape=n)
    C = ti.Matrix.field(2, 2, dtype, shape=n)
    F = ti.Matrix.field(2, 2, dtype, shape=n)
    material = ti.field(ti.i32, shape=n)
    Jp = ti.field(dtype, shape=n)
    grid_v = ti.Vector.field(2, dtype, shape=(n_grid, n_grid))
    grid_m = ti.field(dtype, shape=(n_grid, n_grid))

    @ti.kernel
    def p2g():
        for p in x:
            base = (x[p] * inv_dx - 0.5).cast(int)
            fx = x[p] * inv_dx - base.cast(dtype)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            F[p] = (ti.Matrix.identity(dtype, 2) + dt * C[p]) @ F[p]
            h = ti.exp(10 * (1.0 - Jp[p]))
            if material[p] == 1:
                h = 0.3
            mu, la = mu_0 * h, lambda_0 * h
            if material[p] == 0:
                mu = 0.0
            U, sig, V = ti.svd(F[p], dtype)
            J = 1.0
            for d in ti.static(range(2)):
                new_sig = ti.max(sig[d, d], 1e-6)
                if material[p] == 2:
                    new_sig = ti.min(ti.max(sig[d, d], 1 - 2.5e-2), 1 + 4.5e-3)
                Jp[p] *= sig[d, d] / new_sig
                sig[d, d] = new_sig
                J *= new_sig
            if material[p] == 0:
                F[p] = ti.Matrix.identity(dtype, 2) * ti.sqrt(J)
            elif material[p] == 2:
                F[p] = U @ sig @ V.transpose()
            stress = 2 * mu * (F[p] - U @ V.transpose()) @ F[p].transpose() \
                + ti.Matrix.identity(dtype, 2) * la * J * (J - 1)
            affine = (-dt * p_vol * 4 * inv_dx * inv_dx) * stress + p_mass * C[p]
            for i, j in ti.static(ti.ndrange(3, 3)):
                offset = ti.Vector([i, j])
                dpos = (offset.cast(dtype) - fx) * dx
                weight = w[i][0] * w[j][1]
                grid_v[base + offset] += weight * (p_mass * v[p] + affine @ dpos)
                grid_m[base + offset] += weight * p_mass

    rng = np.random.default_rng(seed)
    t = np.float32 if dtype == ti.f32 else np.float64
    x.from_numpy((rng.random((n, 2)) * 0.6 + 0.2).astype(t))
    v.from_numpy((rng.random((n, 2)) - 0.5).astype(t))
    C.from_numpy((rng.random((n, 2, 2)) - 0.5).astype(t))
    F.from_numpy((np.eye(2) + 0.1 * (rng.random((n, 2, 2)) - 0.5)).astype(t))
    material.from_numpy(rng.integers(0, 3, n).astype(np.int32))
    Jp.from_numpy((1 + 0.01 * rng.random(n)).astype(t))
    for _ in range(2):
        p2g()
    return [grid_v.to_numpy(), grid_m.to_numpy(), F.to_numpy(), Jp.to_numpy()], p2g, ()


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
@pytest.mark.parametrize("n", [1001, 5])
def test_p2g_2d_is_bit_identical(dtype, n):
    _, kernel, args = _both(lambda: _p2g_2d(n=n, dtype=dtype))
    (loop,) = _split_loops(kernel, args)
    assert loop.attrs["fission"] >= 8


def _p2g_3d(n=777, n_grid=16, dtype=ti.f32, array=False):
    """diffmpm3d's p2g: time-indexed particle state under one ti.root tree with the grid, the store of F[f + 1, p]
    in part 0, a log, 3x3x3 scatters into a field (or into ndarray arguments)."""
    dx, inv_dx, dt, E = 1 / n_grid, float(n_grid), 2e-3, 10.0
    x = ti.Vector.field(3, dtype)
    v = ti.Vector.field(3, dtype)
    C = ti.Matrix.field(3, 3, dtype)
    F = ti.Matrix.field(3, 3, dtype)
    kind = ti.field(ti.i32)
    grid_v = ti.Vector.field(3, dtype)
    grid_m = ti.field(dtype)
    ti.root.dense(ti.i, n).place(kind)
    ti.root.dense(ti.k, 2).dense(ti.l, n).place(x, v, C, F)
    ti.root.dense(ti.ijk, n_grid).place(grid_v, grid_m)
    gv = ti.Vector.ndarray(3, dtype, shape=(n_grid, n_grid, n_grid))
    gm = ti.ndarray(dtype, shape=(n_grid, n_grid, n_grid))

    @ti.func
    def body(f, p):
        base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
        fx = x[f, p] * inv_dx - ti.cast(base, dtype)
        w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
        new_F = (ti.Matrix.identity(dtype, 3) + dt * C[f, p]) @ F[f, p]
        J = new_F.determinant()
        if kind[p] == 0:
            sqrtJ = ti.sqrt(J)
            new_F = ti.Matrix([[sqrtJ, 0, 0], [0, sqrtJ, 0], [0, 0, 1]])
        F[f + 1, p] = new_F
        mass = 1.0
        cauchy = ti.Matrix.identity(dtype, 3) * (ti.log(J) - 1.0)
        if kind[p] == 0:
            mass = 4.0
            cauchy = ti.Matrix.identity(dtype, 3) * (J - 1) * E
        affine = -(dt * 4 * inv_dx * inv_dx) * cauchy + mass * C[f, p]
        return base, fx, w, mass, affine

    if array:
        @ti.kernel
        def p2g(f: ti.i32, gv: ti.types.ndarray(), gm: ti.types.ndarray()):
            for p in range(n):
                base, fx, w, mass, affine = body(f, p)
                for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
                    offset = ti.Vector([i, j, k])
                    dpos = (ti.cast(offset, dtype) - fx) * dx
                    weight = w[i][0] * w[j][1] * w[k][2]
                    gv[base + offset] += weight * (mass * v[f, p] + affine @ dpos)
                    gm[base + offset] += weight * mass
    else:
        @ti.kernel
        def p2g(f: ti.i32, gv: ti.types.ndarray(), gm: ti.types.ndarray()):
            for p in range(n):
                base, fx, w, mass, affine = body(f, p)
                for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
                    offset = ti.Vector([i, j, k])
                    dpos = (ti.cast(offset, dtype) - fx) * dx
                    weight = w[i][0] * w[j][1] * w[k][2]
                    grid_v[base + offset] += weight * (mass * v[f, p] + affine @ dpos)
                    grid_m[base + offset] += weight * mass

    rng = np.random.default_rng(1)
    t = np.float32 if dtype == ti.f32 else np.float64
    x.from_numpy((rng.random((2, n, 3)) * 0.6 + 0.2).astype(t))
    v.from_numpy((rng.random((2, n, 3)) - 0.5).astype(t))
    C.from_numpy((rng.random((2, n, 3, 3)) - 0.5).astype(t))
    F.from_numpy((np.eye(3) + 0.1 * (rng.random((2, n, 3, 3)) - 0.5)).astype(t))
    kind.from_numpy(rng.integers(0, 2, n).astype(np.int32))
    p2g(0, gv, gm)
    out = [grid_v.to_numpy(), grid_m.to_numpy(), F.to_numpy()] if not array else [gv.to_numpy(), gm.to_numpy(),
                                                                                   F.to_numpy()]
    return out, p2g, (0, gv, gm)


@pytest.fixture
def any_work(monkeypatch):
    """Split loops however little they compute per scatter (diffmpm3d's p2g shape is left alone by default); the
    kernel cache, which does not see the patch, is off."""
    from simgrad.passes import fission

    monkeypatch.setattr(fission, "MIN_FLOAT_OPS_PER_SCATTER", 0)
    return {"offline_cache": False}


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
@pytest.mark.parametrize("array", [False, True])
def test_p2g_3d_is_bit_identical(dtype, array, any_work):
    _, kernel, args = _both(lambda: _p2g_3d(dtype=dtype, array=array), **any_work)
    assert len(_split_loops(kernel, args)) == 1


def test_p2g_3d_is_left_alone_by_default():
    """6 float operations of part 0 per scatter (108 of them): the unsplit loop overlaps its scalar compute with the
    scatters' cache misses, which the split would expose (diffmpm3d's p2g measured slower split)."""
    ti.init(arch=ti.cpu)
    _, kernel, args = _p2g_3d()
    assert not _split_loops(kernel, args)


def test_several_threads_agree_to_rounding():
    """At two threads the order of float updates between threads follows the pool's scheduling, split or not."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=2, fission_lanes=0, fast_math=False)
    ref = _p2g_2d(n=3001)[0]
    ti.init(arch=ti.cpu, cpu_max_num_threads=2, fission_lanes=8, fast_math=False)
    got, kernel, args = _p2g_2d(n=3001)
    assert _split_loops(kernel, args)
    for a, b in zip(ref, got):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-9)


def _gather_loss(n=203, n_grid=8):
    """A g2p-shaped gather whose adjoint scatters into the grid's gradient (27 atomic adds), in float64."""
    x = ti.Vector.field(3, ti.f64, shape=n, needs_grad=True)
    grid = ti.Vector.field(3, ti.f64, shape=(n_grid, n_grid, n_grid), needs_grad=True)
    out = ti.Vector.field(3, ti.f64, shape=n, needs_grad=True)
    C = ti.Matrix.field(3, 3, ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    inv_dx = float(n_grid)

    @ti.kernel
    def g2p():
        for p in x:
            base = ti.cast(x[p] * inv_dx - 0.5, ti.i32)
            fx = x[p] * inv_dx - ti.cast(base, ti.f64)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.Vector([0.0, 0.0, 0.0], ti.f64)
            new_C = ti.Matrix.zero(ti.f64, 3, 3)
            for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
                dpos = ti.Vector([i, j, k], ti.f64) - fx
                weight = w[i][0] * w[j][1] * w[k][2]
                g_v = ti.sin(grid[base + ti.Vector([i, j, k])])
                new_v += weight * g_v
                new_C += 4 * inv_dx * weight * g_v.outer_product(dpos)
            out[p] = new_v
            C[p] = new_C

    @ti.kernel
    def total():
        for p in out:
            loss[None] += out[p].dot(out[p]) + (C[p] * C[p]).sum() * 1e-3

    return x, grid, loss, g2p, total


def test_gradients_of_a_split_adjoint_match_finite_differences():
    def build():
        x, grid, loss, g2p, total = _gather_loss()
        rng = np.random.default_rng(3)
        x.from_numpy(rng.random((203, 3)) * 0.6 + 0.2)
        grid.from_numpy(rng.random((8, 8, 8, 3)) - 0.5)
        with ti.ad.Tape(loss):
            g2p()
            total()
        return [loss.to_numpy(), grid.grad.to_numpy(), x.grad.to_numpy()], g2p, ()

    (_, ggrad, _), kernel, args = _both(build, default_fp=ti.f64)
    assert _split_loops(kernel, args, "grad")
    x, grid, loss, g2p, total = _gather_loss()
    rng = np.random.default_rng(3)
    xs = rng.random((203, 3)) * 0.6 + 0.2
    gs = rng.random((8, 8, 8, 3)) - 0.5
    x.from_numpy(xs)

    def f(g):
        grid.from_numpy(g)
        loss[None] = 0
        g2p()
        total()
        return loss[None]

    picks = [(1, 2, 3, 0), (4, 4, 4, 2), (2, 5, 3, 1), (0, 0, 0, 0)]
    h = 1e-6
    for pick in picks:
        up, down = gs.copy(), gs.copy()
        up[pick] += h
        down[pick] -= h
        fd = (f(up) - f(down)) / (2 * h)
        np.testing.assert_allclose(ggrad[pick], fd, rtol=1e-6, atol=1e-9)


def _scatter_loop(reads_grid=False, reads_array=False, total=False):
    """A small P2G-shaped loop over ndarray arguments or fields: enough float work for the split to be worth it,
    variants that must not be split."""
    n, m = 301, 16
    x = ti.field(ti.f32, shape=n)
    grid = ti.field(ti.f32, shape=m)
    s = ti.field(ti.f32, shape=())

    @ti.kernel
    def k(a: ti.types.ndarray(), g: ti.types.ndarray()):
        for p in x:
            y = x[p]
            for _ in ti.static(range(12)):
                y = y * 0.9 + ti.sqrt(y * y + 1.0) * 0.1 - 0.05
            if ti.static(reads_grid):
                y += grid[p % m] * 0.5  # part 0 reads what part 1 updates
            if ti.static(reads_array):
                y += a[p] * 0.5  # an ndarray argument may be the one scattered into
            if ti.static(total):
                s[None] += y  # a per-thread float sum, added once per chunk
            b = ti.cast(y * 4, ti.i32) % m
            for d in ti.static(range(3)):
                grid[(b + d) % m] += y * (d + 1)
                g[(b + 2 * d) % m] += y - d

    x.from_numpy(np.linspace(0.1, 3, n, dtype=np.float32))
    a = ti.ndarray(ti.f32, shape=n)
    a.from_numpy(np.linspace(0, 1, n, dtype=np.float32))
    g = ti.ndarray(ti.f32, shape=m)
    k(a, g)
    return [grid.to_numpy(), g.to_numpy(), s.to_numpy()], k, (a, g)


def test_field_and_ndarray_scatters_are_split():
    _, kernel, args = _both(_scatter_loop)
    assert len(_split_loops(kernel, args)) == 1


@pytest.mark.parametrize("variant", ["reads_grid", "reads_array", "total"])
def test_loops_that_must_not_be_split_are_left_alone(variant):
    """Part 0 reading what part 1 updates (a field, or an ndarray argument while another is scattered into: one
    array may be passed twice) would read before other iterations' updates; a per-thread float sum's rounding
    follows the chunks, counted in groups when split."""
    _, kernel, args = _both(lambda: _scatter_loop(**{variant: True}))
    assert not _split_loops(kernel, args)


def _task(kernel, args):
    text = kernel._instance_for(args, "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split("define internal void @sg_kernel_task1_private(")[1].split("\n}")[0]


@pytest.mark.parametrize("which", ["2d", "3d"])
def test_part_0_is_vector_code(which, any_work):
    """mpm99's P2G (conditional stores of F[p]) and diffmpm3d's p2g (one tree for particles and grid, F[f + 1, p]
    stored): their computing part runs as <W x float> arithmetic, which the unsplit loop never does."""
    for width in (0, -1):
        ti.init(arch=ti.cpu, fission_lanes=width, **any_work)
        _, kernel, args = _p2g_2d() if which == "2d" else _p2g_3d()
        task = _task(kernel, args)
        wide = sum(task.count(f"fmul nsz <{w} x float>") for w in (8, 16))  # SLP makes a few of its own
        assert (wide >= 40) == bool(width), wide


def test_default_width_fits_the_slots_in_l1(any_work):
    from simgrad.passes.fission import SLOT_BYTES

    ti.init(arch=ti.cpu, **any_work)
    _, kernel, args = _p2g_3d(n=64, n_grid=8)
    (loop,) = _split_loops(kernel, args)
    w = loop.attrs["fission"]
    assert 8 <= w <= 64 and w * (27 * 4 + 3) * 4 <= SLOT_BYTES


def test_width_is_checked():
    with pytest.raises(ValueError, match="fission_lanes"):
        ti.init(arch=ti.cpu, fission_lanes=6)


def test_not_on_the_simulated_gpu_nor_in_debug_mode(monkeypatch):
    ti.init(arch=ti.cpu, debug=True)
    _, kernel, args = _p2g_2d(n=40)
    assert not _split_loops(kernel, args)
    monkeypatch.setenv("SIMGRAD_GPU_SIM", "1")
    ti.init(arch=ti.cuda)
    _, kernel, args = _p2g_2d(n=40)
    assert not _split_loops(kernel, args)
