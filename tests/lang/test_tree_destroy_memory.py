"""SNodeTree.destroy() returns the tree's memory (runtime/memory.py release): building and destroying large
trees in a loop keeps the process's resident memory flat, as Taichi's; neighbouring trees keep their values."""

import numpy as np

import simgrad as ti


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


def test_destroyed_trees_give_their_memory_back():
    ti.init(arch=ti.cpu)
    keep = ti.field(ti.f32, shape=1000)  # a small tree before them, sharing the first chunk
    keep.from_numpy(np.arange(1000, dtype=np.float32))
    start = _rss_mib()
    for _ in range(12):
        fb = ti.FieldsBuilder()
        big = ti.field(ti.f32)
        fb.dense(ti.i, 1 << 23).place(big)  # 32 MiB, every page touched by fill
        tree = fb.finalize()
        big.fill(1.0)
        assert big[12345] == 1.0
        tree.destroy()
    grown = _rss_mib() - start
    assert grown < 100, f"{grown:.0f} MiB kept after destroying 12 trees of 32 MiB"  # 384 MiB without release
    np.testing.assert_array_equal(keep.to_numpy(), np.arange(1000, dtype=np.float32))


def test_small_trees_destroyed_between_others_leave_the_others_intact():
    ti.init(arch=ti.cpu)
    fields, trees = [], []
    for k in range(6):
        fb = ti.FieldsBuilder()
        f = ti.field(ti.i32)
        fb.dense(ti.i, 5000).place(f)
        trees.append(fb.finalize())
        f.from_numpy(np.full(5000, k, np.int32))
        fields.append(f)
    for k in (1, 3, 4):
        trees[k].destroy()
    for k in (0, 2, 5):
        np.testing.assert_array_equal(fields[k].to_numpy(), np.full(5000, k, np.int32))
    fb = ti.FieldsBuilder()
    g = ti.field(ti.i32)
    fb.dense(ti.i, 5000).place(g)
    fb.finalize()

    @ti.kernel
    def add():
        for i in g:
            g[i] = fields[0][i] + fields[5][i] + i

    add()
    np.testing.assert_array_equal(g.to_numpy(), 5 + np.arange(5000))
