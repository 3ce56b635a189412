"""Scatter privatisation of ndarray arguments (passes/privatize.py, codegen/privatize.py): a loop that only adds
into an ndarray gets per-thread zeroed copies of the whole array, sized at launch from its extents, chosen at run
time by the fields' rule (mpm88_graph's P2G into grid ndarrays: 27 CAS loops per particle at 2 threads before).
Results against numpy (integers exactly, floats against float64); which variant ran is read from the launcher's
holder of the copies (allocated only by the variant over copies)."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.fieldref import ArrayRef
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


@pytest.fixture(autouse=True)
def four_threads():
    ti.init(arch=ti.cpu, cpu_max_num_threads=4)  # privatisation needs > 1 thread, whatever the machine has
    yield


def _copies_made(kernel, args) -> bool:
    """Whether the variant over per-thread copies ran (it alone allocates them; they persist in the launcher).
    A region's holders: its copies, then its page maps (which the one-thread path allocates too)."""
    holders = kernel.instance(args).launcher._holders
    return bool(len(holders)) and bool(holders[0::2, 0].any())


def _array_forms(kernel, args) -> set:
    return {s.attrs["strategy"] for s in walk(kernel.instance(args).ir.body)
            if s.op is Op.ATOMIC and isinstance(s.operands[0].attrs.get("target"), ArrayRef)}


@ti.kernel
def _p2g(x: ti.types.ndarray(ndim=1), v: ti.types.ndarray(ndim=1), grid_v: ti.types.ndarray(ndim=2),
         grid_m: ti.types.ndarray(ndim=2), inv_dx: ti.f64):
    for p in x:
        xp = x[p] * inv_dx
        base = ti.cast(xp - 0.5, ti.i32)
        fx = xp - base
        w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
        for i, j in ti.static(ti.ndrange(3, 3)):
            offset = ti.Vector([i, j])
            weight = w[i].x * w[j].y
            grid_v[base + offset] += weight * v[p]
            grid_m[base + offset] += weight


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_p2g_into_vector_and_scalar_ndarrays_matches_numpy(dtype):
    n, g = 20_000, 16
    rng = np.random.default_rng(1)
    xs = rng.random((n, 2)) * 0.8 + 0.1
    vs = rng.standard_normal((n, 2))
    x = ti.Vector.ndarray(2, dtype, shape=n)
    v = ti.Vector.ndarray(2, dtype, shape=n)
    grid_v = ti.Vector.ndarray(2, dtype, shape=(g, g))
    grid_m = ti.ndarray(dtype, shape=(g, g))
    x.from_numpy(xs)
    v.from_numpy(vs)
    start_v, start_m = rng.standard_normal((g, g, 2)), rng.standard_normal((g, g))
    grid_v.from_numpy(start_v)
    grid_m.from_numpy(start_m)
    args = (x, v, grid_v, grid_m, float(g))
    _p2g(*args)

    xs, vs = x.to_numpy().astype(np.float64), v.to_numpy().astype(np.float64)  # the values the kernel saw
    base = (xs * g - 0.5).astype(np.int32)
    fx = xs * g - base
    w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
    gm, gv = start_m.astype(dtype.np).astype(np.float64), start_v.astype(dtype.np).astype(np.float64)
    for i in range(3):
        for j in range(3):
            wt = w[i][:, 0] * w[j][:, 1]
            np.add.at(gm, (base[:, 0] + i, base[:, 1] + j), wt)
            np.add.at(gv, (base[:, 0] + i, base[:, 1] + j), wt[:, None] * vs)
    tol = 1e-12 if dtype == ti.f64 else 2e-5
    np.testing.assert_allclose(grid_m.to_numpy(), gm, rtol=tol, atol=tol * np.abs(gm).max())
    np.testing.assert_allclose(grid_v.to_numpy(), gv, rtol=tol, atol=tol * np.abs(gv).max())
    assert _array_forms(_p2g, args) == {"private|atomic"}
    assert _copies_made(_p2g, args)
    assert "_private" in _p2g.instance(args).llvm_text


