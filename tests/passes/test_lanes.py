"""SIMT lanes (passes/lanes.py): a parallel loop whose iterations run a while loop of pure local arithmetic runs W
iterations in lock step. Every result must be bit for bit the one of the same kernel with the rewrite off
(ti.init(simt_lanes=0)): ragged trip counts (lanes that never enter the loop, lanes that run to the cap), ranges
that are no multiple of W, 2-D struct-fors and ndranges, locals and values from before the while used after it,
branches, breaks and continues inside the while, ints and f64. Loops the rewrite must not touch are left alone,
and the rewritten escape loop is vector code in the optimised LLVM IR."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.runtime.jit import get_jit


def _both(build, threads=1, lanes=8, **init):
    """build() defines fields and kernels, runs them, returns (arrays, kernel, args); run with the rewrite off and
    on: the arrays must agree bit for bit. Returns (the rewritten run's arrays, its kernel and args)."""
    out = []
    for w in (0, lanes):
        ti.init(arch=ti.cpu, cpu_max_num_threads=threads, simt_lanes=w, **init)
        arrays, kernel, args = build()
        out.append(([np.ascontiguousarray(a) for a in arrays], kernel, args))
    for a, b in zip(out[0][0], out[1][0]):
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8))
    return out[1]


def _simt_loops(kernel, args):
    return [s for s in kernel._instance_for(args, "").ir.body.stmts if s.op is Op.RANGE_FOR and s.attrs.get("simt")]


def _task(kernel, args):
    text = kernel._instance_for(args, "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split("define internal void @sg_kernel_task1")[1].split("\n}")[0]


def _julia(n0, n1, dtype=ti.f32, cap=50):
    pixels = ti.field(ti.i32, shape=(n0, n1))
    last = ti.Vector.field(2, dtype, shape=(n0, n1))

    @ti.kernel
    def paint(cy: dtype):
        for i, j in pixels:
            c = ti.Vector([-0.8, cy])
            z = ti.Vector([i / n0 - 0.5, j / n1 - 0.5]) * 5  # corners start outside: those lanes never enter
            k = 0
            while z.norm() < 2 and k < cap:
                z = ti.Vector([z[0] ** 2 - z[1] ** 2, z[1] * z[0] * 2]) + c
                k += 1
            pixels[i, j] = k
            last[i, j] = z

    paint(0.156)
    return pixels, last, paint


@pytest.mark.parametrize("threads", [1, 2])
def test_escape_time_ragged_lanes_and_partial_last_group(threads):
    def build():
        pixels, last, paint = _julia(61, 37)  # 2257 pixels: no multiple of 8
        return [pixels.to_numpy(), last.to_numpy()], paint, (0.156,)

    arrays, kernel, args = _both(build, threads)
    k = arrays[0]
    assert k.min() == 0 and k.max() == 50 and 0 < (k == 50).sum() < k.size  # ragged: none, some, all the way
    assert len(_simt_loops(kernel, args)) == 1


def test_f64_escape_time_against_numpy():
    def build():
        pixels, last, paint = _julia(40, 24, ti.f64, cap=30)
        return [pixels.to_numpy(), last.to_numpy()], paint, (0.156,)

    (k, z), kernel, args = _both(build, default_fp=ti.f64)
    assert len(_simt_loops(kernel, args)) == 1
    # the same f64 operations in the same order, all pixels at once with a mask
    i, j = np.meshgrid(np.arange(40), np.arange(24), indexing="ij")
    zr, zi = (i * (1 / 40) - 0.5) * 5, (j * (1 / 24) - 0.5) * 5  # fast_math: / c is * (1 / c), as taichi's
    kk = np.zeros(i.shape, np.int32)
    for _ in range(31):
        live = (np.sqrt(zr * zr + zi * zi) < 2) & (kk < 30)
        nr, ni = zr ** 2 - zi ** 2 + -0.8, zi * zr * 2 + 0.156
        zr, zi = np.where(live, nr, zr), np.where(live, ni, zi)
        kk += live
    np.testing.assert_array_equal(k, kk)
    np.testing.assert_array_equal(z[..., 0], zr)
    np.testing.assert_array_equal(z[..., 1], zi)


