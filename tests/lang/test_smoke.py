import numpy as np

import simgrad as ti


def test_parallel_fill_and_struct_for_2d():
    x = ti.field(ti.f32, shape=8)
    y = ti.field(ti.f32, shape=(8, 4))

    @ti.kernel
    def fill(a: ti.f32):
        for i in x:
            x[i] = i * a
        for i, j in y:
            y[i, j] = i * 10 + j

    fill(2.0)
    np.testing.assert_array_equal(x.to_numpy(), np.arange(8) * 2.0)
    np.testing.assert_array_equal(y.to_numpy(), np.arange(8)[:, None] * 10 + np.arange(4)[None, :])


def test_kernel_scope_local_reduction_is_atomic():
    n = 200_000
    x = ti.field(ti.f32, shape=n)
    x.fill(1)

    @ti.kernel
    def total() -> ti.f32:
        s = 0.0
        for i in range(n):
            s += x[i]
        return s

    assert total() == n


def test_owned_updates_are_plain_but_shared_targets_stay_atomic():
    """x[i] += 1 alone needs no atomic; mixed with x[i + 1] += 1 every update must stay atomic."""
    n = 300_000
    own = ti.field(ti.i32, shape=n)
    mixed = ti.field(ti.i32, shape=n + 1)

    @ti.kernel
    def run():
        for i in range(n):
            own[i] += 1
            mixed[i] += 1
            mixed[i + 1] += 1

    for _ in range(3):
        run()
    expect = np.full(n + 1, 6)
    expect[0] = expect[-1] = 3
    np.testing.assert_array_equal(own.to_numpy(), np.full(n, 3))
    np.testing.assert_array_equal(mixed.to_numpy(), expect)


def test_default_parameter_values_apply_to_positional_calls():
    @ti.kernel
    def k(a: ti.i32, b: ti.i32 = 7) -> ti.i32:
        return a * 10 + b

    assert k(1) == 17
    assert k(1, 2) == 12
    assert k(a=3) == 37


def test_vector_scatter_under_contention_is_exact():
    """`g[c] += v` on a 2-vector f32 field (one 64-bit compare-and-swap per update) loses no update. The
    field is much larger than the number of updates, so the atomic path runs (not per-thread copies)."""
    n, cells = 200_000, 4_000_000
    g = ti.Vector.field(2, ti.f32, shape=cells)
    idx = ti.field(ti.i32, shape=n)
    idx.from_numpy((np.arange(n) % 3).astype(np.int32))

    @ti.kernel
    def scatter():
        for p in range(n):
            g[idx[p]] += ti.Vector([1.0, 2.0])

    scatter()
    assert "cmpxchg ptr" in scatter._instance_for((), "").llvm_text
    counts = np.bincount(np.arange(n) % 3, minlength=cells).astype(np.float32)
    np.testing.assert_array_equal(g.to_numpy(), np.stack([counts, 2 * counts], axis=1))


def test_reductions_sum_per_thread_then_once_into_the_shared_place():
    """`total[None] += v` and `s += v` on a kernel-scope local reduce per thread; the gradient of such a
    reduction (x.grad[i] at the loop index) must still land on every element."""
    n = 1 << 16
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    total = ti.field(ti.f64, shape=(), needs_grad=True)
    x.from_numpy(np.arange(n, dtype=np.float64) % 7)

    @ti.kernel
    def reduce_field():
        for i in x:
            total[None] += 3.0 * x[i]

    @ti.kernel
    def reduce_local() -> ti.f64:
        s = 0.0
        for i in x:
            s += x[i] * x[i]
        return s

    reduce_field()
    xs = x.to_numpy()
    assert total[None] == 3.0 * xs.sum()
    assert reduce_local() == (xs * xs).sum()
    total.grad[None] = 1.0
    reduce_field.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), np.full(n, 3.0))


