"""The simulated GPU (SIMGRAD_GPU_SIM=1, arch=cuda): the GPU lowering's grid-stride structure run on the CPU."""

import ctypes

import numpy as np
import pytest

import simgrad as ti
from tests.gpu.kernels import CASES, sin_chain


@pytest.fixture(params=["1", "async"])
def sim(monkeypatch, request):
    """The simulated GPU, synchronous and deferred (SIMGRAD_GPU_SIM=async: launches run at a synchronize)."""
    monkeypatch.setenv("SIMGRAD_GPU_SIM", request.param)
    ti.init(arch=ti.cuda)
    assert ti.lang.impl.current_cfg().arch is ti.cuda
    yield


@pytest.mark.parametrize("case", CASES, ids=[c.__name__ for c in CASES])
def test_cases_on_simulated_gpu(sim, case):
    for got, ref, tol in case():
        np.testing.assert_allclose(np.asarray(got, np.float64), np.asarray(ref, np.float64), rtol=tol, atol=tol)


def test_grid_stride_covers_every_index_once(sim):
    """More iterations than simulated threads (a run-time count: a saturating grid of 128-thread blocks): each
    index once."""
    c = ti.field(ti.i32, shape=5000)

    @ti.kernel
    def k(n: ti.i32):
        for i in range(n):
            c[i] += 1

    k(5000)
    assert (c.to_numpy() == 1).all()


def test_global_thread_idx_is_the_grid_index(sim):
    t = ti.field(ti.i32, shape=256)

    @ti.kernel
    def k():
        for i in range(256):
            t[i] = ti.global_thread_idx()

    k()
    assert (t.to_numpy() == np.arange(256)).all()


def test_sparse_fields_on_the_gpu(sim):
    """pointer, bitmasked and dynamic nodes on arch=cuda: activation by writes from more threads than the CPU
    pool's batch slots (runtime/sparse.py MAX_THREADS), struct-fors over the active cells, deactivation and
    reuse; every result against numpy. The pools are the device's memory and no thread batch is used."""
    from simgrad.lang.program import get_program
    from simgrad.runtime import sparse as rt

    n = 12000
    p = ti.field(ti.f32)
    ti.root.pointer(ti.i, n).place(p)  # one block per cell: every write of the first kernel allocates
    b = ti.field(ti.i32)
    ti.root.bitmasked(ti.ij, (64, 64)).place(b)
    d = ti.field(ti.i32)
    ti.root.dense(ti.i, 8).dynamic(ti.j, 64, chunk_size=8).place(d)

    @ti.kernel
    def fill():
        for i in range(n):
            if i % 3 != 1:
                p[i] = i * 0.5
        for i, j in ti.ndrange(64, 64):
            if (i * j) % 5 == 0:
                b[i, j] = i + j
        for k in range(8 * 20):
            ti.append(d.parent(), k % 8, k)

    @ti.kernel
    def sums() -> ti.types.vector(4, ti.f64):
        sp, sb, sd, cnt = ti.f64(0.0), ti.f64(0.0), ti.f64(0.0), ti.f64(0.0)
        for i in p:
            sp += p[i]
            cnt += 1
        for i, j in b:
            sb += b[i, j]
        for i, j in d:
            sd += d[i, j]
        return ti.Vector([sp, sb, sd, cnt])

    @ti.kernel
    def lengths() -> ti.types.vector(8, ti.i32):
        r = ti.Vector([0] * 8)
        for k in ti.static(range(8)):
            r[k] = ti.length(d.parent(), k)
        return r

    @ti.kernel
    def drop():
        for i in range(n):
            if i % 2 == 0:
                ti.deactivate(p.parent(), i)

    fill()
    keep = np.arange(n) % 3 != 1
    ij = np.add.outer(np.arange(64), np.arange(64))
    mask = (np.multiply.outer(np.arange(64), np.arange(64)) % 5) == 0
    got = sums().to_numpy()
    np.testing.assert_allclose(got, [(np.arange(n) * 0.5)[keep].sum(), ij[mask].sum(), np.arange(160).sum(),
                                     keep.sum()])
    assert (lengths() == 20).all()
    drop()
    keep2 = keep & (np.arange(n) % 2 == 1)
    np.testing.assert_allclose(sums().to_numpy()[[0, 3]], [(np.arange(n) * 0.5)[keep2].sum(), keep2.sum()])
    fill()  # reactivated cells come back from the free list, zeroed, then written
    np.testing.assert_allclose(sums().to_numpy()[[0, 3]], [(np.arange(n) * 0.5)[keep].sum(), keep.sum()])
    np.testing.assert_allclose(p.to_numpy(), np.where(keep, np.arange(n) * 0.5, 0))
    prog = get_program()
    table = prog.sparse.table[: prog.sparse.count]
    dev = prog.device
    assert all(dev.owns(int(row[w])) for row in table for w in (rt.POOL_ZERO, rt.POOL_LISTS))
    assert all(dev.owns(int(row[rt.POOL_BASE])) for row in table if row[rt.POOL_CAPACITY])
    assert all(prog.sparse._unused_batches(k) == 0 and
               not np.ctypeslib.as_array((ctypes.c_int64 * 64).from_address(int(row[rt.POOL_BATCHES]))).any()
               for k, row in enumerate(table))


