"""Float min/max reductions in serial loops vectorise (passes/accumulate.py marks them, codegen/arith.py lowers them
as llvm.minimumnum/maximumnum), and loops along a dynamic list read it with wide loads (codegen/access.py: the
element's address is a getelementptr from its chunk, not an inttoptr). The shape is marching_squares' render
kernel: per pixel, two min reductions over the edges of a dynamic list. A min/max is exact, so the vectorised
results equal the sequential ones bit for bit (NaN operands dropped as llvm.minnum does, as in taichi 1.7.4), with
fast_math on or off; scalar ti.min/ti.max keep their NaN and signed-zero behaviour (recorded from taichi 1.7.4)."""

import re

import numpy as np
import pytest

import simgrad as ti
from simgrad.runtime.jit import get_jit


def _opt_task(kernel, *args, task="sg_kernel_task1"):
    """The optimised CPU task; the simulated GPU (SIMGRAD_GPU_SIM=1 TI_ARCH=cuda) has none: the checks of its
    text are skipped there, after the values were checked."""
    if ti.lang.impl.current_cfg().arch == ti.cuda:
        pytest.skip("the CPU task's LLVM IR is checked on the CPU")
    text = kernel._instance_for(args, "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split(f"define internal void @{task}")[1].split("\n}")[0]


def _sequential(vals, init, pick):
    """The scalar loop's result: llvm.minnum/maxnum folded left to right (a NaN operand gives the other one)."""
    m = np.float32(init)
    for v in vals:
        m = np.float32(pick(m, v))
    return m


@pytest.mark.parametrize("fast_math", [True, False])
def test_several_reductions_in_one_loop_match_the_sequential_fold(fast_math):
    """Three reductions (a min, a max, a three-operand min chain) over 1000 values with NaNs, infinities and
    both zeros among them, per row: equal to the left-to-right fold of np.fmin/np.fmax."""
    ti.init(arch=ti.cpu, fast_math=fast_math)
    n, rows = 1000, 24
    rng = np.random.default_rng(5)
    a = rng.standard_normal((rows, n)).astype(np.float32)
    b = rng.standard_normal((rows, n)).astype(np.float32)
    a[3, 17] = a[3, 900] = b[5, 0] = np.nan
    a[7, :] = np.nan  # a row of only NaNs: the initial value stays
    a[9, 40], b[9, 41] = -np.inf, np.inf
    a[11, :] = 0.0
    a[11, 500] = -0.0
    xa, xb = ti.field(ti.f32, (rows, n)), ti.field(ti.f32, (rows, n))
    xa.from_numpy(a)
    xb.from_numpy(b)
    out = ti.field(ti.f32, (rows, 3))

    @ti.kernel
    def k():
        for r in range(rows):
            lo, hi, lo2 = 1e5, -1e5, 1e5
            for j in range(n):
                lo = ti.min(lo, xa[r, j])
                hi = ti.max(hi, xa[r, j] * 2.0)
                lo2 = ti.min(lo2, xa[r, j] + 1.0, xb[r, j])
            out[r, 0], out[r, 1], out[r, 2] = lo, hi, lo2

    k()
    got = out.to_numpy()
    for r in range(rows):
        assert got[r, 0] == _sequential(a[r], 1e5, np.fmin)
        assert got[r, 1] == _sequential(a[r] * np.float32(2), -1e5, np.fmax)
        assert got[r, 2] == _sequential(np.fmin(a[r] + np.float32(1), b[r]), 1e5, np.fmin)
    assert got[7, 0] == np.float32(1e5) and got[7, 1] == np.float32(-1e5)
    assert got[9, 0] == -np.inf and got[9, 1] == 2 * a[9, np.isfinite(a[9])].max()
    task = _opt_task(k)
    if fast_math:  # vector min/max in the loop: fails if the reductions are lowered as minnum again
        assert "vector.body" in task
        assert re.search(r"@llvm\.minimumnum\.v\d+f32", task) and re.search(r"@llvm\.maximumnum\.v\d+f32", task)
    else:  # program order: minnum, nothing marked
        assert "minimumnum" not in task


def test_a_reduction_local_also_assigned_otherwise_is_left_alone():
    """A local the loop also overwrites (or sums into) is no min reduction: it keeps llvm.minnum."""
    ti.init(arch=ti.cpu)
    n = 64
    x = ti.field(ti.f32, n)
    x.from_numpy(np.arange(n, dtype=np.float32)[::-1].copy())
    out = ti.field(ti.f32, 2)

    @ti.kernel
    def k():
        for _r in range(1):
            m = 1e5
            s = 1e5
            for j in range(n):
                m = ti.min(m, x[j])
                if x[j] == 10.0:
                    m = 7.5
                s = ti.min(s, x[j])
                s += 1.0
            out[0], out[1] = m, s

    k()
    m = np.float32(1e5)
    s = np.float32(1e5)
    for v in x.to_numpy():
        m = min(m, v)
        if v == 10.0:
            m = np.float32(7.5)
        s = np.float32(min(s, v) + 1)
    assert out[0] == m and out[1] == s
    text = k._instance_for((), "").llvm_text
    assert "minimumnum" not in text


