"""The simulated GPU (SIMGRAD_GPU_SIM=1, arch=cuda): the GPU lowering's grid-stride structure run on the CPU."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradNotSupportedError
from tests.gpu.kernels import CASES


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


def test_unsupported_is_located(sim):
    x = ti.field(ti.f32)
    ti.root.pointer(ti.i, 4).dense(ti.i, 4).place(x)

    @ti.kernel
    def k():
        for i in range(3):
            x[i] = 1.0

    with pytest.raises(SimgradNotSupportedError, match="sparse SNodes is not supported with arch=cuda") as e:
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


def test_deep_tape_is_a_located_overflow(sim):
    """The per-thread tape is local memory (at most GPU_TAPE_LIMIT entries): a deeper one is reported, never a
    wrong gradient."""
    from simgrad.errors import SimgradRuntimeError

    x = ti.field(ti.f64, shape=2, needs_grad=True)
    y = ti.field(ti.f64, shape=2, needs_grad=True)

    @ti.kernel
    def f(n: ti.i32):
        for i in x:
            v = x[i]
            for _ in range(n):
                v = ti.sin(v)
            y[i] = v

    f(3000)
    y.grad.fill(1)
    with pytest.raises(SimgradRuntimeError, match="arch=cuda keeps at most 1024 entries") as e:
        f.grad(3000)
    assert "test_gpu_sim.py" in str(e.value)
    f(10)
    f.grad(10)  # a shallow one still works
    assert x.grad[0] != 0


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