def test_integers_collatz_against_python_with_run_time_range():
    def build():
        steps = ti.field(ti.i32, shape=1000)
        peak = ti.field(ti.i64, shape=1000)

        @ti.kernel
        def collatz(lo: ti.i32, hi: ti.i32):
            for i in range(lo, hi):  # run-time bounds: the group count is computed in the kernel
                n = ti.cast(i, ti.i64)
                top = n
                s = 0
                while n > 1:
                    if n % 2 == 0:
                        n = n // 2
                    else:
                        n = 3 * n + 1
                    top = ti.max(top, n)
                    s += 1
                steps[i] = s
                peak[i] = top

        collatz(3, 997)
        collatz(500, 400)  # no iterations at all
        return [steps.to_numpy(), peak.to_numpy()], collatz, (3, 997)

    (steps, peak), kernel, args = _both(build)
    assert len(_simt_loops(kernel, args)) == 1
    for i in range(3, 997):
        n, s, top = i, 0, i
        while n > 1:
            n = n // 2 if n % 2 == 0 else 3 * n + 1
            top = max(top, n)
            s += 1
        assert (steps[i], peak[i]) == (s, top)
    assert not steps[:3].any() and not steps[997:].any()


def test_constant_range_not_starting_at_zero():
    def build():
        out = ti.field(ti.f32, shape=210)

        @ti.kernel
        def k():
            for i in range(5, 203):  # 198 iterations: 24 full groups of 8 and one of 6
                v = i * 0.01
                n = 0
                while v < 1.5 and n < i % 11:
                    v = v * v + 0.3
                    n += 1
                out[i] = v + n

        k()
        return [out.to_numpy()], k, ()

    (out,), kernel, args = _both(build)
    assert len(_simt_loops(kernel, args)) == 1
    assert not out[:5].any() and not out[203:].any() and out[5:203].all()


def test_branches_breaks_continues_and_values_across_the_while():
    def build():
        x = ti.field(ti.f32, shape=333)
        out = ti.field(ti.f32, shape=333)
        count = ti.field(ti.i32, shape=333)

        @ti.kernel
        def k(scale: ti.f32):
            for i in ti.ndrange(333):
                a = x[i] * scale  # a value of the prefix used in the while and after it
                acc = 0.0  # a local of the prefix updated in the while and read after it
                m = 0
                while True:
                    m += 1
                    if m > 40:
                        break
                    b = a * 0.5  # a local of the while's own
                    if acc > 3.0:
                        b = -b
                        if m % 7 == 0:
                            acc = acc * 0.99  # (not only sums: acc's are no reassociable sums, see lanes.py)
                            continue
                    elif a < 0.1:
                        acc += 0.25
                        if acc > 2.0:
                            break
                    acc += b
                    if ti.abs(acc) > 10:
                        break
                out[i] = acc + a
                count[i] = m

        x.from_numpy(np.random.default_rng(1).uniform(-1, 1, 333).astype(np.float32))
        k(1.7)
        return [out.to_numpy(), count.to_numpy()], k, (1.7,)

    (out, count), kernel, args = _both(build)
    assert len(_simt_loops(kernel, args)) == 1
    assert len(set(count.tolist())) > 3  # the lanes leave at different steps


def test_two_whiles_one_after_the_other_and_a_2d_struct_for():
    def build():
        g = ti.field(ti.f32, shape=(19, 23))

        @ti.kernel
        def k():
            for i, j in g:
                x = ti.cast(i * 23 + j, ti.f32) * 0.01
                n1 = 0
                while x < 5.0:
                    x = x * 1.5 + 0.1
                    n1 += 1
                y = x * 0.5
                n2 = 0
                while y > 0.01 and n2 < 100:
                    y = y * 0.7
                    n2 += 1
                g[i, j] = y + n1 * 1000 + n2

        k()
        return [g.to_numpy()], k, ()

    _, kernel, args = _both(build)
    (loop,) = _simt_loops(kernel, args)
    assert sum(1 for s in walk(loop.blocks[0]) if s.op is Op.WHILE and s.attrs.get("simt")) == 2


def test_nested_while_is_left_alone_and_still_right():
    def build():
        out = ti.field(ti.i32, shape=100)

        @ti.kernel
        def k():
            for i in out:
                a = i
                total = 0
                while a > 0:
                    b = a
                    while b > 0:
                        b = b // 3
                        total += 1
                    a -= 7
                out[i] = total

        k()
        return [out.to_numpy()], k, ()

    (out,), kernel, args = _both(build)
    assert not _simt_loops(kernel, args)  # the outer while holds a loop
    want = []
    for i in range(100):
        a, total = i, 0
        while a > 0:
            b = a
            while b > 0:
                b //= 3
                total += 1
            a -= 7
        want.append(total)
    np.testing.assert_array_equal(out, want)


