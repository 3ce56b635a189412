"""Sums in serial loops (passes/accumulate.py, fast_math only): a loop-invariant field element that an inner loop
adds to is summed in a local and added once after the loop; sums into locals are reassociable, so LLVM
vectorises them as reductions. What may change is only the order of the float additions: results equal the
float64 reference to float32 rounding, integer sums exactly; an element the loop never adds to keeps its bits;
no address outside the field is touched; fast_math=False keeps program order."""

import re

import numpy as np
import pytest

import simgrad as ti
from simgrad.runtime.jit import get_jit


def _opt_task(kernel, *args, task="sg_kernel_task2"):
    text = kernel._instance_for(args, "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split(f"define internal void @{task}")[1].split("\n}")[0]


def _nbody(n, pos_np, local_sum: bool):
    pos = ti.Vector.field(2, ti.f32, n)
    force = ti.Vector.field(2, ti.f32, n)
    pos.from_numpy(pos_np)

    @ti.kernel
    def into_field():
        for i in range(n):
            force[i] = [0.0, 0.0]
        for i in range(n):
            p = pos[i]
            for j in range(n):
                if i != j:
                    d = p - pos[j]
                    r = d.norm(1e-5)
                    force[i] += -(1.0 / r) ** 3 * d

    @ti.kernel
    def into_local():
        for i in range(n):
            p = pos[i]
            acc = ti.Vector([0.0, 0.0])
            for j in range(n):
                if i != j:
                    d = p - pos[j]
                    r = d.norm(1e-5)
                    acc += -(1.0 / r) ** 3 * d
            force[i] = acc

    k = into_local if local_sum else into_field
    k()
    return force.to_numpy(), k


def _nbody_reference(pos):
    p = pos.astype(np.float64)
    d = p[:, None, :] - p[None, :, :]
    r = np.sqrt((d * d).sum(-1) + np.float32(1e-5))
    w = -(1.0 / r) ** 3
    np.fill_diagonal(w, 0.0)
    return (w[:, :, None] * d).sum(1)


@pytest.mark.parametrize("local_sum", [False, True])
def test_nbody_force_vectorises_and_matches_float64(local_sum):
    ti.init(arch=ti.cpu)
    n = 300
    pos = np.random.default_rng(1).random((n, 2), dtype=np.float32)
    got, k = _nbody(n, pos, local_sum)
    want = _nbody_reference(pos)
    scale = np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5 * scale)
    task = _opt_task(k, task="sg_kernel_task2" if not local_sum else "sg_kernel_task1")
    assert "vector.body" in task and re.search(r"fadd reassoc nsz <\d+ x float>", task)  # vector partial sums


def test_fast_math_off_keeps_program_order():
    """With fast_math=False nothing is reassociated or cached: bit for bit the sequential float32 sum."""
    ti.init(arch=ti.cpu, fast_math=False)
    n = 257
    x = ti.field(ti.f32, n)
    out = ti.field(ti.f32, 4)
    vals = np.random.default_rng(2).standard_normal(n).astype(np.float32) * np.float32(1e3)
    x.from_numpy(vals)

    @ti.kernel
    def k():
        for i in range(4):
            for j in range(n):
                out[i] += x[j] * (i + 1)

    k()
    for i in range(4):
        s = np.float32(0)
        for v in vals:
            s = np.float32(s + v * np.float32(i + 1))
        assert out[i] == s
    assert "reassoc" not in k._instance_for((), "").llvm_text


def test_integer_sums_are_exact_and_untouched_elements_keep_their_bits():
    ti.init(arch=ti.cpu)
    n, m = 64, 1000
    a = ti.field(ti.i32, n)
    f = ti.field(ti.f32, n)
    f.from_numpy(np.full(n, -0.0, np.float32))

    @ti.kernel
    def k():
        for i in range(n):
            for j in range(m):
                if (i * 7 + j) % 3 == 0:
                    a[i] += j
                if i % 2 == 0 and j < i:
                    f[i] += 1.0

    k()
    i = np.arange(n)[:, None]
    j = np.arange(m)[None, :]
    np.testing.assert_array_equal(a.to_numpy(), np.where((i * 7 + j) % 3 == 0, j, 0).sum(1))
    got = f.to_numpy()
    want = np.where(np.arange(n) % 2 == 0, np.arange(n), 0).astype(np.float32)
    np.testing.assert_array_equal(got, want)
    # f[0] and the odd elements were never added to: still -0.0 (x + -0.0 is x, -0.0 included)
    assert np.signbit(got[0]) and np.signbit(got[1::2]).all()


def test_no_address_outside_the_field_is_touched():
    """An index beyond the field that the program guards never reaches memory: the field placed next to it
    (same tree, dense) is unchanged."""
    ti.init(arch=ti.cpu)
    n = 16
    a = ti.field(ti.f32)
    b = ti.field(ti.f32)
    ti.root.dense(ti.i, n).place(a)
    ti.root.dense(ti.i, n).place(b)
    b.from_numpy(np.arange(n, dtype=np.float32))

    @ti.kernel
    def k():
        for i in range(n + 8):
            for _j in range(10):
                if i < n:
                    a[i] += 1.0

    k()
    np.testing.assert_array_equal(a.to_numpy(), np.full(n, 10, np.float32))
    np.testing.assert_array_equal(b.to_numpy(), np.arange(n, dtype=np.float32))


def test_updates_that_need_atomics_stay_atomic():
    """Several iterations adding to one element (not owned): no caching, the sum is complete."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    total = ti.field(ti.i64, ())
    hist = ti.field(ti.i32, 8)

    @ti.kernel
    def k():
        for i in range(4096):
            for j in range(16):
                total[None] += j
                hist[(i + j) % 8] += 1

    k()
    assert total[None] == 4096 * sum(range(16))
    np.testing.assert_array_equal(hist.to_numpy(), np.full(8, 4096 * 16 // 8))


def test_gradient_through_a_cached_sum_matches_finite_differences():
    """The pass runs after autodiff, on the forward and on the adjoint: an n-body-like energy's gradient in
    float64 matches central differences."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    n = 12
    x = ti.field(ti.f64, n, needs_grad=True)
    e = ti.field(ti.f64, n, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    x0 = np.random.default_rng(3).random(n)

    @ti.kernel
    def energy():
        for i in range(n):
            for j in range(n):
                if i != j:
                    e[i] += ti.sin(x[i] - x[j]) * x[j]

    @ti.kernel
    def total():
        for i in range(n):
            loss[None] += e[i] ** 2

    def run(v):
        x.from_numpy(v)
        e.fill(0)
        loss[None] = 0
        energy()
        total()
        return loss[None]

    with ti.ad.Tape(loss):
        run(x0)
    g = x.grad.to_numpy()
    h = 1e-6
    fd = np.array([(run(x0 + h * np.eye(n)[k]) - run(x0 - h * np.eye(n)[k])) / (2 * h) for k in range(n)])
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)