@pytest.mark.parametrize("shape,dtype,element", [
    ((37,), ti.i32, ()),
    ((5, 7), ti.i64, ()),
    ((3, 4, 5), ti.i32, (3,)),
    ((6, 5), ti.i64, (2, 3)),
])
def test_integer_scatter_is_exact_for_every_shape_and_element_type(shape, dtype, element):
    n = 60_000
    size = int(np.prod(shape))
    if element == ():
        hist = ti.ndarray(dtype, shape=shape)
    elif len(element) == 1:
        hist = ti.Vector.ndarray(element[0], dtype, shape=shape)
    else:
        hist = ti.Matrix.ndarray(element[0], element[1], dtype, shape=shape)
    rng = np.random.default_rng(len(shape))
    start = rng.integers(-50, 50, (*shape, *element))
    hist.from_numpy(start)
    keys = rng.integers(0, size, n).astype(np.int32)
    unravel = np.stack(np.unravel_index(keys, shape), axis=1).astype(np.int32)
    ncomp = int(np.prod(element)) if element else 1

    @ti.kernel
    def count(at: ti.types.ndarray(ndim=2), h: ti.types.ndarray(ndim=len(shape))):
        for p in range(n):
            idx = ti.Vector([at[p, d] for d in ti.static(range(len(shape)))])
            if ti.static(element == ()):
                h[idx] += 1
            elif ti.static(len(element) == 1):
                for c in ti.static(range(element[0])):
                    h[idx][c] += c + 1
            else:
                for r, c in ti.static(ti.ndrange(element[0], element[1])):
                    h[idx][r, c] += r * 10 + c + 1

    count(unravel, hist)
    per = np.bincount(keys, minlength=size).reshape(shape)
    if element == ():
        want = start + per
    else:
        weights = (np.arange(ncomp) + 1) if len(element) == 1 else \
            (np.arange(element[0])[:, None] * 10 + np.arange(element[1])[None, :] + 1)
        want = start + per.reshape(*shape, *([1] * len(element))) * weights
    np.testing.assert_array_equal(hist.to_numpy(), want)
    assert _copies_made(count, (unravel, hist))


@ti.kernel
def _histogram(keys: ti.types.ndarray(ndim=1), h: ti.types.ndarray(ndim=1)):
    for p in keys:
        h[keys[p]] += 1


@pytest.mark.parametrize("threads,n,cells,copies", [
    (4, 100_000, 64, True),  # many updates per element: per-thread copies
    (4, 20_000, 1 << 20, False),  # few updates into a large array: atomics
    (1, 100_000, 64, False),  # one thread: the array itself is thread 0's copy, plain updates
    (4, 3, 64, False),  # no more iterations than a grain: likewise
])
def test_the_run_time_rule_picks_each_variant_with_the_same_result(threads, n, cells, copies):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads)
    keys = np.random.default_rng(n).integers(0, cells, n).astype(np.int32)
    h = np.arange(cells, dtype=np.int32)
    _histogram(keys, h)
    np.testing.assert_array_equal(h, np.arange(cells) + np.bincount(keys, minlength=cells))
    assert _copies_made(_histogram, (keys, h)) == copies
    assert _array_forms(_histogram, (keys, h)) == {"private|atomic"}


def test_empty_and_one_element_ndarrays():
    n = 50_000
    keys = np.zeros(n, np.int32)
    one = np.array([7], np.int64)
    empty = np.zeros(0, np.int64)

    @ti.kernel
    def count(k: ti.types.ndarray(ndim=1), h: ti.types.ndarray(ndim=1), none: ti.types.ndarray(ndim=1)):
        for p in k:
            h[k[p]] += 2
            if k[p] < 0:  # never: the empty array is never updated, and no copy of it is made
                none[k[p]] += 1

    count(keys, one, empty)
    assert one[0] == 7 + 2 * n
    assert not _copies_made(count, (keys, one, empty))  # one region empty: the atomic variant
    bigger = np.array([1], np.int64)
    count(keys, bigger, np.zeros(3, np.int64))
    assert bigger[0] == 1 + 2 * n and _copies_made(count, (keys, one, empty))
    # a 0-size target with a 0-size loop
    count(np.zeros(0, np.int32), np.zeros(0, np.int64), empty)


