"""Struct-fors over a pointer (or bitmasked) node with dense blocks below, as mgpcg's grids: the loop's own cell
and its neighbours inside the block start from the block's cell looked up once per block (passes/lower_access.py
OwnBlock). Values against numpy with the same operation order (exact), holes of inactive blocks, neighbours in
other blocks and off the grid, another node's field, and the IR the optimisation leaves."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op

NB, BS = 6, 4  # 6^3 blocks of 4^3 cells; only inner blocks are active, so every read stays on the grid
N = NB * BS


def _grid(kind="pointer"):
    r, z, w = ti.field(ti.f32), ti.field(ti.f32), ti.field(ti.f32)
    getattr(ti.root, kind)(ti.ijk, NB).dense(ti.ijk, BS).place(r, z)
    ti.root.pointer(ti.ijk, NB).dense(ti.ijk, BS).place(w)
    return r, z, w


def _blocks(seed=0):
    """Active blocks: about half of the inner ones, with holes (an index off the grid names some other cell, as in
    Taichi, so the stencils keep to it)."""
    rng = np.random.default_rng(seed)
    act = np.zeros((NB, NB, NB), bool)
    act[1:-1, 1:-1, 1:-1] = rng.random((NB - 2,) * 3) < 0.5
    act[1, 1, 1] = act[-2, -2, -2] = True
    return act


def _activate(r, z, w, act, seed=1):
    rng = np.random.default_rng(seed)
    mask = np.kron(act, np.ones((BS, BS, BS), bool))
    r0 = np.where(mask, rng.random((N, N, N)), 0).astype(np.float32)
    z0 = np.where(mask, rng.random((N, N, N)), 0).astype(np.float32)
    wmask = np.kron(~act, np.ones((BS, BS, BS), bool))  # w lives where r does not (and in one r block)
    wmask[BS:2 * BS, BS:2 * BS, BS:2 * BS] = True
    w0 = np.where(wmask, rng.random((N, N, N)), 0).astype(np.float32)

    @ti.kernel
    def put(a: ti.types.ndarray(), b: ti.types.ndarray(), c: ti.types.ndarray(),
            m: ti.types.ndarray(), mw: ti.types.ndarray()):
        for i, j, k in ti.ndrange(N, N, N):
            if m[i, j, k]:
                r[i, j, k] = a[i, j, k]
                z[i, j, k] = b[i, j, k]
            if mw[i, j, k]:
                w[i, j, k] = c[i, j, k]

    put(r0, z0, w0, mask.astype(np.int32), wmask.astype(np.int32))
    return r0, z0, w0, mask


def _at(a, di, dj, dk):
    """a[i + di, j + dj, k + dk] with zeros off the grid (inactive reads are 0)."""
    p = np.pad(a, 1)
    return p[1 + di:1 + di + N, 1 + dj:1 + dj + N, 1 + dk:1 + dk + N]


@pytest.mark.parametrize("kind", ["pointer", "bitmasked"])
def test_red_black_smoothing_matches_numpy(kind):
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid(kind)
    r0, z0, _w0, mask = _activate(r, z, w, _blocks())

    @ti.kernel
    def smooth(phase: ti.template()):
        for i, j, k in r:
            if (i + j + k) & 1 == phase:
                z[i, j, k] = (r[i, j, k] + z[i + 1, j, k] + z[i - 1, j, k] + z[i, j + 1, k]
                              + z[i, j - 1, k] + z[i, j, k + 1] + z[i, j, k - 1]) / 6.0

    ii, jj, kk = np.meshgrid(*[np.arange(N)] * 3, indexing="ij")
    ref = z0.copy()
    for phase in (0, 1, 0, 1):
        smooth(phase)
        new = (r0 + _at(ref, 1, 0, 0) + _at(ref, -1, 0, 0) + _at(ref, 0, 1, 0) + _at(ref, 0, -1, 0)
               + _at(ref, 0, 0, 1) + _at(ref, 0, 0, -1)) * (np.float32(1) / np.float32(6))  # fast_math, as taichi
        ref = np.where(mask & ((ii + jj + kk) % 2 == phase), new, ref).astype(np.float32)
        np.testing.assert_array_equal(z.to_numpy(), ref)


def test_laplacian_reduction_and_another_nodes_field():
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid()
    out, total = ti.field(ti.f32), ti.field(ti.f32, shape=())
    ti.root.pointer(ti.ijk, NB).dense(ti.ijk, BS).place(out)
    r0, z0, w0, mask = _activate(r, z, w, _blocks(2), seed=3)

    @ti.kernel
    def apply():
        for i, j, k in z:  # own cell of r and z; w (another node) and its neighbours; 2-cell reach
            out[i, j, k] = (6.0 * z[i, j, k] - z[i + 1, j, k] - z[i, j - 1, k] - z[i, j, k + 3] - w[i, j, k]
                            - w[i + 1, j, k] - r[i - 2, j + 1, k])
            total[None] += r[i, j, k] * z[i, j, k]

    apply()
    ref = (np.float32(6.0) * z0 - _at(z0, 1, 0, 0) - _at(z0, 0, -1, 0) - np.pad(z0, 3)[3:3 + N, 3:3 + N, 6:6 + N]
           - w0 - _at(w0, 1, 0, 0) - np.pad(r0, 2)[:N, 3:3 + N, 2:2 + N])
    np.testing.assert_array_equal(out.to_numpy(), np.where(mask, ref, 0).astype(np.float32))
    np.testing.assert_allclose(total[None], float((r0.astype(np.float64) * z0).sum()), rtol=1e-5)


def test_writes_to_own_cells_and_to_other_levels():
    """mgpcg's restrict / prolongate: += into a coarser grid's cell, a plain copy from it back."""
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid()
    coarse = ti.field(ti.f32)
    ti.root.pointer(ti.ijk, NB // 2).dense(ti.ijk, BS).place(coarse)  # (N/2)^3 cells, blocks of 4^3
    r0, z0, _w0, mask = _activate(r, z, w, _blocks(4), seed=5)

    @ti.kernel
    def restrict():
        for i, j, k in r:
            coarse[i // 2, j // 2, k // 2] += (r[i, j, k] - z[i, j, k + 1]) * 0.5

    @ti.kernel
    def prolongate():
        for I in ti.grouped(z):
            z[I] = coarse[I // 2] + r[I]

    restrict()
    res = np.where(mask, (r0 - _at(z0, 0, 0, 1)) * np.float32(0.5), 0).astype(np.float64)
    c_ref = res.reshape(N // 2, 2, N // 2, 2, N // 2, 2).sum(axis=(1, 3, 5))
    np.testing.assert_allclose(coarse.to_numpy(), c_ref, rtol=1e-5, atol=1e-6)
    prolongate()
    up = np.repeat(np.repeat(np.repeat(coarse.to_numpy(), 2, 0), 2, 1), 2, 2)
    np.testing.assert_array_equal(z.to_numpy(), np.where(mask, up + r0, z0).astype(np.float32))


def _direct(block):
    """The SPARSE_CELLs of `block` not under an IF."""
    out = []
    for s in block.stmts:
        if s.op is Op.SPARSE_CELL:
            out.append(s)
        if s.op is not Op.IF:
            for b in s.blocks:
                out += _direct(b)
    return out


def _cell_loops(kernel):
    """(parallel loop, [its cell loops]): one, or the fast and the slow copy under an IF."""
    out = []
    for x in kernel.instance(()).ir.body.stmts:
        if x.op is Op.RANGE_FOR and x.attrs.get("cells"):
            inner = [s for s in x.blocks[0].stmts if s.op is Op.RANGE_FOR]
            for s in x.blocks[0].stmts:
                if s.op is Op.IF and all(b.stmts and b.stmts[-1].op is Op.RANGE_FOR for b in s.blocks):
                    inner = [b.stmts[-1] for b in s.blocks]
            out.append((x, inner))
    return out


def test_only_block_crossings_walk_the_pointer_table():
    """The optimisation's trace in the IR: the block's cell, and the cells of the blocks beside it that the
    neighbours need, looked up ahead of the cell loop; the cell loop of a block whose neighbours are on the grid
    looks nothing up (a select per neighbour); at the grid's edge a copy whose neighbours off the block walk
    from the root in a branch. Without OwnBlock every access has a SPARSE_CELL directly in the cell loop."""
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid()

    @ti.kernel
    def smooth():
        for i, j, k in r:
            z[i, j, k] = (r[i, j, k] + z[i + 1, j, k] + z[i, j, k - 1]) / 3.0

    smooth()
    [(body, [fast, slow])] = _cell_loops(smooth)
    ahead = [s for s in walk(body.blocks[0]) if s.op is Op.SPARSE_CELL]
    assert len(ahead) - sum(s.op is Op.SPARSE_CELL for loop in (fast, slow) for s in walk(loop.blocks[0])) == 3
    assert not any(s.op is Op.SPARSE_CELL for s in walk(fast.blocks[0]))
    assert fast.attrs.get("unroll") and not slow.attrs.get("unroll")  # 64 cells: unrolled, the digits fold
    assert "llvm.loop.unroll.full" in smooth.instance(()).llvm_text
    assert _direct(slow.blocks[0]) == []
    assert sum(s.op is Op.SPARSE_CELL for s in walk(slow.blocks[0])) == 2  # the two neighbours' crossings


def test_a_kernel_that_deactivates_keeps_the_full_walk():
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid()
    blk = r.snode.parent(2)  # the pointer (parent(): the dense block)
    assert blk.kind == "pointer"
    r0, z0, _w0, mask = _activate(r, z, w, _blocks(6), seed=7)

    @ti.kernel
    def drop_and_read():
        for i, j, k in r:
            if i == BS and j == BS and k == BS:
                ti.deactivate(blk, [1, 1, 1])
        for i, j, k in z:
            z[i, j, k] = r[i, j, k] + 1.0

    drop_and_read()
    [_first, (_body, [cells])] = _cell_loops(drop_and_read)
    assert len(_direct(cells.blocks[0])) == 2  # r's read and z's write walk from the root
    keep = mask.copy()
    keep[BS:2 * BS, BS:2 * BS, BS:2 * BS] = False
    np.testing.assert_array_equal(z.to_numpy(), np.where(keep, r0 + np.float32(1.0), 0).astype(np.float32))


def test_stencil_gradient_matches_finite_differences():
    """The adjoint of a neighbour stencil over pointer blocks (its reads start from the block's cell too) against
    central differences, in f64."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x, y = ti.field(ti.f64), ti.field(ti.f64)
    ti.root.pointer(ti.ijk, NB).dense(ti.ijk, BS).place(x, y, x.grad, y.grad)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    act = _blocks(8)
    rng = np.random.default_rng(9)
    x0 = np.where(np.kron(act, np.ones((BS, BS, BS), bool)), rng.random((N, N, N)), 0.0)
    for c in np.argwhere(act):
        for d in np.ndindex(BS, BS, BS):
            p = tuple(int(v) for v in c * BS + np.array(d))
            x[p] = x0[p]

    @ti.kernel
    def stencil():
        for i, j, k in x:
            y[i, j, k] = x[i, j, k] * x[i + 1, j, k] - ti.sin(x[i, j - 1, k]) * x[i, j, k + 1]

    @ti.kernel
    def total():
        for i, j, k in y:
            loss[None] += y[i, j, k] ** 2

    def run():
        loss[None] = 0.0
        stencil()
        total()
        return loss[None]

    with ti.ad.Tape(loss=loss):
        stencil()
        total()
    g = x.grad.to_numpy()
    cells = [tuple(int(v) for v in c) for c in np.argwhere(np.kron(act, np.ones((BS, BS, BS), bool)))[::97]]
    eps = 1e-6
    for c in cells:
        v = x[c]
        x[c] = v + eps
        up = run()
        x[c] = v - eps
        down = run()
        x[c] = v
        assert abs((up - down) / (2 * eps) - g[c]) < 1e-5 * max(1.0, abs(g[c])), c


def test_blocks_at_the_grid_edge_take_the_branching_copy():
    """Active blocks on every face: their neighbours off the grid are guarded by the kernel, as mgpcg's
    boundaries are; those blocks run the copy of the cell loop with branches, the others the selects."""
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid()
    out = ti.field(ti.f32)
    ti.root.pointer(ti.ijk, NB).dense(ti.ijk, BS).place(out)
    act = np.random.default_rng(10).random((NB, NB, NB)) < 0.6
    act[0, :, 0] = act[-1, :, -1] = True
    r0, z0, _w0, mask = _activate(r, z, w, act, seed=11)

    @ti.kernel
    def edge():
        for i, j, k in r:
            acc = r[i, j, k]
            if i + 1 < N:
                acc += z[i + 1, j, k]
            if k >= 1:
                acc += 2.0 * z[i, j, k - 1]
            if j >= 2:
                acc += 3.0 * r[i, j - 2, k]
            out[i, j, k] = acc

    edge()
    ref = (r0 + np.pad(z0, 1)[2:, 1:-1, 1:-1] + np.float32(2.0) * np.pad(z0, 1)[1:-1, 1:-1, :-2]
           + np.float32(3.0) * np.pad(r0, 2)[2:-2, :-4, 2:-2])
    np.testing.assert_array_equal(out.to_numpy(), np.where(mask, ref, 0).astype(np.float32))
    [(_body, loops)] = _cell_loops(edge)
    assert len(loops) == 2  # the fast loop and the copy


def test_a_neighbour_written_in_the_loop_is_read_back():
    """An iteration that activates the block beside (a write) and reads the neighbour it wrote gets the value: the
    blocks beside are not taken from before the cell loop then."""
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    r, z, w = _grid()
    act = np.zeros((NB, NB, NB), bool)
    act[2, 2, 2] = True  # alone: every block beside is inactive when the loop starts
    r0, z0, _w0, mask = _activate(r, z, w, act, seed=12)
    out = ti.field(ti.f32)
    ti.root.pointer(ti.ijk, NB).dense(ti.ijk, BS).place(out)

    @ti.kernel
    def spill():
        for i, j, k in r:
            z[i + 1, j, k] = r[i, j, k] + 1.0
            out[i, j, k] = z[i + 1, j, k]

    spill()
    np.testing.assert_array_equal(out.to_numpy(), np.where(mask, r0 + np.float32(1.0), 0))
