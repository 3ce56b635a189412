"""Conditional stores made branch-free (passes/speculate.py marks the IF, codegen/llvm.py writes select(c, new,
old)): only where the iteration owns the element and the element is inside the field whatever the condition.
Values against numpy (bit for bit: the same arithmetic, only the branch is gone); the rasterizer's per-sample
stores vectorise (<4 x float> divisions); every case that must keep its branch keeps it."""

import re

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.runtime.jit import get_jit


def _speculated(kernel, *args) -> list[bool]:
    inst = kernel._instance_for(args, "")
    return [bool(s.attrs.get("speculate")) for s in walk(inst.ir.body) if s.op is Op.IF]


def _opt_task(kernel, *args, task="sg_kernel_task1"):
    """The optimised CPU task; the simulated GPU (SIMGRAD_GPU_SIM=1 TI_ARCH=cuda) has none: the checks of its
    text are skipped there, after the values were checked."""
    if ti.lang.impl.current_cfg().arch == ti.cuda:
        pytest.skip("the CPU task's LLVM IR is checked on the CPU")
    text = kernel._instance_for(args, "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split(f"define internal void @{task}")[1].split("\n}")[0]


def test_rasterizer_samples_are_stored_without_branches_and_vectorise():
    """rendering/rasterizer.py's inner loop: per pixel, per triangle, per 2x2 sample, `if inside: samples[i, j,
    si, sj] = colour`. The result equals the branchy numpy reference exactly; the four samples' divisions are
    one vector division."""
    ti.init(arch=ti.cpu)
    W, H, n = 40, 30, 12
    rng = np.random.default_rng(7)
    tri = (rng.random((n, 3, 2)) * [W, H]).astype(np.float32)
    col = rng.random((n, 3, 3)).astype(np.float32)
    A = ti.Vector.field(2, ti.f32, n)
    B = ti.Vector.field(2, ti.f32, n)
    C = ti.Vector.field(2, ti.f32, n)
    c0 = ti.Vector.field(3, ti.f32, n)
    A.from_numpy(tri[:, 0])
    B.from_numpy(tri[:, 1])
    C.from_numpy(tri[:, 2])
    c0.from_numpy(col[:, 0])
    samples = ti.Vector.field(3, ti.f32, (W, H, 2, 2))
    pixels = ti.Vector.field(3, ti.f32, (W, H))

    @ti.kernel
    def rasterize():
        for i, j in pixels:
            for k in range(n):
                a, b, c = A[k], B[k], C[k]
                for si, sj in ti.ndrange(2, 2):
                    p = ti.Vector([i + (si + 0.5) / 2, j + (sj + 0.5) / 2])
                    al = -(p.x - b.x) * (c.y - b.y) + (p.y - b.y) * (c.x - b.x)
                    al /= -(a.x - b.x) * (c.y - b.y) + (a.y - b.y) * (c.x - b.x)
                    be = -(p.x - c.x) * (a.y - c.y) + (p.y - c.y) * (a.x - c.x)
                    be /= -(b.x - c.x) * (a.y - c.y) + (b.y - c.y) * (a.x - c.x)
                    ga = 1.0 - al - be
                    if al >= 0.0 and al <= 1.0 and be >= 0.0 and be <= 1.0 and ga >= 0.0:
                        samples[i, j, si, sj] = c0[k] * al
            s = ti.Vector([0.0, 0.0, 0.0])
            for si, sj in ti.ndrange(2, 2):
                s += samples[i, j, si, sj]
            pixels[i, j] = s / 4

    samples.fill(1.0)
    rasterize()
    f = np.float32
    want = np.ones((W, H, 2, 2, 3), f)
    for i in range(W):
        for j in range(H):
            for k in range(n):
                a, b, c = tri[k]
                for si in range(2):
                    for sj in range(2):
                        px, py = f(i) + (f(si) + f(0.5)) / f(2), f(j) + (f(sj) + f(0.5)) / f(2)
                        al = (-(px - b[0]) * (c[1] - b[1]) + (py - b[1]) * (c[0] - b[0])) / \
                            (-(a[0] - b[0]) * (c[1] - b[1]) + (a[1] - b[1]) * (c[0] - b[0]))
                        be = (-(px - c[0]) * (a[1] - c[1]) + (py - c[1]) * (a[0] - c[0])) / \
                            (-(b[0] - c[0]) * (a[1] - c[1]) + (b[1] - c[1]) * (a[0] - c[0]))
                        ga = f(1) - al - be
                        if 0 <= al <= 1 and 0 <= be <= 1 and ga >= 0:
                            want[i, j, si, sj] = col[k, 0] * al
    np.testing.assert_allclose(samples.to_numpy(), want, rtol=1e-5, atol=1e-6)
    assert _speculated(rasterize) == [True]
    assert re.search(r"fdiv nsz <\d+ x float>", _opt_task(rasterize))  # fails when the store keeps its branch