def test_owned_updates_of_a_3d_struct_for_need_no_atomics():
    """(i, j, k) of a flattened 3-D loop are digits of its index: g[i, j, k] += ... is owned."""
    g = ti.field(ti.f32, shape=(6, 5, 4))
    h = ti.field(ti.f32, shape=(6, 5, 4))

    @ti.kernel
    def bump_owned():
        for i, j, k in g:
            g[i, j, k] += i * 100 + j * 10 + k

    @ti.kernel
    def bump_shared():
        for i, j, _k in g:
            h[i, j, 0] += 1.0  # not owned: four iterations share it

    def atomics(kernel):
        text = kernel._instance_for((), "").llvm_text
        task = text[text.index("_task1("):]
        task = task[:task.index("\n}\n")]
        return task.count("cmpxchg") + task.count("atomicrmw")

    bump_owned()
    bump_shared()
    assert atomics(bump_owned) == 0 and atomics(bump_shared) >= 1
    i, j, k = np.meshgrid(np.arange(6), np.arange(5), np.arange(4), indexing="ij")
    np.testing.assert_array_equal(g.to_numpy(), i * 100 + j * 10 + k)
    expect = np.zeros((6, 5, 4), np.float32)
    expect[:, :, 0] = 4
    np.testing.assert_array_equal(h.to_numpy(), expect)


def test_struct_for_accesses_in_loop_order_transposed_and_of_other_shapes():
    """g[i, j, k] of a field iterated in its own order is addressed as base + L * stride (affine in the
    flat loop index); transposed indices, another shape, AoS vector components and neighbours are not:
    all must agree with numpy."""
    a = np.random.default_rng(7).random((4, 5, 6)).astype(np.float32)
    src = ti.field(ti.f32, shape=(4, 5, 6))
    out = ti.Vector.field(3, ti.f32, shape=(4, 5, 6))
    tr = ti.field(ti.f32, shape=(6, 5, 4))
    wide = ti.field(ti.f32, shape=(4, 5, 7))
    src.from_numpy(a)

    @ti.kernel
    def run():
        for i, j, k in src:
            out[i, j, k] = ti.Vector([src[i, j, k], 2 * src[i, j, k], src[i, j, (k + 1) % 6]])
            tr[k, j, i] = src[i, j, k] + 1
            wide[i, j, k] = 3 * src[i, j, k]

    run()
    o = out.to_numpy()
    np.testing.assert_array_equal(o[..., 0], a)
    np.testing.assert_array_equal(o[..., 1], 2 * a)
    np.testing.assert_array_equal(o[..., 2], np.roll(a, -1, axis=2))
    np.testing.assert_array_equal(tr.to_numpy(), np.transpose(a + 1, (2, 1, 0)))
    np.testing.assert_array_equal(wide.to_numpy()[:, :, :6], 3 * a)
    np.testing.assert_array_equal(wide.to_numpy()[:, :, 6], 0)


def test_neighbour_and_time_sliced_accesses_in_a_struct_for_agree_with_numpy():
    """p[t - 1, i + di, j + dj] in `for i, j in g` is addressed as L * stride plus a constant and a
    loop-invariant slice (no division); guarded neighbours at the edges, a slice chosen at run time and
    a field whose rows are wider than the loop's (not affine) must all agree with numpy."""
    rng = np.random.default_rng(3)
    n, m, steps = 6, 9, 4
    a = rng.random((steps, n, m)).astype(np.float32)
    p = ti.field(ti.f32, shape=(steps, n, m))
    g = ti.field(ti.f32, shape=(n, m))
    wide = ti.field(ti.f32, shape=(n, m + 3))
    p.from_numpy(a)

    @ti.kernel
    def stencil(t: ti.i32):
        for i, j in g:
            s = -4.0 * p[t - 1, i, j]
            if i > 0:
                s += p[t - 1, i - 1, j]
            if i < n - 1:
                s += p[t - 1, i + 1, j]
            if j > 0:
                s += p[t - 1, i, j - 1]
            if j < m - 1:
                s += p[t - 1, i, j + 1]
            g[i, j] = s + p[0, i, j]
            wide[i, j + 3] = p[t, i, j]

    for t in (1, 3):
        stencil(t)
        q = np.pad(a[t - 1], 1)
        expect = -4 * a[t - 1] + q[:-2, 1:-1] + q[2:, 1:-1] + q[1:-1, :-2] + q[1:-1, 2:] + a[0]
        np.testing.assert_allclose(g.to_numpy(), expect, rtol=1e-6)
        np.testing.assert_array_equal(wide.to_numpy()[:, 3:], a[t])