def test_scalar_min_max_keep_nan_and_signed_zero_behaviour():
    """ti.min/ti.max/min/max outside reductions: the values taichi 1.7.4 gives on the CPU (probed: NaN operands
    dropped, of two equal zeros the first operand)."""
    ti.init(arch=ti.cpu)
    a, b = ti.field(ti.f32, 8), ti.field(ti.f32, 8)
    r = ti.field(ti.f32, (4, 8))
    a.from_numpy(np.array([np.nan, 1.0, -0.0, 0.0, np.nan, -np.inf, 2.0, np.nan], np.float32))
    b.from_numpy(np.array([1.0, np.nan, 0.0, -0.0, np.nan, np.nan, -3.0, -np.inf], np.float32))

    @ti.kernel
    def k():
        for i in range(8):
            r[0, i] = ti.min(a[i], b[i])
            r[1, i] = ti.max(a[i], b[i])
            r[2, i] = min(a[i], b[i])
            r[3, i] = max(a[i], b[i])

    k()
    got = r.to_numpy()
    lo = np.array([1, 1, -0.0, 0.0, np.nan, -np.inf, -3, -np.inf], np.float32)
    hi = np.array([1, 1, -0.0, 0.0, np.nan, -np.inf, 2, -np.inf], np.float32)
    for row, want in ((0, lo), (1, hi), (2, lo), (3, hi)):
        np.testing.assert_array_equal(got[row], want)
        np.testing.assert_array_equal(np.signbit(got[row]), np.signbit(want))


def _render_like(n_edges: int, whole_list: bool, monkeypatch):
    from simgrad.lang import snode

    if not whole_list:
        monkeypatch.setattr(snode, "WHOLE_LIST_BYTES", 0)
    ti.init(arch=ti.cpu)
    edge = ti.types.struct(p0=ti.math.vec2, p1=ti.math.vec2)
    edges = edge.field()
    ti.root.dynamic(ti.i, 1024, chunk_size=32).place(edges)
    W, H = 64, 48
    out = ti.Vector.field(2, ti.f32, (W, H))
    rng = np.random.default_rng(3)
    pts = (rng.random((n_edges, 4), dtype=np.float32) * np.float32(8) - np.float32(4))

    @ti.kernel
    def fill(p: ti.types.ndarray()):
        edges.deactivate()
        for k in range(p.shape[0]):
            edges.append(edge(ti.math.vec2(p[k, 0], p[k, 1]), ti.math.vec2(p[k, 2], p[k, 3])))

    @ti.func
    def dseg(p, a, b):
        p -= a
        b -= a
        h = ti.math.clamp(ti.math.dot(p, b) / ti.math.dot(b, b), 0, 1)
        return ti.math.length(p - h * b)

    @ti.kernel
    def render():
        for i, j in out:
            p = (2 * ti.math.vec2(i, j) - ti.math.vec2(W, H)) / H * 4
            dedge = 1e5
            dv = 1e5
            for k in range(edges.length()):
                s, e = edges[k].p0, edges[k].p1
                dedge = ti.min(dedge, dseg(p, s, e))
                dv = ti.min(dv, ti.math.length(p - s), ti.math.length(p - e))
            out[i, j] = ti.math.vec2(dedge, dv)

    fill(pts)
    render()
    return out.to_numpy(), pts, render, (W, H)


def _render_reference(pts, wh):
    W, H = wh
    f = np.float32
    i, j = np.meshgrid(np.arange(W, dtype=f), np.arange(H, dtype=f), indexing="ij")
    px, py = (f(2) * i - f(W)) / f(H) * f(4), (f(2) * j - f(H)) / f(H) * f(4)
    dedge = np.full((W, H), f(1e5))
    dv = np.full((W, H), f(1e5))
    for sx, sy, ex, ey in pts:
        qx, qy, bx, by = px - sx, py - sy, f(ex - sx), f(ey - sy)
        h = np.clip((qx * bx + qy * by) / (bx * bx + by * by), f(0), f(1))
        dedge = np.fmin(dedge, np.sqrt((qx - h * bx) ** 2 + (qy - h * by) ** 2))
        dv = np.fmin(dv, np.fmin(np.sqrt((px - sx) ** 2 + (py - sy) ** 2), np.sqrt((px - ex) ** 2 + (py - ey) ** 2)))
    return dedge, dv


@pytest.mark.parametrize("whole_list", [True, False])
def test_loop_over_a_dynamic_list_vectorises_with_wide_loads(whole_list, monkeypatch):
    """marching_squares' render loop: min reductions of segment and vertex distances over the edges of a dynamic
    list of structs. Values against numpy (float32 arithmetic, tolerance for sqrt/div rounding by LLVM's
    contraction-free but reordered dot products); the one-chunk list (the default for a 16 KiB list) is read with
    wide loads in the vectorised loop, the chunked one (WHOLE_LIST_BYTES 0) stays correct."""
    got, pts, render, wh = _render_like(147, whole_list, monkeypatch)
    dedge, dv = _render_reference(pts, wh)
    np.testing.assert_allclose(got[..., 0], dedge, rtol=2e-5, atol=2e-6)
    np.testing.assert_allclose(got[..., 1], dv, rtol=2e-5, atol=2e-6)
    if whole_list:
        task = _opt_task(render)
        assert "vector.body" in task
        assert re.search(r"load <\d+ x float>", task)  # consecutive (interleaved) loads of the list
        assert "masked.gather" not in task  # an inttoptr address made them gathers
        assert re.search(r"@llvm\.minimumnum\.v\d+f32", task)