def test_sparse_struct_for_lists_its_cells_in_parallel(sim):
    """On arch=cuda a struct-for's list of active cells is built by a grid of threads (each active cell takes
    the next entry with an atomic add), not by one thread walking every cell; the gradient kernel replays it
    the same way. Every active cell is visited once."""
    x = ti.field(ti.f32, needs_grad=True)
    ti.root.pointer(ti.ij, 64).dense(ti.ij, 2).place(x, x.grad)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)

    @ti.kernel
    def init():
        for i, j in ti.ndrange(128, 128):
            if (i // 2 + j // 2) % 5 == 0:
                x[i, j] = 1.0 + (i % 2)

    @ti.kernel
    def f():
        for i, j in x:
            loss[None] += x[i, j] ** 2

    init()
    with ti.ad.Tape(loss=loss):
        f()
    active = np.add.outer(np.arange(128) // 2, np.arange(128) // 2) % 5 == 0
    vals = np.where(active, 1.0 + (np.arange(128) % 2)[:, None], 0.0)
    assert loss[None] == pytest.approx((vals ** 2).sum())
    np.testing.assert_allclose(x.grad.to_numpy(), 2 * vals)
    for launcher in (f.instance(()).launcher, f.grad.launcher(())):
        # (function, grid, block): the count's reset, the listgen, the count read, the loop over the list;
        # before, the count and the listgen were one one-thread kernel
        assert [grid * block > 1 for _, grid, block in launcher.launches[:4]] == [False, True, False, True]


def test_sparse_gradient_on_the_gpu(sim):
    """Reverse mode over a pointer field on arch=cuda against the analytic gradient (float64)."""
    ti.init(arch=ti.cuda, default_fp=ti.f64)
    x = ti.field(ti.f64, needs_grad=True)
    ti.root.pointer(ti.i, 16).dense(ti.i, 8).place(x, x.grad)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    rng = np.random.default_rng(3)
    vals = rng.normal(size=128)

    @ti.kernel
    def init(v: ti.types.ndarray()):
        for i in range(128):
            if i % 24 < 8:
                x[i] = v[i]

    @ti.kernel
    def f():
        for i in x:
            loss[None] += ti.sin(x[i]) * x[i]

    init(vals)
    with ti.ad.Tape(loss=loss):
        f()
    active = np.arange(128) % 24 < 8
    np.testing.assert_allclose(loss[None], (np.sin(vals) * vals)[active].sum(), rtol=1e-12)
    np.testing.assert_allclose(x.grad.to_numpy()[active], (np.cos(vals) * vals + np.sin(vals))[active], rtol=1e-12)


def test_sparse_pool_exhaustion_on_the_gpu_is_located(sim):
    ti.init(arch=ti.cuda, device_memory_GB=64 * 1024 / 2**30)  # 64 KB a pool
    x = ti.field(ti.f32)
    ti.root.pointer(ti.i, 4096).dense(ti.i, 64).place(x)  # 256-byte blocks: 256 fit

    @ti.kernel
    def k():
        for i in range(4096 * 64):
            x[i] = 1.0

    with pytest.raises(Exception, match="(?i)pool|memory") as e:
        k()
    assert "test_gpu_sim.py" in str(e.value) and "x[i] = 1.0" in str(e.value)


def test_print_in_parallel_and_serial_code(sim, capfd):
    """print on arch=cuda (the host's printf on the simulated GPU, vprintf on the GPU: test_ptx.py)."""
    x = ti.field(ti.f32, shape=3)

    @ti.kernel
    def k(a: ti.i64):
        for i in range(3):
            x[i] = i * 0.5
            print("i =", i, x[i], a)
        print(f"done {a + 1}")

    k(7)  # a kernel that prints waits (as Taichi's): its output is there when the call returns
    lines = capfd.readouterr().out.splitlines()
    assert sorted(lines[:3]) == ["i = 0 0.000000 7", "i = 1 0.500000 7", "i = 2 1.000000 7"]
    assert lines[3] == "done 8"


def test_codegen_segments_and_spills(sim):
    """A serial run of pure statements (arguments, arithmetic) launches nothing; a local read by a later loop
    travels in a scratch word."""
    from simgrad.codegen import nvptx

    x = ti.field(ti.f32, shape=8)

    @ti.kernel
    def k(a: ti.f32):
        b = a * 2.0
        for i in x:
            x[i] = b
        s = 0.0
        ti.loop_config(serialize=True)
        for j in range(4):
            s += x[j]
        for i in x:
            x[i] += s

    k(1.0)
    assert (x.to_numpy() == 10.0).all()
    cg = nvptx.GpuCodegen(_ir_of(k, 1.0), "t", sim=False)
    cg.generate()
    assert [(ln.grid, ln.block) for ln in cg.launches] == [(1, 128), (1, 1), (1, 128)]
    assert cg.scratch_slots >= 1


def _ir_of(kernel, *args):
    from simgrad.compiler.driver import compile_kernel
    from simgrad.lang.program import get_program

    prog = get_program()
    prog.jit.cache_enabled, old = False, prog.jit.cache_enabled
    try:
        return compile_kernel(kernel, prog, args).ir
    finally:
        prog.jit.cache_enabled = old


@pytest.mark.parametrize("stack", [None, 1500])
def test_deep_tape_on_the_gpu(sim, stack):
    """A tape deeper than a thread's local memory holds (GPU_TAPE_LIMIT) is a region per thread of a device buffer:
    the gradient is exact (float64, against the chain rule); deeper than ti.init(ad_stack_size=...) is the located
    overflow, never a wrong gradient."""
    from simgrad.codegen.nvptx import GPU_TAPE_LIMIT
    from simgrad.errors import SimgradRuntimeError

    if stack:
        ti.init(arch=ti.cuda, ad_stack_size=stack)
    x, y, f, reference = sin_chain(np.linspace(0.1, 1.4, 300))
    n = 3000
    assert n > GPU_TAPE_LIMIT
    f(n)
    y.grad.fill(1)
    if stack:
        with pytest.raises(SimgradRuntimeError, match="adstack|tape") as e:
            f.grad(n)
        assert "kernels.py" in str(e.value) and "v = ti.sin(v)" in str(e.value)  # the kernel's line
        return
    f.grad(n)
    v, d = reference(n)
    np.testing.assert_allclose(y.to_numpy(), v, rtol=1e-12)
    np.testing.assert_allclose(x.grad.to_numpy(), d, rtol=1e-10)


def test_shared_pure_values_across_segments(sim):
    """A pure value built from shared subexpressions (each step uses the last one twice) that a later segment
    recomputes: planned once per statement (before, the spill planner walked every path of the DAG, 2**40 here,
    and an integer `3 ** e` in debug mode hung the compile)."""
    x = ti.field(ti.i32, shape=4)

    @ti.kernel
    def k(a: ti.i32):
        v = a
        for _ in ti.static(range(40)):
            v = v * v + v
        for i in x:
            x[i] = v + i

    k(0)
    assert list(x.to_numpy()) == [0, 1, 2, 3]
    k(-1)  # -1 * -1 + -1 = 0, and so on
    assert list(x.to_numpy()) == [0, 1, 2, 3]


def test_serial_tape_spans_kernels(sim):
    """Serial code pushes before a loop and its adjoint pops after the next: the serial tape is the context's,
    its top a scratch word (a per-kernel tape gave NaN gradients)."""
    from simgrad.testing import check_grads

    ti.init(arch=ti.cuda, default_fp=ti.f64)
    n = 20
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    a = ti.field(ti.f64, shape=(), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    total = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        s = a[None] * 2.0
        if s > 1.0:
            s = ti.sqrt(s)
        k = 0
        while k < 3:
            s = s * a[None] + 0.1
            k += 1
        for i in x:
            y[i] = x[i] * s
        total[None] = y[3] * y[5] + s

    x.from_numpy(np.linspace(-1, 1, n))
    for av in (0.8, 0.3):
        a[None] = av
        check_grads(f, [x, a], [y, total], rtol=1e-6, atol=1e-10)


def test_kernels_launch_through_the_device_interface(sim):
    """A kernel runs as its segments launched on the program's device (the HostDriver here, CudaDriver on a
    GPU): the context is copied to device memory each launch (so a later write to the host copy cannot reach a
    running kernel) and return values come back from the device's copy."""
    from simgrad.lang.program import get_program
    from simgrad.runtime.gpu_launch import GpuLauncher

    x = ti.field(ti.f32, shape=1000)

    @ti.kernel
    def k(a: ti.f32) -> ti.f32:
        b = a * 2.0  # a serial segment, then a loop over the field, then the sum and return
        for i in range(1000):
            x[i] = i * b
        s = 0.0
        for i in range(1000):
            s += x[i]
        return s

    dev = get_program().device
    before = dev.launches
    assert k(1.5) == pytest.approx(3.0 * 999 * 1000 / 2, rel=1e-6)
    assert dev.launches - before >= 3  # the serial part and the two loops are separate launches
    inst = k.instance((1.5,))
    assert isinstance(inst.launcher, GpuLauncher) and inst.launcher.dctx != inst.launcher.buf.ctypes.data
    assert k(0.5) == pytest.approx(999 * 1000 / 2, rel=1e-6)  # the new argument reached the device copy


def test_what_kernels_read_is_device_memory(sim):
    """On arch=cuda the SNode trees, the roots table, the error buffer, the random states, ndarrays and each
    launcher's context copy are the device's memory (managed memory on a GPU), never host-only buffers."""
    from simgrad.lang.program import get_program

    x = ti.field(ti.f32, shape=100)
    a = ti.ndarray(ti.i32, 10)

    @ti.kernel
    def k(a: ti.types.ndarray()) -> ti.f32:
        for i in range(10):
            a[i] = i
        for i in x:
            x[i] = 2.0
        return x[3]

    assert k(a) == 2.0
    prog = get_program()
    dev = prog.device
    pointers = {"roots table": prog.memory.roots_address, "x's tree": int(prog.memory.roots[0]),
                "error buffer": prog.error.ctypes.data, "random states": prog.rng_states.ctypes.data,
                "ndarray": a._ndarray.ctypes.data, "context copy": k.instance((a,)).launcher.dctx}
    assert {name: dev.owns(p) for name, p in pointers.items()} == {name: True for name in pointers}
    assert not dev.owns(np.zeros(4).ctypes.data)
    assert (a.to_numpy() == np.arange(10)).all() and (x.to_numpy() == 2).all()
    ti.sync()


def test_random_numbers_on_the_gpu(sim):
    """ti.random on arch=cuda: a state per GPU thread (grids are capped at the saturating size, so a thread
    index has a state); uniform in [0, 1), integers over their range, independent across threads."""
    n = 200_000
    x = ti.field(ti.f32, shape=n)
    u = ti.field(ti.i32, shape=n)

    @ti.kernel
    def draw():
        for i in range(n):
            x[i] = ti.random()
            u[i] = ti.random(ti.i32) & 1023

    draw()
    xs, us = x.to_numpy(), u.to_numpy()
    assert 0.0 <= xs.min() and xs.max() < 1.0
    assert abs(xs.mean() - 0.5) < 0.005 and abs(xs.var() - 1 / 12) < 0.002
    assert len(np.unique(xs)) > 0.99 * n  # not a few threads' streams repeated
    counts = np.bincount(us, minlength=1024)
    assert counts.min() > 100 and counts.max() < 300  # ~195 each
    assert abs(np.corrcoef(xs[:-1], xs[1:])[0, 1]) < 0.01
