"""Scatter privatisation (codegen/privatize.py): loops that only add into a field run over per-thread
copies when they do many more updates than the field has elements. Results must equal numpy's, and
the fields the loop does not own entirely (read, stored, interleaved with others) must stay atomic."""

import numpy as np
import pytest

import simgrad as ti


@pytest.fixture(autouse=True)
def four_threads():
    ti.init(arch=ti.cpu, cpu_max_num_threads=4)  # privatisation needs > 1 thread, whatever the machine has
    yield


def _text(kernel, *args):
    return kernel._instance_for(args, "").llvm_text


def test_p2g_scatter_into_small_grid_matches_numpy():
    n, g = 60_000, 16
    rng = np.random.default_rng(1)
    xs = (rng.random((n, 2)) * 0.8 + 0.1).astype(np.float64)
    vs = rng.standard_normal((n, 2))
    x = ti.Vector.field(2, ti.f64, shape=n)
    v = ti.Vector.field(2, ti.f64, shape=n)
    grid_v = ti.Vector.field(2, ti.f64, shape=(g, g), needs_grad=True)
    grid_m = ti.field(ti.f64, shape=(g, g))
    x.from_numpy(xs)
    v.from_numpy(vs)
    grid_v.grad.from_numpy(np.full((g, g, 2), 7.0))  # the gradient lives in the same tree: untouched

    @ti.kernel
    def p2g():
        for p in x:
            base = ti.cast(x[p] * g - 0.5, ti.i32)
            fx = x[p] * g - ti.cast(base, ti.f64)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    weight = w[i][0] * w[j][1]
                    grid_v[base + ti.Vector([i, j])] += weight * v[p]
                    grid_m[base + ti.Vector([i, j])] += weight

    p2g()
    assert "_private" in _text(p2g)
    base = (xs * g - 0.5).astype(np.int32)
    fx = xs * g - base
    w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
    gm, gv = np.zeros((g, g)), np.zeros((g, g, 2))
    for i in range(3):
        for j in range(3):
            wt = w[i][:, 0] * w[j][:, 1]
            np.add.at(gm, (base[:, 0] + i, base[:, 1] + j), wt)
            np.add.at(gv, (base[:, 0] + i, base[:, 1] + j), wt[:, None] * vs)
    np.testing.assert_allclose(grid_m.to_numpy(), gm, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(grid_v.to_numpy(), gv, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(grid_v.grad.to_numpy(), np.full((g, g, 2), 7.0))


@pytest.mark.parametrize("dtype", [ti.i32, ti.i64])
def test_integer_histogram_is_exact_and_adds_to_existing_counts(dtype):
    n, bins = 200_000, 37
    data = ti.field(ti.i32, shape=n)
    hist = ti.field(dtype, shape=bins)
    values = np.random.default_rng(2).integers(0, 1000, n).astype(np.int32)
    data.from_numpy(values)
    hist.from_numpy(np.arange(bins))

    @ti.kernel
    def count():
        for i in data:
            hist[data[i] % bins] += 1

    count()
    count()
    assert "_private" in _text(count)
    np.testing.assert_array_equal(hist.to_numpy(), np.arange(bins) + 2 * np.bincount(values % bins, minlength=bins))


def test_updates_in_a_constant_serial_loop_count_towards_the_decision():
    """100 iterations x 64 inner updates into 4096 cells: worth privatising only counting the inner loop."""
    cells = 4096
    acc = ti.field(ti.f32, shape=cells)

    @ti.kernel
    def spread():
        for p in range(100):
            for s in range(64):
                acc[(p * 64 + s * 7) % cells] += 1.0

    spread()
    expect = np.zeros(cells, np.float32)
    for p in range(100):
        np.add.at(expect, (p * 64 + np.arange(64) * 7) % cells, 1.0)
    assert "_private" in _text(spread)
    np.testing.assert_array_equal(acc.to_numpy(), expect)


def test_a_negative_zero_no_update_reached_keeps_its_sign():
    n = 50_000
    h = ti.field(ti.f32, shape=8)
    h.from_numpy(np.array([-0.0] * 8, np.float32))

    @ti.kernel
    def only_first_four():
        for i in range(n):
            h[i % 4] += 0.5

    only_first_four()
    out = h.to_numpy()
    np.testing.assert_array_equal(out[:4], np.full(4, n / 8))
    assert np.all(np.signbit(out[4:]))


def test_fields_the_loop_reads_or_whose_old_value_it_uses_stay_atomic():
    n, bins = 100_000, 5
    hist = ti.field(ti.i32, shape=bins)
    seen = ti.field(ti.i32, shape=n)
    read = ti.field(ti.i32, shape=bins)
    total = ti.field(ti.i32, shape=n)

    @ti.kernel
    def with_old_value():
        for i in range(n):
            seen[i] = ti.atomic_add(hist[i % bins], 1)

    @ti.kernel
    def reads_too():
        for i in range(n):
            read[i % bins] += 1
            total[i] = read[0] * 0 + 1

    with_old_value()
    reads_too()
    assert "_private" not in _text(with_old_value)
    assert "_private" not in _text(reads_too)
    np.testing.assert_array_equal(hist.to_numpy(), np.full(bins, n // bins))
    # every old value of a bin was seen exactly once
    for b in range(bins):
        np.testing.assert_array_equal(np.sort(seen.to_numpy()[b::bins]), np.arange(n // bins))
    np.testing.assert_array_equal(read.to_numpy(), np.full(bins, n // bins))


def test_a_copy_spanning_an_interleaved_field_leaves_that_field_as_the_loop_left_it():
    """a and b share a dense node (AoS): a's copy spans b's elements too; b, stored by the same loop at
    elements it owns, must keep the loop's values (the final sum skips zero partials)."""
    n, cells = 64 * 1600, 64
    a = ti.field(ti.f32)
    b = ti.field(ti.f32)
    ti.root.dense(ti.i, cells).place(a, b)
    b.from_numpy(np.arange(cells, dtype=np.float32))

    @ti.kernel
    def scatter():
        for i in range(n):
            a[i % cells] += 1.0
            if i < cells:
                b[i] = b[i] * 2.0 + 1.0

    scatter()
    assert "_private" in _text(scatter)
    np.testing.assert_array_equal(a.to_numpy(), np.full(cells, n / cells, np.float32))
    np.testing.assert_array_equal(b.to_numpy(), np.arange(cells, dtype=np.float32) * 2 + 1)


def _stencil_spread(h, src, n: int, lo: int):
    """h[t, i +- 1, j +- 1] += w * src[i, j] where the target index lies in [lo, n) on both axes."""
    @ti.kernel
    def spread(t: ti.i32):
        for i, j in src:
            for di, dj in ti.static([(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]):
                if lo <= i + di < n and lo <= j + dj < n:
                    h[t, i + di, j + dj] += (1.0 + di + 2 * dj) * src[i, j]

    return spread


@pytest.mark.parametrize("debug", [False, True])
def test_stencil_scatter_into_one_time_slice_copies_only_that_slice(debug):
    """h[t, i +- 1, j +- 1] += ...: the leading index is the same loop-invariant t in every update, so the
    per-thread copy is one (n, n) slice (the whole field is 50x larger than the loop); other slices keep
    their values. In debug mode slices are off (the whole field would be copied, so atomics run)."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=4, debug=debug)
    steps, n = 50, 64
    h = ti.field(ti.f64, shape=(steps, n, n))
    src = ti.field(ti.f64, shape=(n, n))
    rng = np.random.default_rng(3)
    start = rng.standard_normal((steps, n, n))
    h.from_numpy(start)
    s = rng.standard_normal((n, n))
    src.from_numpy(s)

    spread = _stencil_spread(h, src, n, 0)
    spread(7)
    expect = start.copy()
    for di, dj in [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]:
        dst = expect[7, max(di, 0):n + min(di, 0), max(dj, 0):n + min(dj, 0)]
        dst += (1.0 + di + 2 * dj) * s[max(-di, 0):n - max(di, 0), max(-dj, 0):n - max(dj, 0)]
    np.testing.assert_allclose(h.to_numpy(), expect, rtol=1e-13, atol=1e-13)
    if not debug:
        assert "_private" in _text(spread, 7)


def test_few_updates_into_a_large_field_use_atomics_with_the_same_result():
    n, cells = 1000, 1_000_000
    big = ti.field(ti.f32, shape=cells)

    @ti.kernel
    def few():
        for i in range(n):
            big[(i * 7919) % cells] += 2.0
            big[(i * 7919 + 1) % cells] += 1.0

    few()
    expect = np.zeros(cells, np.float32)
    np.add.at(expect, (np.arange(n) * 7919) % cells, 2.0)
    np.add.at(expect, (np.arange(n) * 7919 + 1) % cells, 1.0)
    np.testing.assert_array_equal(big.to_numpy(), expect)


def test_adjoint_of_a_gather_scatters_into_a_private_gradient_copy():
    """out[i] = sum_k c_k * d[idx(i, k)]: d.grad[idx] += c_k * out.grad[i] over a small d, against numpy."""
    n, cells = 40_000, 50
    d = ti.field(ti.f64, shape=cells, needs_grad=True)
    out = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def gather():
        for i in out:
            for k in range(4):
                out[i] += (k + 1.0) * d[(i * 3 + k * 11) % cells]

    out.grad.from_numpy(np.linspace(0, 1, n))
    gather.grad()
    g = np.zeros(cells)
    og = np.linspace(0, 1, n)
    for k in range(4):
        np.add.at(g, (np.arange(n) * 3 + k * 11) % cells, (k + 1.0) * og)
    np.testing.assert_allclose(d.grad.to_numpy(), g, rtol=1e-12)
    assert "_private" in gather._instance_for((), "grad").llvm_text


def test_reading_another_slice_of_the_field_keeps_privatisation_reading_maybe_the_same_one_does_not():
    """q[t, .] += q[t + 1, .]: the read slice differs from the updated one by construction. With
    q[u, .] read (u a second argument, maybe equal to t) the copy could hide updates: atomics run."""
    n, c = 40_000, 16
    q = ti.field(ti.f64, shape=(4, c))
    start = np.arange(4 * c, dtype=np.float64).reshape(4, c)

    @ti.kernel
    def next_slice(t: ti.i32):
        for i in range(n):
            q[t, i % c] += q[t + 1, i % c] * 0.5

    @ti.kernel
    def any_slice(t: ti.i32, u: ti.i32):
        for i in range(n):
            q[t, i % c] += 1.0 + 0.0 * q[u, 0]

    q.from_numpy(start)
    next_slice(1)
    expect = start.copy()
    expect[1] += (n // c) * 0.5 * start[2]
    np.testing.assert_array_equal(q.to_numpy(), expect)
    assert "_private" in _text(next_slice, 1)
    any_slice(2, 2)
    expect[2] += n // c
    np.testing.assert_array_equal(q.to_numpy(), expect)
    assert "_private" not in _text(any_slice, 2, 2)


def test_fixed_and_varying_updates_of_one_field_after_a_store_before_the_loop():
    """hist[0] (a fixed element, not a per-thread reduction since the field is also updated at varying
    elements) and hist[i % 5] go to the copies; the store before the loop happens first."""
    n = 100_000
    hist = ti.field(ti.i32, shape=5)
    hist.from_numpy(np.full(5, 9, np.int32))

    @ti.kernel
    def count():
        hist[0] = 0
        for i in range(n):
            hist[0] += 1
            hist[i % 5] += 1

    count()
    assert "_private" in _text(count)
    np.testing.assert_array_equal(hist.to_numpy(), [n + n // 5] + [9 + n // 5] * 4)


def test_private_copies_kept_between_launches_start_each_launch_at_zero():
    """The per-thread copies persist in the launcher and are zeroed by the final sum: every launch must
    add exactly its own updates (float scatter with fresh inputs each time)."""
    n, cells = 50_000, 64
    idx = ti.field(ti.i32, shape=n)
    w = ti.field(ti.f64, shape=n)
    grid = ti.field(ti.f64, shape=cells)

    @ti.kernel
    def scatter():
        for p in idx:
            grid[idx[p]] += w[p]
            grid[(idx[p] + 1) % cells] += 0.5 * w[p]

    rng = np.random.default_rng(7)
    for _ in range(3):
        i = rng.integers(0, cells, n).astype(np.int32)
        v = rng.standard_normal(n)
        idx.from_numpy(i)
        w.from_numpy(v)
        grid.fill(0)
        scatter()
        want = np.bincount(i, v, cells) + 0.5 * np.bincount((i + 1) % cells, v, cells)
        np.testing.assert_allclose(grid.to_numpy(), want, rtol=1e-12, atol=1e-12)
    assert "_private" in _text(scatter)


@pytest.mark.parametrize("threads,n", [(1, 64), (4, 8)])
def test_a_loop_run_on_one_thread_updates_the_fields_directly(threads, n):
    """One pool thread, or no more iterations than a grain (the pool's serial path): the private task runs with
    the fields themselves as thread 0's copies (plain updates, no copy to zero or sum; 7x on mpm88's p2g at one
    thread). The slice the prefix index picks, the other slices, a -0.0 no update reaches and a neighbouring
    field in the copied range all come out as numpy says."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads)
    steps = 5
    h = ti.field(ti.f64)
    other = ti.field(ti.f64)
    ti.root.dense(ti.ijk, (steps, n, n)).place(h, other)  # interleaved: the copied range spans `other` too
    src = ti.field(ti.f64, shape=(n, n))
    rng = np.random.default_rng(5)
    start = rng.standard_normal((steps, n, n))
    start[2, 0, 0] = -0.0
    h.from_numpy(start)
    other.from_numpy(start + 100)
    s = rng.standard_normal((n, n))
    src.from_numpy(s)

    spread = _stencil_spread(h, src, n, 1)
    spread(2)
    expect = start.copy()
    for di, dj in [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]:
        for i in range(n):
            for j in range(n):
                if 1 <= i + di < n and 1 <= j + dj < n:
                    expect[2, i + di, j + dj] += (1.0 + di + 2 * dj) * s[i, j]
    got = h.to_numpy()
    np.testing.assert_allclose(got, expect, rtol=1e-13, atol=1e-13)
    assert np.signbit(got[2, 0, 0])
    np.testing.assert_array_equal(other.to_numpy(), start + 100)
    text = _text(spread, 2)
    assert "_private" in text and "direct" in text


@pytest.mark.parametrize("threads,n", [(1, 20000), (4, 20000), (4, 100)])
def test_atomic_updates_have_a_plain_variant_for_a_loop_on_one_thread(threads, n):
    """A loop whose updates need atomics (ndarray min/max/mul: no per-thread copies; its adds go to copies) also
    gets a `_serial` task whose updates are plain, run when the pool runs the loop on the calling thread alone (one
    thread, or at most a grain of iterations); otherwise the atomic task runs. Every kind of update agrees with
    numpy either way."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads)
    rng = np.random.default_rng(7)
    idx = rng.integers(0, 37, n).astype(np.int32)
    val = rng.standard_normal(n)

    @ti.kernel
    def scatter(ix: ti.types.ndarray(), v: ti.types.ndarray(), s: ti.types.ndarray(), lo: ti.types.ndarray(),
                hi: ti.types.ndarray(), cnt: ti.types.ndarray(), prod: ti.types.ndarray()):
        for p in ix:
            k = ix[p]
            s[k] += v[p]
            ti.atomic_min(lo[k], v[p])
            ti.atomic_max(hi[k], v[p])
            cnt[k] += 1
            ti.atomic_mul(prod[k], 1.0 + 1e-3 * v[p])  # (`*=` is a plain update, as in Taichi)

    s, lo, hi = np.zeros(37), np.full(37, np.inf), np.full(37, -np.inf)
    cnt, prod = np.zeros(37, np.int32), np.ones(37)
    scatter(idx, val, s, lo, hi, cnt, prod)
    np.testing.assert_allclose(s, np.bincount(idx, val, 37), rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(cnt, np.bincount(idx, minlength=37))
    for k in range(37):
        sel = val[idx == k]
        assert lo[k] == (sel.min() if sel.size else np.inf) and hi[k] == (sel.max() if sel.size else -np.inf)
        np.testing.assert_allclose(prod[k], np.prod(1.0 + 1e-3 * sel), rtol=1e-9)
    text = scatter._instance_for((idx, val, s, lo, hi, cnt, prod), "").llvm_text
    assert "_private_serial" in text


def _page_counts(kernel, *args):
    """Per region, the pages its last final sum found marked (-1 before one): the page maps' holders (a region's
    holders are its copies', then its maps')."""
    return list(kernel._instance_for(args, "").launcher._holders[1::2, 2])


def test_the_final_sum_adds_the_pages_each_thread_marked_as_the_updates_move():
    """A scatter into two small clusters of a 16 MB interleaved field: each thread marks the pages of its copy it
    updates, and only marked pages are summed and cleared. The clusters move every launch (a page left marked or
    a missed mark would add a stale partial or lose one), a -0.0 and the neighbouring field stay as they were."""
    n, cells = 100_000, 1 << 21
    a, b = ti.field(ti.f32), ti.field(ti.f32)
    ti.root.dense(ti.i, cells).place(a, b)  # the copy spans b too
    at = ti.field(ti.i32, shape=n)
    w = ti.field(ti.f32, shape=n)

    @ti.kernel
    def scatter():
        for p in at:
            for k in ti.static(range(4)):
                a[at[p] + k] += w[p] * (k + 1)

    rng = np.random.default_rng(3)
    start = rng.integers(-4, 4, cells).astype(np.float32)
    start[5] = -0.0
    a.from_numpy(start)
    b.from_numpy(start + 1)
    want = start.copy()
    for _launch in range(4):
        centres = rng.integers(10, cells - 5000, 2)
        i = (centres[rng.integers(0, 2, n)] + rng.integers(0, 3000, n)).astype(np.int32)
        v = rng.integers(-8, 8, n).astype(np.float32)  # integers: exact in any order
        at.from_numpy(i)
        w.from_numpy(v)
        scatter()
        for k in range(4):
            np.add.at(want, i + k, v * (k + 1))
        got = a.to_numpy()
        np.testing.assert_array_equal(got, want)
        assert np.signbit(got[5])
        (count,) = _page_counts(scatter)
        assert 0 < count <= 4 * 2 * 4, count  # <= threads x clusters x pages a 3000-cell cluster can touch
    np.testing.assert_array_equal(b.to_numpy(), start + 1)
    assert "_private" in _text(scatter)


def test_copies_whose_pages_all_got_marked_give_way_to_atomics_at_the_next_launch():
    """Before a count the copies are taken if the updates outweigh an eighth of the copies' pages; a histogram
    over a whole 4 MB field then marks every page (of each thread that took part), and the next launch keeps its
    atomics (the count decays by 1/64 a launch that does). Both launches count exactly."""
    # work 100000 x 8 updates' worth: over the first guess (4 threads x 1024 pages / 8 x 1024 elements), under one
    # thread's marks on every page (1024 x 1024), however many threads took part in the first launch
    n, cells = 100_000, 1 << 20
    h = ti.field(ti.i32, shape=cells)
    at = ti.field(ti.i32, shape=n)

    @ti.kernel
    def histogram():
        for p in at:
            h[at[p]] += 1

    keys = np.random.default_rng(4).integers(0, cells, n).astype(np.int32)
    at.from_numpy(keys)
    assert _page_counts(histogram) == [-1]
    histogram()
    (first,) = _page_counts(histogram)
    assert first >= cells * 4 >> 12  # every page, by each thread that took a chunk
    histogram()
    assert _page_counts(histogram) == [first - (first >> 6)]
    np.testing.assert_array_equal(h.to_numpy(), 2 * np.bincount(keys, minlength=cells))