@pytest.mark.parametrize("what", ["store", "atomic", "read_written", "float_sum", "two_sums"])
def test_loops_that_do_not_qualify_are_left_alone(what):
    def build():
        x = ti.field(ti.f32, shape=50)
        hist = ti.field(ti.i32, shape=8)
        total = ti.field(ti.f32, shape=())

        @ti.kernel
        def k():
            for i in x:
                # (another iteration's element: loops that touch only the iteration's own are
                # passes/lanes_memory.py's, tests/passes/test_lanes_memory.py)
                v = x[(i + 1) % 50] if ti.static(what == "read_written") else i * 0.1
                n = 0
                s = 0.0
                while v < 3.0:
                    v = v * 1.3 + 0.05
                    n += 1
                    if ti.static(what == "two_sums"):  # reassociable (fast_math): LLVM may pair them in one form
                        s += v
                        s += v * 0.5
                    if ti.static(what == "store"):
                        x[(i + 1) % 50] = v  # memory inside the while
                    if ti.static(what == "atomic"):
                        hist[n % 8] += 1
                if ti.static(what == "float_sum"):
                    total[None] += v  # a per-thread float sum: its rounding follows the pool's chunks
                else:
                    x[i] = v + n + s

        x.from_numpy(np.linspace(0, 1, 50, dtype=np.float32))
        k()
        return [x.to_numpy(), hist.to_numpy(), total.to_numpy()], k, ()

    _, kernel, args = _both(build)
    assert not _simt_loops(kernel, args)
    assert "simt" not in kernel._instance_for(args, "").llvm_text


def test_the_escape_loop_is_vector_code():
    for lanes in (0, 8):
        ti.init(arch=ti.cpu, simt_lanes=lanes)
        _, _, paint = _julia(64, 64)
        task = _task(paint, (0.156,))
        vector_fmul = "fmul nsz <8 x float>" in task
        assert vector_fmul == bool(lanes), task


def test_gradients_of_a_kernel_with_a_while_are_unchanged():
    def build():
        x = ti.field(ti.f64, shape=21, needs_grad=True)
        y = ti.field(ti.f64, shape=21, needs_grad=True)
        loss = ti.field(ti.f64, shape=(), needs_grad=True)

        @ti.kernel
        def f():
            for i in x:
                v = x[i]
                k = 0
                while k < i % 5:
                    v = ti.sin(v) * 1.5 + 0.1
                    k += 1
                y[i] = v

        @ti.kernel
        def total():
            for i in y:
                loss[None] += y[i] * y[i]

        x.from_numpy(np.linspace(-1, 1, 21))
        with ti.ad.Tape(loss):
            f()
            total()
        return [y.to_numpy(), x.grad.to_numpy()], f, ()

    (y, g), kernel, args = _both(build, default_fp=ti.f64)
    assert len(_simt_loops(kernel, args)) == 1
    # against central differences of the same map
    def fwd(x):
        out = []
        for i, v in enumerate(x):
            for _ in range(i % 5):
                v = np.sin(v) * 1.5 + 0.1
            out.append(v)
        return np.array(out)
    xs, h = np.linspace(-1, 1, 21), 1e-6
    fd = (fwd(xs + h) ** 2 - fwd(xs - h) ** 2) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_default_width_is_four_vector_registers_of_the_widest_lane_value(dtype):
    ti.init(arch=ti.cpu, default_fp=dtype)
    _, _, paint = _julia(8, 8, dtype)
    (loop,) = _simt_loops(paint, (0.156,))
    assert loop.attrs["simt"] == min(64, 4 * get_jit().vector_bits() // dtype.bits)


def test_width_is_checked():
    with pytest.raises(ValueError, match="simt_lanes"):
        ti.init(arch=ti.cpu, simt_lanes=3)


def test_not_on_the_simulated_gpu_nor_in_debug_mode(monkeypatch):
    """A GPU runs its threads in lock step already; debug mode keeps every check where the user's code has it."""
    ti.init(arch=ti.cpu, debug=True)
    pixels, _, paint = _julia(16, 16)
    assert not _simt_loops(paint, (0.156,))
    k_debug = pixels.to_numpy()
    monkeypatch.setenv("SIMGRAD_GPU_SIM", "1")
    ti.init(arch=ti.cuda)
    assert ti.lang.impl.current_cfg().arch is ti.cuda
    pixels, _, paint = _julia(16, 16)
    assert not _simt_loops(paint, (0.156,))
    np.testing.assert_array_equal(pixels.to_numpy(), k_debug)
