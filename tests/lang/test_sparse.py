"""Sparse SNodes (pointer, bitmasked, dynamic): acceptance tests pinned to Taichi 1.7.4's semantics.

Every fact asserted here was checked against real Taichi 1.7.4 on the CPU (see /work/notes/sparse_semantics.md for
the probes). The rules they encode:

* every SNode has its own index space, ``snode.shape`` (cells from the root along each axis): ``ti.activate``,
  ``ti.deactivate``, ``ti.is_active`` and ``for I in snode`` use the coordinates of *that* SNode (block coordinates for
  a pointer over 8x8 dense blocks, element coordinates for the dense node under it);
* a write (kernel or Python scope) activates the whole path to the cell: under a pointer the whole dense block
  becomes active and a struct-for over the field visits all its cells; under a bitmasked node only the cell;
* reads never activate; reading under an inactive pointer gives 0;
* ``to_numpy``, ``from_numpy`` and ``fill`` are struct-fors over the active cells (from_numpy/fill activate nothing);
* deactivating a pointer cell frees its block (re-activation gives zeros); deactivating a bitmasked cell only clears
  its mask bit (the value is still readable and comes back on re-activation);
* ``ti.append`` returns the old length; writing ``w[i, j]`` directly extends the length to ``j + 1``.

Taichi-wrong cases: none in this module (see TAICHI_WRONG in tests/autodiff/test_ad_sparse.py). The set exists so a
run of this file under real Taichi (through a shim module named simgrad) can skip documented Taichi bugs. To run
both files under Taichi 1.7.4:

    mkdir -p /tmp/tishim/simgrad /tmp/tirun
    printf 'import sys\nimport taichi\nsys.modules[__name__] = taichi\n' > /tmp/tishim/simgrad/__init__.py
    # /tmp/tirun/conftest.py: an autouse fixture that skips request.node.originalname if it is in the module's
    # TAICHI_WRONG, then ti.init(arch=ti.cpu); yield; ti.reset()
    cp tests/lang/test_sparse.py tests/autodiff/test_ad_sparse.py /tmp/tirun/ && cd /tmp/tirun && \
        PYTHONPATH=/tmp/tishim /work/tivenv/bin/python -m pytest -p no:cacheprovider -q .
"""

import numpy as np
import pytest

import simgrad as ti

TAICHI_WRONG: set[str] = set()


def _pointer_2d(dtype=ti.f32, nb=4, bs=8):
    """x of shape (nb*bs, nb*bs) under ti.root.pointer(ti.ij, nb).dense(ti.ij, bs); returns (x, blk, dense)."""
    x = ti.field(dtype)
    blk = ti.root.pointer(ti.ij, nb)
    dn = blk.dense(ti.ij, bs)
    dn.place(x)
    return x, blk, dn


def _visited(f, n_axes=2):
    """Sorted list of the index tuples a struct-for over `f` (a field or an SNode) visits, and the visit count."""
    shape = f.shape
    mark = ti.field(ti.i32, shape=shape)

    if n_axes == 1:

        @ti.kernel
        def visit1(s: ti.template()):
            for i in s:
                mark[i] += 1

        visit1(f)
    else:

        @ti.kernel
        def visit2(s: ti.template()):
            for i, j in s:
                mark[i, j] += 1

        visit2(f)
    m = mark.to_numpy()
    assert m.max(initial=0) <= 1, "a struct-for visited a cell twice"
    return sorted(tuple(int(v) for v in idx) for idx in np.argwhere(m))


def _block_cells(blocks, bs=8):
    return sorted((bi * bs + di, bj * bs + dj) for bi, bj in blocks for di in range(bs) for dj in range(bs))


# ---------------------------------------------------------------------------------------------------------------
# layout


def test_shapes_of_sparse_layouts():
    x, blk, dn = _pointer_2d()
    y = ti.field(ti.i32)
    ti.root.pointer(ti.i, 4).pointer(ti.i, 4).place(y)
    z = ti.field(ti.i32)
    bm = ti.root.dense(ti.i, 4).bitmasked(ti.j, 8)
    bm.place(z)
    w = ti.field(ti.i32)
    dyn = ti.root.dense(ti.i, 4).dynamic(ti.j, 32, chunk_size=8)
    dyn.place(w)
    assert x.shape == (32, 32)
    assert y.shape == (16,)
    assert z.shape == (4, 8)
    assert w.shape == (4, 32)  # the dynamic axis reports max_len, not the current length
    assert blk.shape == (4, 4)
    assert dn.shape == (32, 32)
    assert x.snode.shape == (32, 32)
    assert bm.shape == (4, 8)
    assert bm.parent().shape == (4,)
    assert dyn.shape == (4, 32)
    assert y.parent().shape == (16,)
    assert y.parent(2).shape == (4,)


