"""Sparse SNode memory: pools under parallel activation and scatter, reuse after deactivation, what
memory_usage() reports, running out of a pool (an error, not a crash), and compiled kernels that must not
be shared between programs whose sparse nodes got other pools."""

import numpy as np
import pytest

import simgrad as ti


def _blocked(n=64, b=8):
    x = ti.field(ti.f32)
    blk = ti.root.pointer(ti.i, n // b)
    blk.dense(ti.i, b).place(x)
    return x, blk


def test_parallel_scatter_into_a_pointer_field_matches_numpy():
    """Many threads add into elements of a pointer field and activate its blocks as they go: every add
    lands once (no per-thread copies of a sparse field, whose addresses are not in the tree's buffer)."""
    x, blk = _blocked(4096, 16)
    rng = np.random.default_rng(5)
    targets = rng.integers(0, 4096 // 4, 200000).astype(np.int32) * 4  # a quarter of the blocks at most
    idx = ti.field(ti.i32, shape=targets.size)
    idx.from_numpy(targets)

    @ti.kernel
    def scatter():
        for k in idx:
            x[idx[k]] += 1.0

    scatter()
    want = np.bincount(targets, minlength=4096).astype(np.float32)
    np.testing.assert_array_equal(x.to_numpy(), want)
    touched_blocks = np.unique(targets // 16).size
    assert blk.memory_usage()["live_blocks"] == touched_blocks


def test_deactivated_blocks_are_reused():
    x, blk = _blocked(1024, 8)

    @ti.kernel
    def write(lo: ti.i32, hi: ti.i32):
        for i in range(lo, hi):
            x[i] = 1.0

    write(0, 512)
    use = blk.memory_usage()
    assert use["live_blocks"] == 64 and use["touched_blocks"] == 64
    blk.deactivate_all()  # the blocks go back to the pool's free list, zeroed
    assert blk.memory_usage()["live_blocks"] == 0
    write(512, 1024)
    use = blk.memory_usage()
    assert use["live_blocks"] == 64 and use["touched_blocks"] == 64
    assert x.to_numpy()[:512].sum() == 0 and x.to_numpy()[512:].sum() == 512

    @ti.kernel
    def drop_half():
        for b in blk:
            if b % 2 == 0:
                ti.deactivate(blk, [b])

    drop_half()
    write(0, 64)  # 8 blocks come back from the free list, not from fresh memory
    use = blk.memory_usage()
    assert use["live_blocks"] == 32 + 8 and use["touched_blocks"] == 64


def test_running_out_of_a_pool_is_a_located_error_and_the_program_goes_on():
    ti.init(arch=ti.cpu, device_memory_GB=2**-16)  # 16 KiB per pool: 64 blocks of 256 bytes
    x = ti.field(ti.f32)
    blk = ti.root.pointer(ti.i, 1024)
    blk.dense(ti.i, 64).place(x)

    @ti.kernel
    def fill(n: ti.i32):
        for i in range(n):
            x[i] = 1.0

    with pytest.raises(ti.SimgradRuntimeError, match="out of memory for pointer SNode blocks") as e:
        fill(64 * 100)
    assert "test_sparse_memory.py" in str(e.value)
    blk.deactivate_all()
    fill(64 * 48)  # well within the pool (threads take blocks 16 at a time: the cap is that approximate)
    assert x.to_numpy().sum() == 64 * 48


def test_kernel_cache_keys_pools(tmp_path):
    """The same kernel over the same layouts, in two programs whose sparse nodes were materialised in
    another order (so other pool ids, here pools of other block sizes): each must use its own pools (the
    kernel cache keys every node's pool)."""
    results = []
    for order in (0, 1):
        ti.init(arch=ti.cpu, offline_cache_file_path=str(tmp_path))
        a, b = ti.field(ti.f32), ti.field(ti.f32)
        fb_a = ti.FieldsBuilder()
        fb_a.pointer(ti.i, 8).dense(ti.i, 4).place(a)
        fb_b = ti.FieldsBuilder()
        fb_b.pointer(ti.i, 8).dense(ti.i, 64).place(b)
        first, second = (fb_a, fb_b) if order == 0 else (fb_b, fb_a)
        first.finalize()
        second.finalize()

        @ti.kernel
        def put():
            for i in range(32):
                a[i] = i + 1.0
            for i in range(512):
                b[i] = -i - 1.0

        put()
        results.append((a.to_numpy().copy(), b.to_numpy().copy()))
    for av, bv in results:
        np.testing.assert_array_equal(av, np.arange(32) + 1.0)
        np.testing.assert_array_equal(bv, -np.arange(512) - 1.0)


def test_nested_pointers_survive_deactivate_all_cycles():
    """Three pointer levels (Taichi's taichi_sparse.py layout): after deactivate_all every pool starts over
    on its freed blocks, whose first word held a free-list link; a block of slots must come back all null
    (a stale link there was followed as a child block: a crash)."""
    x = ti.field(ti.i32)
    b1 = ti.root.pointer(ti.ij, 8)
    b2 = b1.pointer(ti.ij, 4)
    b3 = b2.pointer(ti.ij, 4)
    b3.dense(ti.ij, 4).place(x)

    @ti.kernel
    def stripe(m: ti.i32):
        for i, j in ti.ndrange(512, 512):
            if (i + j) % m == 0:
                x[i, j] = 1

    @ti.kernel
    def total() -> ti.i32:
        c = 0
        for i, j in x:
            c += x[i, j]
        return c

    i, j = np.meshgrid(np.arange(512), np.arange(512), indexing="ij")
    for m in (7, 5, 7, 3):
        b1.deactivate_all()
        stripe(m)
        assert total() == int(((i + j) % m == 0).sum())
        np.testing.assert_array_equal(x.to_numpy(), ((i + j) % m == 0).astype(np.int32))


def test_fill_inside_a_kernel_writes_the_active_cells_only():
    x, blk = _blocked(64, 8)

    @ti.kernel
    def touch_and_fill(v: ti.f32):
        x[3] = 1.0
        x[40] = 2.0
        x.fill(v)

    touch_and_fill(5.0)
    want = np.zeros(64, np.float32)
    want[0:8] = want[40:48] = 5.0
    np.testing.assert_array_equal(x.to_numpy(), want)
    assert blk.memory_usage()["live_blocks"] == 2


def test_debug_mode_reports_an_out_of_bounds_sparse_index_at_the_users_line():
    ti.init(arch=ti.cpu, debug=True)
    x, _blk = _blocked(64, 8)

    @ti.kernel
    def poke(i: ti.i32):
        x[i] = 1.0

    poke(63)
    with pytest.raises(IndexError, match="Out of bound access") as e:
        poke(64)
    assert "test_sparse_memory.py" in str(e.value)
    assert x[63] == 1.0  # (the refused write went to index 0, as for dense fields: no wild address)