def test_copies_follow_the_array_size_between_launches_and_in_a_graph():
    """One compiled kernel with arrays of 10, 5000 and 10 elements: the copies grow for the larger one (the old
    ones freed) and stay zero between launches; a ti.graph replays copied contexts, which share the copies."""
    rng = np.random.default_rng(4)

    def run(cells, n=40_000):
        keys = rng.integers(0, cells, n).astype(np.int32)
        h = np.zeros(cells, np.int32)
        _histogram(keys, h)
        np.testing.assert_array_equal(h, np.bincount(keys, minlength=cells))
        return keys

    small = run(10)
    holders = _histogram.instance((small, np.zeros(10, np.int32))).launcher._holders
    cap_small = int(holders[0, 1])
    run(5000)
    assert int(holders[0, 1]) > cap_small
    run(10)

    sym_k = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "k", ti.i32, ndim=1)
    sym_a = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "a", ti.i32, ndim=1)
    sym_b = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "b", ti.i32, ndim=1)
    builder = ti.graph.GraphBuilder()
    builder.dispatch(_histogram, sym_k, sym_a)
    builder.dispatch(_histogram, sym_k, sym_b)
    graph = builder.compile()
    keys = ti.ndarray(ti.i32, shape=60_000)
    keys.from_numpy(rng.integers(0, 8, 60_000).astype(np.int32))
    a, b = ti.ndarray(ti.i32, shape=8), ti.ndarray(ti.i32, shape=20_000)
    for runs in range(1, 4):
        graph.run({"k": keys, "a": a, "b": b})
        want = runs * np.bincount(keys.to_numpy(), minlength=8)
        np.testing.assert_array_equal(a.to_numpy(), want)
        np.testing.assert_array_equal(b.to_numpy(), np.pad(want, (0, 20_000 - 8)))


def test_a_component_the_loop_reads_stays_atomic_the_others_are_copied():
    """h[k][1] is read by the loop: never privatised (a copy would hide the updates from the read); h[k][0] is
    only added into, so the array is copied for it, and the final sum leaves component 1 as the atomics left it."""
    n, cells = 80_000, 16
    keys = np.random.default_rng(9).integers(0, cells, n).astype(np.int32)
    h = ti.Vector.ndarray(2, ti.i32, shape=cells)
    seen = np.zeros(n, np.int32)

    @ti.kernel
    def both(k: ti.types.ndarray(ndim=1), h: ti.types.ndarray(ndim=1), seen: ti.types.ndarray(ndim=1)):
        for p in k:
            h[k[p]][0] += 3
            seen[p] = ti.atomic_add(h[k[p]][1], 1)

    both(keys, h, seen)
    per = np.bincount(keys, minlength=cells)
    np.testing.assert_array_equal(h.to_numpy(), np.stack([3 * per, per], axis=1))
    for c in range(cells):
        np.testing.assert_array_equal(np.sort(seen[keys == c]), np.arange(per[c]))
    forms = sorted(s.attrs["strategy"] for s in walk(both.instance((keys, h, seen)).ir.body)
                   if s.op is Op.ATOMIC and isinstance(s.operands[0].attrs.get("target"), ArrayRef))
    assert forms == ["atomic", "private|atomic"]
    assert _copies_made(both, (keys, h, seen))


def test_debug_mode_checks_the_indices_of_a_privatised_scatter():
    ti.init(arch=ti.cpu, cpu_max_num_threads=4, debug=True)
    keys = np.random.default_rng(0).integers(0, 16, 100_000).astype(np.int32)
    h = np.zeros(16, np.int32)
    _histogram(keys, h)
    np.testing.assert_array_equal(h, np.bincount(keys, minlength=16))
    assert _copies_made(_histogram, (keys, h))
    keys[5] = 99
    with pytest.raises(ti.SimgradError, match="index 99 is out of bounds in dimension 0 of ndarray h"):
        _histogram(keys, h)