def test_parent_navigation():
    x, blk, dn = _pointer_2d()
    assert x.parent() == dn
    assert x.snode.parent() == dn
    assert x.parent(2) == blk
    assert x.snode.parent(2) == blk
    assert x.snode.parent(0) == x.snode
    assert x.parent(3) is ti.root
    assert x.parent(4) is None
    assert blk.parent() is ti.root
    assert dn.parent() == blk


# ---------------------------------------------------------------------------------------------------------------
# activation by writes, reads, is_active


def test_kernel_write_activates_the_whole_pointer_block():
    x, blk, _ = _pointer_2d()

    @ti.kernel
    def write():
        x[3, 5] = 1.0

    write()
    assert _visited(x) == _block_cells([(0, 0)])
    assert _visited(blk) == [(0, 0)]


def test_python_scope_writes_activate_blocks():
    x, blk, _ = _pointer_2d()
    x[20, 20] = 2.0
    x[3, 5] += 1.0
    assert _visited(x) == _block_cells([(0, 0), (2, 2)])
    assert x[20, 20] == 2.0 and x[3, 5] == 1.0
    assert x[4, 4] == 0.0  # an untouched cell of an active block


def test_bitmasked_write_activates_only_that_cell():
    z = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).bitmasked(ti.j, 8).place(z)

    @ti.kernel
    def write():
        z[1, 3] = 5

    write()
    assert _visited(z) == [(1, 3)]
    z[0, 0] = 3
    assert _visited(z) == [(0, 0), (1, 3)]


def test_pointer_over_bitmasked_granularity():
    """pointer(4).bitmasked(4): a write activates the pointer cell and one bit; the field's struct-for visits the
    written cell only, a struct-for over the pointer visits its block (in block coordinates)."""
    z = ti.field(ti.i32)
    ptr = ti.root.pointer(ti.i, 4)
    ptr.bitmasked(ti.i, 4).place(z)
    z[5] = 1
    z[14] = 2
    assert _visited(z, 1) == [(5,), (14,)]
    assert _visited(ptr, 1) == [(1,), (3,)]
    assert _visited(z.parent(), 1) == [(5,), (14,)]