def test_stores_that_must_keep_their_branch():
    """An index that may leave the field, an element another iteration writes or reads, an ndarray, a local
    written in the branch: the branch stays, and the values are the program's."""
    ti.init(arch=ti.cpu)
    n = 16
    x = ti.field(ti.f32, n)
    y = ti.field(ti.f32, n)
    z = ti.field(ti.f32, n)
    w = ti.field(ti.f32, n)

    @ti.kernel
    def past_the_end():
        for i in range(n + 4):
            if i < n:
                x[i] = i * 2.0

    @ti.kernel
    def neighbour_read():
        for i in range(n):
            if i % 2 == 0:
                y[i] = 1.0 + i
            z[i] = y[(i + 1) % n]

    @ti.kernel
    def not_owned():
        for i in range(n):
            if i > 3:
                w[n - 1 - i // 2] = 3.0

    @ti.kernel
    def on_ndarray(a: ti.types.ndarray()):
        for i in range(n):
            if i > 2:
                a[i] = 1.0

    @ti.kernel
    def local_in_branch():
        for i in range(n):
            t = 0.0
            if i > 2:
                t = 5.0
                x[i] = t

    past_the_end()
    neighbour_read()
    not_owned()
    a = np.zeros(n, np.float32)
    on_ndarray(a)
    np.testing.assert_array_equal(x.to_numpy(), np.arange(n, dtype=np.float32) * 2)
    np.testing.assert_array_equal(a, np.where(np.arange(n) > 2, 1, 0).astype(np.float32))
    for k, args in ((past_the_end, ()), (neighbour_read, ()), (not_owned, ()), (on_ndarray, (a,)),
                    (local_in_branch, ())):
        assert not any(_speculated(k, *args)), k


def test_owned_conditional_store_is_branch_free_and_exact():
    """`if c: y[i, j, c] = v` over a 2-D ndrange and an inner loop over the last axis: no branch around the
    store, the same values as the branchy program. With the inner loop one longer than the axis (the branch
    excludes the extra index) the store keeps its branch: its address would leave the field."""
    ti.init(arch=ti.cpu)
    y = ti.field(ti.f32, (8, 6, 3))

    @ti.kernel
    def k(t: ti.f32, m: ti.template()):
        for i, j in ti.ndrange(8, 6):
            for c in range(m):
                v = ti.sin(i * 0.7 + j * 0.3 + c * 0.1 + t)
                if v > 0.2 and c < 3:
                    y[i, j, c] = v

    ii, jj, cc = np.meshgrid(np.arange(8), np.arange(6), np.arange(3), indexing="ij")
    f = np.float32
    v = np.sin(ii.astype(f) * f(0.7) + jj.astype(f) * f(0.3) + cc.astype(f) * f(0.1) + f(0.5))
    for m, speculated in ((3, True), (4, False)):
        y.fill(-1.0)
        k(0.5, m)
        np.testing.assert_allclose(y.to_numpy(), np.where(v > 0.2, v, -1.0), rtol=2e-6)
        assert _speculated(k, 0.5, m) == [speculated]
        assert bool(re.search(r"%old\.\d+ = load", k._instance_for((0.5, m), "").llvm_text)) == speculated


@pytest.mark.parametrize("debug", [True])
def test_debug_mode_keeps_the_branch(debug):
    ti.init(arch=ti.cpu, debug=debug)
    x = ti.field(ti.f32, 8)

    @ti.kernel
    def k():
        for i in range(8):
            if i > 3:
                x[i] = 1.0

    k()
    assert x.to_numpy().tolist() == [0, 0, 0, 0, 1, 1, 1, 1]
    assert _speculated(k) == [False]
