"""SIMT lanes with memory (passes/lanes_memory.py): a parallel loop whose iterations each run a counted loop to a
bound of their own, reading fields, storing to their own elements and running nested constant-trip loops, runs W
iterations in lock step. Every result must be bit for bit the one of the same kernel with the rewrite off
(ti.init(simt_lanes=0)): per-lane trip counts read from a field (0, small, the most), ranges no multiple of W, loads
at lane-varying indices that an off lane would take outside the field, own-element stores under an IF, a nested
constant loop, 2-D struct-fors, f32 and f64. Loops the rewrite must not touch are left alone, and the rewritten
step is vector code in the optimised LLVM IR. At the host's width (-1) only uniform counted loops are taken (a
tile's shared count and list: rows no multiple of the width, tiles of 4/8/16, other loop shapes), their shared loads
made once per trip; counts that may differ between lanes are left alone."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.runtime.jit import get_jit
from tests.passes.test_lanes import _both, _simt_loops, _task


def _rasterizer(w, h, ntri, dtype=ti.f32, tile=4, seed=0):
    """Taichi's rendering/rasterizer.py rasterize kernel (tiles of `tile` pixels, 2x2 sub-samples per pixel)."""
    samples = ti.Vector.field(3, dtype, shape=(w, h, 2, 2))
    pixels = ti.Vector.field(3, dtype, shape=(w, h))
    A, B, C = (ti.Vector.field(2, dtype) for _ in range(3))
    c0, c1, c2 = (ti.Vector.field(3, dtype) for _ in range(3))
    ti.root.dense(ti.i, ntri).place(A, B, C)
    ti.root.dense(ti.i, ntri).place(c0, c1, c2)
    tw, th = (w - 1) // tile + 1, (h - 1) // tile + 1
    count = ti.field(ti.i32, shape=(tw, th))
    which = ti.field(ti.i32, shape=(tw, th, ntri))

    @ti.func
    def point_in_triangle(P, A, B, C):
        alpha = -(P.x - B.x) * (C.y - B.y) + (P.y - B.y) * (C.x - B.x)
        alpha /= -(A.x - B.x) * (C.y - B.y) + (A.y - B.y) * (C.x - B.x)
        beta = -(P.x - C.x) * (A.y - C.y) + (P.y - C.y) * (A.x - C.x)
        beta /= -(B.x - C.x) * (A.y - C.y) + (B.y - C.y) * (A.x - C.x)
        gamma = 1.0 - alpha - beta
        result = alpha >= 0.0 and alpha <= 1.0 and beta >= 0.0 and beta <= 1.0 and gamma >= 0.0
        return result, alpha, beta, gamma

    @ti.kernel
    def rasterize():
        for i, j in pixels:
            for k in range(count[i // tile, j // tile]):
                idx = which[i // tile, j // tile, k]
                a, b, c = A[idx], B[idx], C[idx]
                d0, d1, d2 = c0[idx], c1[idx], c2[idx]
                for subi, subj in ti.ndrange(2, 2):
                    P = ti.Vector([i + (subi + 0.5) / 2, j + (subj + 0.5) / 2])
                    result, alpha, beta, gamma = point_in_triangle(P, a, b, c)
                    if result:
                        samples[i, j, subi, subj] = d0 * alpha + d1 * beta + d2 * gamma
            total = ti.Vector([0.0, 0.0, 0.0], dt=dtype)
            for subi, subj in ti.ndrange(2, 2):
                total += samples[i, j, subi, subj]
            pixels[i, j] = total / 4

    rng = np.random.default_rng(seed)
    for f, n in ((A, 2), (B, 2), (C, 2)):
        f.from_numpy((rng.random((ntri, n)) * [w, h]).astype(np.float32 if dtype is ti.f32 else np.float64))
    for f in (c0, c1, c2):
        f.from_numpy(rng.random((ntri, 3)).astype(np.float32 if dtype is ti.f32 else np.float64))
    # per tile a random subset of the triangles, in order: tiles with none, tiles with every one
    lists = np.zeros((tw, th, ntri), np.int32)
    counts = rng.integers(0, ntri + 1, (tw, th)).astype(np.int32)
    counts[0, 0], counts[-1, -1], counts[tw // 2, 0] = 0, ntri, ntri
    for ti_ in range(tw):
        for tj in range(th):
            pick = np.sort(rng.permutation(ntri)[:counts[ti_, tj]])
            lists[ti_, tj, :len(pick)] = pick
            lists[ti_, tj, len(pick):] = 1 << 30  # never read by an iteration: an off lane that did would fault
    count.from_numpy(counts)
    which.from_numpy(lists)
    samples.fill(1.0)
    rasterize()
    return [samples.to_numpy(), pixels.to_numpy()], rasterize, ()


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_rasterizer_bit_identical(dtype, threads):
    """Per-lane trip counts from a field (0 to all), gathers of triangles at lane-varying indices, own-element
    stores under an IF in a nested 2x2 loop, a 2-D struct-for over 37 x 29 pixels (no multiple of 8)."""
    (samples, pixels), kernel, args = _both(lambda: _rasterizer(37, 29, 7, dtype), threads,
                                            default_fp=dtype)
    (loop,) = _simt_loops(kernel, args)
    assert any(s.attrs.get("parallel_lanes") for s in walk(loop.blocks[0]))  # the step touches memory
    assert any(s.attrs.get("unroll") for s in walk(loop.blocks[0]))  # the sub-sample loop, unrolled whole
    assert (samples != 1.0).any() and (samples == 1.0).any()  # some sub-samples covered, some not


def test_rasterizer_step_is_vector_code():
    for lanes in (0, 8):
        ti.init(arch=ti.cpu, simt_lanes=lanes)
        _, kernel, args = _rasterizer(40, 40, 5)
        task = _task(kernel, args)
        vector_div = "fdiv nsz <8 x float>" in task
        assert vector_div == bool(lanes), task
        if lanes:
            assert "masked.gather" in task  # the triangles, at each lane's index
            assert "masked.scatter" not in task  # own elements through lane slots, not scattered


def test_host_width_leaves_lanes_own_counts_alone():
    """At the host's width (-1) a loop whose lanes count to bounds of their own is left alone: its lock step gathers
    at each lane's index, and on the machine measured (AMD Zen 5) a gather costs about a scalar load per element.
    3-pixel tiles: no power-of-two group of lanes shares a tile."""
    ti.init(arch=ti.cpu)
    _, kernel, args = _rasterizer(16, 16, 3, tile=3)
    assert not _simt_loops(kernel, args)


# -- uniform counted loops: the host's width -------------------------------------------------------------------
def _host_lanes(tile: int) -> int:
    return min(tile, max(8, get_jit().vector_bits() // 32))


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
@pytest.mark.parametrize("shape, tile", [((37, 29), 8), ((40, 24), 8), ((19, 45), 4), ((33, 17), 16)])
def test_host_width_runs_shared_tiles_once_per_group(shape, tile, dtype, threads):
    """Lanes of one tile share its triangle list: the group runs the counted loop once, loading each triangle once,
    and only the sub-sample tests per lane. Rows of 29, 45 and 17 pixels are no multiple of the width (groups cut
    per row, the last one short), 24 is (groups over the whole range); bit for bit the scalar loop's."""
    (samples, pixels), kernel, args = _both(lambda: _rasterizer(*shape, 7, dtype, tile=tile), threads, lanes=-1,
                                            default_fp=dtype)
    (loop,) = _simt_loops(kernel, args)
    assert loop.attrs["simt"] == _host_lanes(tile)
    assert (samples != 1.0).any() and (samples == 1.0).any()


def test_shared_tile_loads_are_scalar():
    """The triangles' loads are the group's, once per triangle (in the triangle loop, outside its lane loop), their
    tests vector code over the lanes; no scatter (own elements through lane slots)."""
    ti.init(arch=ti.cpu)
    _, kernel, args = _rasterizer(40, 40, 5, tile=8)
    (loop,) = _simt_loops(kernel, args)
    (guard,) = [s for s in loop.blocks[0].stmts if s.op is Op.IF]  # the triangle loop runs when it has trips
    (triangles,) = [s for s in guard.blocks[0].stmts if s.op is Op.RANGE_FOR and not s.attrs.get("lanes")]
    loads = [s for s in triangles.blocks[0].stmts if s.op is Op.GLOBAL_LOAD]
    assert len(loads) == 1 + 6 + 9  # the list entry, A B C, c0 c1 c2
    (lanes,) = [s for s in triangles.blocks[0].stmts if s.op is Op.RANGE_FOR]
    assert not any(s.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE) for s in walk(lanes.blocks[0]))
    task = _task(kernel, args)
    assert "masked.scatter" not in task
    assert f"fdiv nsz <{_host_lanes(8)} x float>" in task, task


@pytest.mark.parametrize("what", ["ndrange_offsets", "flat", "three_d", "field_offset", "tile_in_loop"])
def test_uniform_counts_in_other_loop_shapes(what):
    """ndrange bounds that start off 0 (j = digit + 8: aligned for at most 8 lanes, its // 4 for 4), a 1-D range,
    a 3-D struct-for's innermost axis, a field with an index offset; per-lane arithmetic on a shared list's
    entries, a local carried through the loop, own elements stored after it."""
    def build():
        lst = ti.field(ti.i32, shape=(40, 40, 6))
        cnt = ti.field(ti.i32, shape=(40, 40))
        tab = ti.field(ti.f32, shape=16)
        out = ti.field(ti.f32, shape=(40, 40))
        flat = ti.field(ti.f32, shape=203)
        cube = ti.field(ti.f32, shape=(3, 5, 20))
        shifted = ti.field(ti.f32, shape=(6, 20), offset=(-2, -4))

        @ti.func
        def walk_list(a, b, x):
            acc = x * 0.01
            for t in range(cnt[a, b]):
                acc = acc * 0.5 + tab[lst[a, b, t]] * (x - t)
            return acc

        @ti.kernel
        def k():
            if ti.static(what == "ndrange_offsets"):
                for i, j in ti.ndrange((2, 30), (8, 27)):
                    out[i, j] = walk_list(i, j // 4, j)
            if ti.static(what == "flat"):
                for p in range(203):
                    flat[p] = walk_list(p // 16, 3, p)
            if ti.static(what == "three_d"):
                for i, j, m in cube:
                    cube[i, j, m] = walk_list(i + j, m // 4, m + i)
            if ti.static(what == "field_offset"):
                for i, j in shifted:
                    shifted[i, j] = walk_list(i + 2, (j + 4) // 4, j)
            if ti.static(what == "tile_in_loop"):  # (j + 4) // 4 - 1: first computed inside the counted loop
                for i, j in out:
                    acc = j * 0.01
                    for t in range(cnt[i, 3]):
                        acc = acc * 0.5 + tab[lst[i, (j + 4) // 4 - 1, t]] * (j - t)
                    out[i, j] = acc

        rng = np.random.default_rng(11)
        lst.from_numpy(rng.integers(0, 16, (40, 40, 6)).astype(np.int32))
        cnt.from_numpy(rng.integers(0, 7, (40, 40)).astype(np.int32))
        tab.from_numpy(rng.uniform(-1, 1, 16).astype(np.float32))
        k()
        return [out.to_numpy(), flat.to_numpy(), cube.to_numpy(), shifted.to_numpy()], k, ()

    arrays, kernel, args = _both(build, lanes=-1)
    (loop,) = _simt_loops(kernel, args)
    assert loop.attrs["simt"] == {"ndrange_offsets": 4, "flat": _host_lanes(16), "three_d": 4,
                                  "field_offset": 4, "tile_in_loop": 4}[what]
    assert any(a.any() for a in arrays)


@pytest.mark.parametrize("index", ["(j + 1) // 8", "j // 8 + j % 2", "lst[i, j, 0] // 8"])
def test_counts_that_differ_between_lanes_are_left_alone(index):
    """A tile index off the groups' alignment, one that mixes in the lane's parity, or read at the lane's own
    element: the lanes' counts may differ, so the host's width leaves the loop alone."""
    ti.init(arch=ti.cpu)
    lst = ti.field(ti.i32, shape=(16, 16, 4))
    cnt = ti.field(ti.i32, shape=(16, 16))
    out = ti.field(ti.f32, shape=(16, 16))
    @ti.func
    def tile(i, j):
        v = 0
        if ti.static(index == "(j + 1) // 8"):
            v = (j + 1) // 8
        if ti.static(index == "j // 8 + j % 2"):
            v = j // 8 + j % 2
        if ti.static(index == "lst[i, j, 0] // 8"):
            v = lst[i, j, 0] // 8
        return v

    @ti.kernel
    def k():
        for i, j in out:
            acc = 0.0
            for t in range(cnt[i, ti.min(tile(i, j), 15)]):
                acc += lst[i, 3, t]
            out[i, j] = acc

    cnt.fill(2)
    k()
    assert not _simt_loops(k, ())
    assert (out.to_numpy() == 0).all()


def _guarded_list():
    """lst (M entries) with a sentinel right after it in memory, so lst[M] reads the sentinel: a huge index."""
    M = 8
    lst = ti.field(ti.i32)
    sentinel = ti.field(ti.i32)
    ti.root.dense(ti.i, M).place(lst)
    ti.root.place(sentinel)
    sentinel[None] = (1 << 31) - 1  # (materialises the tree)
    lay, sl = lst.ref().layout, sentinel.ref().layout
    assert lay[0] == sl[0] and sl[1] == lay[1] + 4 * M, (lay, sl)  # lst[M] is the sentinel
    return M, lst


def test_off_lanes_never_read_outside_a_field():
    """A lane whose count is the list's length ends at t = M: the lock step still evaluates its body (off), so
    lst[t] would read one past the list (the sentinel) and tab[sentinel] 8 GiB past tab, which faults. The
    indices of an off lane's loads are the field's first element instead. (Without the select the process dies.)"""
    def build():
        M, lst = _guarded_list()
        tab = ti.field(ti.f32, shape=16)
        cnt = ti.field(ti.i32, shape=101)
        out = ti.field(ti.f32, shape=101)

        @ti.kernel
        def k():
            for i in out:
                s = 0.0
                for t in range(cnt[i]):
                    s = s * 0.5 + tab[lst[t]] * (t + 1)
                out[i] = s

        lst.from_numpy(np.arange(8, dtype=np.int32) * 2 % 16)
        tab.from_numpy(np.linspace(-1, 2, 16, dtype=np.float32))
        c = np.random.default_rng(3).integers(0, M + 1, 101).astype(np.int32)
        c[:10] = M  # a whole group at the most
        cnt.from_numpy(c)
        k()
        return [out.to_numpy()], k, ()

    (out,), kernel, args = _both(build)
    assert len(_simt_loops(kernel, args)) == 1
    assert out.any()


@pytest.mark.parametrize("threads", [1, 2])
def test_counted_loop_with_run_time_bounds_continue_and_break(threads):
    def build():
        lo = ti.field(ti.i32, shape=203)
        hi = ti.field(ti.i32, shape=203)
        w = ti.field(ti.f64, shape=64)
        out = ti.field(ti.f64, shape=203)
        hits = ti.field(ti.i32, shape=203)

        @ti.kernel
        def k(scale: ti.f64):
            for i in out:
                acc = ti.cast(i, ti.f64) * 0.01
                n = 0
                for t in range(lo[i], hi[i]):  # empty, backwards, long ranges
                    v = w[t % 64] * scale
                    if v < 0.1:
                        continue
                    acc = acc * 0.9 + v
                    n += 1
                    if acc > 50.0:
                        break
                    if n % 3 == 0:
                        hits[i] = n  # an own element, stored under a condition in the counted loop
                out[i] = acc

        rng = np.random.default_rng(5)
        a = rng.integers(-5, 40, 203).astype(np.int32)
        lo.from_numpy(a)
        hi.from_numpy((a + rng.integers(-3, 120, 203)).astype(np.int32))
        w.from_numpy(rng.uniform(-1, 3, 64))
        k(1.25)
        return [out.to_numpy(), hits.to_numpy()], k, (1.25,)

    (out, hits), kernel, args = _both(build, threads, default_fp=ti.f64)
    assert len(_simt_loops(kernel, args)) == 1
    assert hits.any() and not hits.all()


def test_while_reading_a_field_and_storing_its_own_element():
    """A data-dependent while (not counted) that reads a read-only table and stores the iteration's own element."""
    def build():
        table = ti.field(ti.f32, shape=(5, 7))
        trace = ti.field(ti.f32, shape=(90, 4))

        @ti.kernel
        def k():
            for i in range(90):
                x = ti.cast(i, ti.f32) * 0.05
                m = 0
                while x < 4.0 and m < 30:
                    x += table[m % 5, i % 7]
                    if m < 4:
                        trace[i, m] = x
                    m += 1

        table.from_numpy(np.random.default_rng(7).uniform(0.01, 0.5, (5, 7)).astype(np.float32))
        k()
        return [trace.to_numpy()], k, ()

    _, kernel, args = _both(build)
    assert len(_simt_loops(kernel, args)) == 1


@pytest.mark.parametrize("what", ["store_elsewhere", "read_written_elsewhere", "atomic", "ndarray"])
def test_loops_that_do_not_qualify_are_left_alone(what):
    def build():
        x = ti.field(ti.f32, shape=64)
        y = ti.field(ti.f32, shape=64)
        hist = ti.field(ti.i32, shape=8)
        cnt = ti.field(ti.i32, shape=64)
        arr = ti.ndarray(ti.f32, shape=64)

        @ti.kernel
        def k(a: ti.types.ndarray()):
            for i in x:
                s = 0.0
                for t in range(cnt[i]):
                    if ti.static(what == "store_elsewhere"):
                        y[(i + t) % 64] = s  # another iteration's element
                    if ti.static(what == "read_written_elsewhere"):
                        s += x[(i + 1) % 64]  # x is written below, at i
                    if ti.static(what == "atomic"):
                        hist[t % 8] += 1
                    if ti.static(what == "ndarray"):
                        s += a[t]  # (ndarray loads are not made safe for off lanes: left alone)
                    s = s * 0.5 + t
                x[i] = s

        cnt.from_numpy(np.arange(64, dtype=np.int32) % 9)
        x.from_numpy(np.linspace(0, 1, 64, dtype=np.float32))
        arr.from_numpy(np.linspace(0, 1, 64, dtype=np.float32))
        k(arr)
        return [x.to_numpy(), y.to_numpy(), hist.to_numpy()], k, (arr,)

    _, kernel, args = _both(build)
    assert not _simt_loops(kernel, args)