def test_is_active_takes_the_snodes_own_coordinates():
    x, blk, _ = _pointer_2d()
    x[20, 9] = 1.0

    @ti.kernel
    def active(i: ti.i32, j: ti.i32) -> ti.i32:
        return ti.is_active(blk, [i, j])

    got = np.array([[active(i, j) for j in range(4)] for i in range(4)])
    want = np.zeros((4, 4), int)
    want[20 // 8, 9 // 8] = 1
    assert np.array_equal(got, want)


def test_is_active_bitmasked():
    z = ti.field(ti.f32)
    bm = ti.root.dense(ti.i, 4).bitmasked(ti.j, 8)
    bm.place(z)
    z[2, 6] = 1.0

    @ti.kernel
    def active(i: ti.i32, j: ti.i32) -> ti.i32:
        return ti.is_active(bm, [i, j])

    got = np.array([[active(i, j) for j in range(8)] for i in range(4)])
    want = np.zeros((4, 8), int)
    want[2, 6] = 1
    assert np.array_equal(got, want)


def test_is_active_on_a_dense_node_is_an_error():
    x, _, dn = _pointer_2d()

    @ti.kernel
    def active() -> ti.i32:
        return ti.is_active(dn, [0, 0])

    with pytest.raises(ti.TaichiCompilationError):
        active()


def test_reads_of_inactive_cells_are_zero_and_do_not_activate():
    x, blk, _ = _pointer_2d()
    z = ti.field(ti.f32)
    ti.root.dense(ti.i, 4).bitmasked(ti.j, 8).place(z)
    x[3, 5] = 1.5
    z[1, 1] = 2.5

    @ti.kernel
    def read_x(i: ti.i32, j: ti.i32) -> ti.f32:
        return x[i, j]

    @ti.kernel
    def read_z(i: ti.i32, j: ti.i32) -> ti.f32:
        return z[i, j]

    @ti.kernel
    def sum_all() -> ti.f32:
        s = 0.0
        for i, j in ti.ndrange(32, 32):
            s += x[i, j]
        for i in range(4):
            for j in range(z.shape[1]):
                s += z[i, j]
        return s

    assert read_x(20, 20) == 0.0
    assert x[31, 0] == 0.0
    assert read_z(3, 7) == 0.0
    assert z[0, 2] == 0.0
    assert sum_all() == 4.0
    assert _visited(x) == _block_cells([(0, 0)])
    assert _visited(z) == [(1, 1)]


# ---------------------------------------------------------------------------------------------------------------
# to_numpy / from_numpy / fill


def test_to_numpy_is_zero_where_inactive():
    x, _, _ = _pointer_2d()
    x.fill(5.0)  # nothing active: nothing written
    x[3, 5] = 1.0
    x[20, 20] = 2.0
    want = np.zeros((32, 32), np.float32)
    want[3, 5] = 1.0
    want[20, 20] = 2.0
    got = x.to_numpy()
    assert got.dtype == np.float32 and got.shape == (32, 32)
    assert np.array_equal(got, want)


def test_fill_writes_active_cells_only():
    x, _, _ = _pointer_2d()
    z = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).bitmasked(ti.j, 8).place(z)
    x[3, 5] = 1.0
    x[20, 20] = 2.0
    z[1, 3] = 1
    z[2, 0] = 1
    x.fill(7.0)
    z.fill(9)
    want = np.zeros((32, 32), np.float32)
    want[0:8, 0:8] = 7.0
    want[16:24, 16:24] = 7.0
    assert np.array_equal(x.to_numpy(), want)
    wz = np.zeros((4, 8), np.int32)
    wz[1, 3] = wz[2, 0] = 9
    assert np.array_equal(z.to_numpy(), wz)
    assert _visited(x) == _block_cells([(0, 0), (2, 2)])
    assert _visited(z) == [(1, 3), (2, 0)]


def test_from_numpy_writes_active_cells_only():
    """Taichi's from_numpy is a struct-for over the active cells: values at inactive cells are dropped and nothing
    is activated, even where the array is non-zero."""
    x, _, _ = _pointer_2d()
    x[3, 5] = 4.0
    a = np.arange(32 * 32, dtype=np.float32).reshape(32, 32) + 1.0
    x.from_numpy(a)
    want = np.zeros((32, 32), np.float32)
    want[0:8, 0:8] = a[0:8, 0:8]
    assert np.array_equal(x.to_numpy(), want)
    assert _visited(x) == _block_cells([(0, 0)])
    assert x[31, 31] == 0.0

    z = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).bitmasked(ti.j, 8).place(z)
    z[2, 2] = 1
    z.from_numpy(np.full((4, 8), 6, np.int32))
    wz = np.zeros((4, 8), np.int32)
    wz[2, 2] = 6
    assert np.array_equal(z.to_numpy(), wz)
    assert _visited(z) == [(2, 2)]


# ---------------------------------------------------------------------------------------------------------------
# struct-fors over SNodes, nested loops, rescale_index


def test_struct_for_over_pointer_gives_block_coordinates():
    x, blk, dn = _pointer_2d()
    x[3, 5] = 1.0
    x[20, 9] = 2.0
    assert _visited(blk) == [(0, 0), (2, 1)]
    assert _visited(dn) == _block_cells([(0, 0), (2, 1)])  # the dense node under the pointer: element coordinates

    got = ti.field(ti.i32, shape=(4, 2))
    n = ti.field(ti.i32, shape=())

    @ti.kernel
    def grouped():
        for I in ti.grouped(blk):
            k = ti.atomic_add(n[None], 1)
            got[k, 0] = I[0]
            got[k, 1] = I[1]

    grouped()
    assert n[None] == 2
    assert sorted(map(tuple, got.to_numpy()[:2].tolist())) == [(0, 0), (2, 1)]


def test_struct_for_over_pointer_writes_through_block_coordinates():
    x, blk, _ = _pointer_2d(ti.i32)
    x[3, 5] = 1
    x[20, 9] = 1

    @ti.kernel
    def corner():
        for bi, bj in blk:
            x[bi * 8 + 7, bj * 8 + 7] += 10

    corner()
    want = np.zeros((32, 32), np.int32)
    want[3, 5] = want[20, 9] = 1
    want[7, 7] += 10
    want[23, 15] += 10
    assert np.array_equal(x.to_numpy(), want)


def test_nested_loop_over_parent_snode_blocks():
    """Taichi has no nested struct-fors; the idiom is a struct-for over the pointer and a range-for over the
    block's cells."""
    x, blk, _ = _pointer_2d()
    rng = np.random.default_rng(3)
    ref = np.zeros((32, 32), np.float32)
    for i, j in rng.integers(0, 32, size=(6, 2)):
        v = float(rng.integers(1, 100))
        x[i, j] = v
        ref[i, j] = v
    block_sums = ti.field(ti.f32, shape=(4, 4))
    cells = ti.field(ti.i32, shape=())

    @ti.kernel
    def per_block():
        for bi, bj in blk:
            for di, dj in ti.ndrange(8, 8):
                I = ti.Vector([bi, bj]) * 8 + ti.Vector([di, dj])
                block_sums[bi, bj] += x[I]
                cells[None] += 1

    per_block()
    want = ref.reshape(4, 8, 4, 8).sum(axis=(1, 3))
    active_blocks = {(int(i) // 8, int(j) // 8) for i, j in np.argwhere(ref)}
    assert np.array_equal(block_sums.to_numpy(), want)
    assert cells[None] == 64 * len(active_blocks)


def test_rescale_index():
    x, blk, _ = _pointer_2d()
    out = ti.field(ti.i32, shape=4)
    marks = ti.field(ti.i32, shape=(32, 32))

    @ti.kernel
    def down(i: ti.i32, j: ti.i32):
        b = ti.rescale_index(x, blk, [i, j])
        out[0] = b[0]
        out[1] = b[1]
        c = ti.rescale_index(x, blk, ti.Vector([i, j]))
        out[2] = c[0]
        out[3] = c[1]

    down(9, 17)
    assert out.to_numpy().tolist() == [1, 2, 1, 2]
    down(31, 0)
    assert out.to_numpy().tolist() == [3, 0, 3, 0]
    x[20, 9] = 1.0
    x[3, 3] = 1.0

    @ti.kernel
    def up():
        for I in ti.grouped(blk):
            marks[ti.rescale_index(blk, x, I)] = 1  # coarse -> fine: the block's first element

    up()
    assert sorted(map(tuple, np.argwhere(marks.to_numpy()).tolist())) == [(0, 0), (16, 8)]


def test_official_explicit_activation_example():
    """python/taichi/examples/features/sparse/explicit_activation.py: two pointer levels over a dense leaf."""
    x = ti.field(ti.i32)
    block1 = ti.root.pointer(ti.ij, (4, 4))
    block2 = block1.pointer(ti.ij, (2, 2))
    block2.dense(ti.ij, (2, 2)).place(x)
    act = ti.field(ti.i32, shape=4)
    res = ti.field(ti.i32, shape=4)

    @ti.kernel
    def demo():
        ti.activate(block1, [0, 1])
        ti.activate(block2, [1, 2])
        for j in range(4):
            act[j] = ti.is_active(block2, [1, j])
        r = ti.rescale_index(x, block1, ti.Vector([9, 17]))
        res[0] = r[0]
        res[1] = r[1]

    demo()
    assert _visited(x) == [(2, 4), (2, 5), (3, 4), (3, 5)]
    assert _visited(block2) == [(1, 2)]
    assert _visited(block1) == [(0, 1)]
    assert act.to_numpy().tolist() == [0, 0, 1, 0]
    assert res.to_numpy()[:2].tolist() == [2, 4]

    @ti.kernel
    def check(s: ti.template(), i: ti.i32, j: ti.i32) -> ti.i32:
        return ti.is_active(s, [i, j])

    assert check(block2, 1, 2) == 1
    block2.deactivate_all()
    assert check(block2, 1, 2) == 0
    assert check(block1, 0, 1) == 1
    ti.deactivate_all_snodes()
    assert check(block1, 0, 1) == 0


def test_nested_pointers_activated_top_down_and_deactivated_from_the_parent():
    """Activate the outer pointer cell, then the inner one (Taichi 1.7.4 does not activate inactive ancestors on
    ti.activate(child, I): the child then reports is_active 1 but no struct-for visits it; not tested). Deactivating
    the outer cell hides everything under it."""
    x = ti.field(ti.i32)
    b1 = ti.root.pointer(ti.i, 4)
    b2 = b1.pointer(ti.i, 4)
    b2.dense(ti.i, 2).place(x)

    @ti.kernel
    def act():
        ti.activate(b1, [3])
        ti.activate(b2, [13])

    @ti.kernel
    def deact_outer():
        ti.deactivate(b1, [3])

    act()
    assert _visited(b1, 1) == [(3,)]
    assert _visited(b2, 1) == [(13,)]
    assert _visited(x, 1) == [(26,), (27,)]
    x[26] = 5
    x[3] = 1  # activates b1[0] and b2[1] through the write
    assert _visited(b1, 1) == [(0,), (3,)]
    assert _visited(b2, 1) == [(1,), (13,)]
    deact_outer()
    assert _visited(b1, 1) == [(0,)]
    assert _visited(b2, 1) == [(1,)]
    assert _visited(x, 1) == [(2,), (3,)]
    assert x[26] == 0 and x[3] == 1


# ---------------------------------------------------------------------------------------------------------------
# activate / deactivate


def test_pointer_deactivate_frees_the_block_and_reactivation_is_zero():
    x, blk, _ = _pointer_2d()

    @ti.kernel
    def act(i: ti.i32, j: ti.i32):
        ti.activate(blk, [i, j])

    @ti.kernel
    def deact(i: ti.i32, j: ti.i32):
        ti.deactivate(blk, [i, j])

    x[3, 5] = 1.5
    x[20, 20] = 2.5
    deact(0, 0)
    assert x[3, 5] == 0.0
    assert _visited(x) == _block_cells([(2, 2)])
    act(0, 0)
    assert _visited(x) == _block_cells([(0, 0), (2, 2)])
    assert x[3, 5] == 0.0  # a fresh block
    x[3, 5] = 2.0
    act(0, 0)  # activating an active cell changes nothing
    assert x[3, 5] == 2.0
    act(3, 3)
    assert _visited(blk) == [(0, 0), (2, 2), (3, 3)]
    assert x[31, 31] == 0.0
    for _ in range(3):  # recycled blocks come back zeroed
        x[8, 8] = 9.0
        deact(1, 1)
        act(1, 1)
        assert x[8, 8] == 0.0
    assert x[20, 20] == 2.5


def test_bitmasked_deactivate_hides_the_cell_but_keeps_its_value():
    """Taichi 1.7.4: deactivating a bitmasked cell clears its mask bit only. Struct-fors and to_numpy skip it, yet a
    direct read still returns the stored value, and re-activation brings it back."""
    z = ti.field(ti.f32)
    bm = ti.root.dense(ti.i, 4).bitmasked(ti.j, 8)
    bm.place(z)

    @ti.kernel
    def act(i: ti.i32, j: ti.i32):
        ti.activate(bm, [i, j])

    @ti.kernel
    def deact(i: ti.i32, j: ti.i32):
        ti.deactivate(bm, [i, j])

    z[1, 3] = 4.5
    deact(1, 3)
    assert _visited(z) == []
    assert z.to_numpy()[1, 3] == 0.0
    assert z[1, 3] == 4.5
    act(1, 3)
    assert _visited(z) == [(1, 3)]
    assert z[1, 3] == 4.5
    act(2, 2)  # a never-written cell reads 0
    assert z[2, 2] == 0.0
    assert _visited(z) == [(1, 3), (2, 2)]


def test_activate_and_deactivate_on_a_dense_node_do_nothing():
    x, _, dn = _pointer_2d()
    x[3, 5] = 1.0

    @ti.kernel
    def act():
        ti.activate(dn, [30, 30])

    @ti.kernel
    def deact():
        ti.deactivate(dn, [3, 5])

    act()
    deact()
    assert _visited(x) == _block_cells([(0, 0)])
    assert x[3, 5] == 1.0


def test_struct_for_after_deactivate():
    x, blk, _ = _pointer_2d(ti.i32)
    for i, j in [(1, 1), (9, 9), (17, 17), (25, 25), (25, 1)]:
        x[i, j] = 1

    @ti.kernel
    def deact_diagonal():
        for bi, bj in blk:
            if bi == bj:
                ti.deactivate(blk, [bi, bj])

    deact_diagonal()
    assert _visited(blk) == [(3, 0)]
    assert _visited(x) == _block_cells([(3, 0)])

    @ti.kernel
    def total() -> ti.i32:
        s = 0
        for i, j in x:
            s += x[i, j]
        return s

    assert total() == 1


def _mirror_rounds(kind: str, seed: int):
    """Random writes / activations / deactivations over several rounds, checked after every step against a numpy
    mirror (values and active cells)."""
    rng = np.random.default_rng(seed)
    nb, bs = 4, 4
    n = nb * bs
    x = ti.field(ti.i32)
    if kind == "pointer":
        node = ti.root.pointer(ti.ij, nb)
        node.dense(ti.ij, bs).place(x)
        gran = bs  # activity is per block
    else:
        node = ti.root.dense(ti.ij, nb).bitmasked(ti.ij, bs)
        node.place(x)
        gran = 1
    k_max = 24
    idx = ti.field(ti.i32, shape=(k_max, 2))
    val = ti.field(ti.i32, shape=k_max)
    count = ti.field(ti.i32, shape=())

    @ti.kernel
    def write(k: ti.i32):
        for t in range(k):
            x[idx[t, 0], idx[t, 1]] = val[t]

    @ti.kernel
    def act(k: ti.i32):
        for t in range(k):
            ti.activate(node, [idx[t, 0], idx[t, 1]])

    @ti.kernel
    def deact(k: ti.i32):
        for t in range(k):
            ti.deactivate(node, [idx[t, 0], idx[t, 1]])

    mark = ti.field(ti.i32, shape=(n, n))
    read_back = ti.field(ti.i32, shape=(n, n))

    @ti.kernel
    def count_active():
        count[None] = 0
        for i, j in ti.ndrange(n, n):
            mark[i, j] = 0
        for i, j in x:
            count[None] += 1
            mark[i, j] += 1

    @ti.kernel
    def read_all():
        for i, j in ti.ndrange(n, n):
            read_back[i, j] = x[i, j]

    m = node.shape[0]
    active = np.zeros((m, m), bool)  # in the node's own coordinates
    values = np.zeros((n, n), np.int64)  # what a read returns

    def cell_mask():
        return np.kron(active, np.ones((gran, gran), bool)) if gran > 1 else active

    for _ in range(6):
        # writes: distinct cells so the parallel loop has one writer per cell
        k = int(rng.integers(1, 12))
        flat = rng.choice(n * n, size=k, replace=False)
        cells = np.stack([flat // n, flat % n], axis=1)
        vals = rng.integers(1, 1000, size=k)
        idx.from_numpy(np.pad(cells, ((0, k_max - k), (0, 0))).astype(np.int32))
        val.from_numpy(np.pad(vals, (0, k_max - k)).astype(np.int32))
        write(k)
        for (i, j), v in zip(cells, vals):
            active[i // gran, j // gran] = True
            values[i, j] = v
        # activations and deactivations in the node's coordinates
        for op in (act, deact):
            k = int(rng.integers(1, 6))
            flat = rng.choice(m * m, size=k, replace=False)
            cells = np.stack([flat // m, flat % m], axis=1)
            idx.from_numpy(np.pad(cells, ((0, k_max - k), (0, 0))).astype(np.int32))
            op(k)
            for i, j in cells:
                if op is deact:
                    if active[i, j] and kind == "pointer":
                        values[i * gran : (i + 1) * gran, j * gran : (j + 1) * gran] = 0  # the block is freed
                    active[i, j] = False
                else:
                    active[i, j] = True
            mask = cell_mask()
            assert np.array_equal(x.to_numpy(), np.where(mask, values, 0))
            count_active()
            assert count[None] == int(mask.sum())
            assert np.array_equal(mark.to_numpy(), mask.astype(np.int32))
    # direct reads: under a pointer an inactive cell reads 0; a bitmasked cell keeps its value (see above)
    read_all()
    assert np.array_equal(read_back.to_numpy(), values if kind == "bitmasked" else np.where(cell_mask(), values, 0))
    assert x[0, 0] == read_back[0, 0] and x[n - 1, 3] == read_back[n - 1, 3]
    count_active()  # the reads activated nothing
    assert count[None] == int(cell_mask().sum())


def test_activation_cycles_against_numpy_mirror_pointer():
    _mirror_rounds("pointer", seed=1)


def test_activation_cycles_against_numpy_mirror_bitmasked():
    _mirror_rounds("bitmasked", seed=2)


def test_struct_for_counts_random_active_cells():
    x, _, _ = _pointer_2d(ti.i32, nb=8, bs=4)
    z = ti.field(ti.i32)
    ti.root.dense(ti.ij, 8).bitmasked(ti.ij, 4).place(z)
    rng = np.random.default_rng(7)
    cells = rng.integers(0, 32, size=(40, 2))
    for i, j in cells:
        x[i, j] = 1
        z[i, j] = 1

    @ti.kernel
    def counts() -> ti.i32:
        c = 0
        for _i, _j in x:
            c += 1
        for _i, _j in z:
            c += 1000
        return c

    blocks = {(int(i) // 4, int(j) // 4) for i, j in cells}
    distinct = {(int(i), int(j)) for i, j in cells}
    assert counts() == 16 * len(blocks) + 1000 * len(distinct)


# ---------------------------------------------------------------------------------------------------------------
# deactivate_all


def test_deactivate_all_variants():
    x, blk, dn = _pointer_2d()
    z = ti.field(ti.f32)
    bm = ti.root.dense(ti.i, 4).bitmasked(ti.j, 8)
    bm.place(z)
    x[3, 5] = 1.0
    x[20, 20] = 2.0
    z[1, 1] = 3.0
    z[2, 7] = 4.0
    dn.deactivate_all()  # a dense node: recurses into its children (a place) and deactivates nothing
    assert _visited(x) == _block_cells([(0, 0), (2, 2)])
    blk.deactivate_all()  # this subtree only
    assert _visited(x) == []
    assert x[3, 5] == 0.0
    assert _visited(z) == [(1, 1), (2, 7)]
    x[3, 5] = 1.0
    x.parent(2).deactivate_all()
    assert _visited(x) == []
    bm.deactivate_all()
    assert _visited(z) == []
    z[1, 1] = 3.0
    x[3, 5] = 1.0
    ti.deactivate_all_snodes()
    assert _visited(x) == [] and _visited(z) == []
    assert np.array_equal(x.to_numpy(), np.zeros((32, 32), np.float32))
    x[3, 5] = 1.0
    z[0, 0] = 1.0
    ti.root.deactivate_all()
    assert _visited(x) == [] and _visited(z) == []


# ---------------------------------------------------------------------------------------------------------------
# dynamic


def _dynamic_rows():
    w = ti.field(ti.i32)
    dyn = ti.root.dense(ti.i, 4).dynamic(ti.j, 32, chunk_size=8)
    dyn.place(w)

    @ti.kernel
    def append(i: ti.i32, v: ti.i32) -> ti.i32:
        return ti.append(w.parent(), i, v)

    @ti.kernel
    def length(i: ti.i32) -> ti.i32:
        return ti.length(w.parent(), i)

    return w, dyn, append, length


def test_append_returns_the_old_length():
    w, dyn, append, length = _dynamic_rows()
    assert w.parent() == dyn
    assert [append(0, 10 + k) for k in range(3)] == [0, 1, 2]
    assert [append(2, 7)] == [0]
    assert [length(i) for i in range(4)] == [3, 0, 1, 0]
    want = np.zeros((4, 32), np.int32)
    want[0, :3] = [10, 11, 12]
    want[2, 0] = 7
    assert np.array_equal(w.to_numpy(), want)


def test_dynamic_field_methods_append_and_length():
    w, _, _, _ = _dynamic_rows()
    out = ti.field(ti.i32, shape=4)

    @ti.kernel
    def fill():
        for i in range(4):
            for k in range(i + 1):
                w[i].append(i * 10 + k)
        for i in range(4):
            out[i] = w[i].length()

    fill()
    assert out.to_numpy().tolist() == [1, 2, 3, 4]
    assert w[3, 3] == 33 and w[1, 1] == 11

    l = ti.field(ti.f32)
    ti.root.dynamic(ti.i, 16, chunk_size=4).place(l)
    n = ti.field(ti.i32, shape=2)

    @ti.kernel
    def one_d():
        for k in range(5):
            ti.append(l.parent(), [], k * 0.5)
        n[0] = ti.length(l.parent(), [])
        n[1] = l.length()

    one_d()
    assert n.to_numpy().tolist() == [5, 5]
    assert sorted(l.to_numpy()[:5].tolist()) == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert l.to_numpy()[5:].tolist() == [0.0] * 11


def test_dynamic_direct_write_extends_the_length():
    w, _, _, length = _dynamic_rows()

    @ti.kernel
    def write(i: ti.i32, j: ti.i32, v: ti.i32):
        w[i, j] = v

    write(1, 10, 7)
    assert length(1) == 11
    assert w[1, 10] == 7 and w[1, 9] == 0
    w[2, 3] = 5  # Python scope too
    assert length(2) == 4
    assert _visited(w) == [(1, j) for j in range(11)] + [(2, j) for j in range(4)]


def test_dynamic_read_beyond_length_is_zero_and_does_not_extend():
    w, _, append, length = _dynamic_rows()
    for k in range(3):
        append(0, k + 1)

    @ti.kernel
    def read(i: ti.i32, j: ti.i32) -> ti.i32:
        return w[i, j]

    assert read(0, 5) == 0 and w[0, 20] == 0
    assert read(3, 3) == 0 and w[2, 0] == 0
    assert [length(i) for i in range(4)] == [3, 0, 0, 0]


def test_dynamic_deactivate_resets_the_length():
    w, dyn, append, length = _dynamic_rows()
    for k in range(5):
        append(0, k + 1)
        append(1, k + 1)

    @ti.kernel
    def deact(i: ti.i32):
        ti.deactivate(w.parent(), i)

    deact(0)
    assert length(0) == 0 and length(1) == 5
    assert w[0, 0] == 0 and w[0, 4] == 0
    assert _visited(w) == [(1, j) for j in range(5)]
    assert append(0, 99) == 0
    assert w[0, 0] == 99 and w[0, 1] == 0
    dyn.deactivate_all()
    assert [length(i) for i in range(4)] == [0, 0, 0, 0]
    assert _visited(w) == []
    assert append(1, 3) == 0
    ti.deactivate_all_snodes()
    assert length(1) == 0


def test_dynamic_struct_for_visits_below_length_only():
    w, _, append, _ = _dynamic_rows()
    lengths = [3, 0, 17, 9]
    for i, n in enumerate(lengths):
        for k in range(n):
            append(i, 100 * i + k)

    @ti.kernel
    def sums() -> ti.i32:
        s = 0
        for i, j in w:
            s += w[i, j] + 1
        return s

    assert _visited(w) == [(i, j) for i, n in enumerate(lengths) for j in range(n)]
    assert sums() == sum(100 * i + k + 1 for i, n in enumerate(lengths) for k in range(n))


def test_parallel_appends_to_one_list():
    n = 100000
    g = ti.field(ti.i32)
    ti.root.dynamic(ti.i, 2**17, chunk_size=1024).place(g)
    ret = ti.field(ti.i32, shape=n)

    @ti.kernel
    def fill():
        for k in range(n):
            ret[k] = ti.append(g.parent(), [], k)

    @ti.kernel
    def length() -> ti.i32:
        return ti.length(g.parent(), [])

    fill()
    assert length() == n
    vals = g.to_numpy()[:n]
    assert np.array_equal(np.sort(vals), np.arange(n))
    slots = ret.to_numpy()  # each append got its own slot, and wrote its value there
    assert np.array_equal(np.sort(slots), np.arange(n))
    assert np.array_equal(vals[slots], np.arange(n))


def test_parallel_appends_to_64_lists():
    n, lists = 100000, 64
    g = ti.field(ti.i32)
    ti.root.dense(ti.i, lists).dynamic(ti.j, 4096, chunk_size=64).place(g)

    @ti.kernel
    def fill():
        for k in range(n):
            ti.append(g.parent(), k % lists, k)

    lengths = ti.field(ti.i32, shape=lists)

    @ti.kernel
    def get_lengths():
        for i in range(lists):
            lengths[i] = ti.length(g.parent(), i)

    fill()
    get_lengths()
    ln = lengths.to_numpy()
    want = np.bincount(np.arange(n) % lists, minlength=lists)
    assert np.array_equal(ln, want)
    a = g.to_numpy()
    for i in range(lists):
        row = a[i, : ln[i]]
        assert np.array_equal(np.sort(row), np.arange(i, n, lists))
        assert not a[i, ln[i] :].any()
