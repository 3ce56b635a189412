"""Each pass on IR built with the Builder: what it must do (asserted) and its whole output (golden text,
tests/passes/golden; rewrite with `pytest tests/passes --update-golden` and review the diff)."""

import numpy as np
import pytest
from irkit import atomic_add, load, new_kernel, parallel_for, ptr, serial_for, store

import simgrad as ti
from simgrad import dtypes as dt
from simgrad.ir.builder import Builder
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.passes.hoist import hoist
from simgrad.passes.parallel_strategy import LoopStrategy, parallel_strategy
from simgrad.passes.promote import promote
from simgrad.passes.simplify import simplify
from simgrad.passes.verify import IRVerifyError, verify


def _ops(k):
    return [s.op for s in walk(k.body)]


def _before_after(golden, k, fn):
    before = golden.ir(k)
    fn(k)
    verify(k)
    return f"before:\n{before}after:\n{golden.ir(k)}"


def test_simplify_folds_identities_cse_and_dead_code(golden):
    k, b = new_kernel("simplify")
    i = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    x = b.emit(Op.ARG, dt.f32, (), {"slot": 1})
    five = b.binary(Op.ADD, b.const(2, dt.i32), b.const(3, dt.i32))  # folds to 5
    same = b.binary(Op.MUL, b.binary(Op.ADD, i, b.const(0, dt.i32)), b.const(1, dt.i32))  # i
    p, q = b.binary(Op.MUL, same, five), b.binary(Op.MUL, same, five)  # one of them after CSE
    b.binary(Op.MUL, x, x)  # unused: removed
    f32_sum = b.binary(Op.ADD, b.const(0.1, dt.f32), b.const(0.2, dt.f32))  # folds, rounded to f32
    f64_sum = b.binary(Op.ADD, b.const(0.5, dt.f64), b.const(0.25, dt.f64))  # folds to 0.75
    b.emit(Op.RET_STORE, None, (b.binary(Op.ADD, p, q),), {"slot": 0})
    b.emit(Op.RET_STORE, None, (f32_sum,), {"slot": 1})
    b.emit(Op.RET_STORE, None, (f64_sum,), {"slot": 2})
    text = _before_after(golden, k, simplify)
    muls = [s for s in walk(k.body) if s.op is Op.MUL]
    assert len(muls) == 1 and muls[0].operands[0] is i and muls[0].operands[1].attrs["value"] == 5
    rets = [s.operands[0] for s in k.body.stmts if s.op is Op.RET_STORE]
    assert rets[1].op is Op.CONST and rets[1].attrs["value"] == float(np.float32(0.1) + np.float32(0.2))
    assert rets[2].op is Op.CONST and rets[2].attrs["value"] == 0.75 and f64_sum not in list(walk(k.body))
    golden.check("simplify.txt", text)


def test_promote_replaces_loads_of_once_stored_locals(golden):
    ti.init(arch=ti.cpu)
    f = ti.field(ti.f32, shape=(4, 8), name="f")
    k, b = new_kernel("promote")
    t = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    once = b.emit(Op.ALLOCA, dt.i32)
    store(b, once, b.binary(Op.MUL, t, b.const(2, dt.i32)))
    twice = b.emit(Op.ALLOCA, dt.f32)  # stored twice: stays a local, its last store forwarded (_forward_last)
    store(b, twice, b.const(1.0, dt.f32))
    store(b, twice, b.const(2.0, dt.f32))
    loop = parallel_for(b, 8)
    with b.inside(loop.blocks[0]):
        store(b, ptr(b, f, load(b, once), loop), load(b, twice))
    text = _before_after(golden, k, promote)
    assert not [s for s in walk(k.body) if s.op is Op.LOCAL_LOAD]
    (put,) = [s for s in walk(k.body) if s.op is Op.GLOBAL_STORE]
    assert put.operands[1].op is Op.CONST and put.operands[1].attrs["value"] == 2.0  # the loop stores no `twice`
    assert once not in list(walk(k.body))  # nobody reads it any more: gone with its store
    golden.check("promote.txt", text)


def test_hoist_moves_safe_invariant_integer_arithmetic_only(golden):
    ti.init(arch=ti.cpu)
    f = ti.field(ti.f32, shape=(64, 8), name="f")
    k, b = new_kernel("hoist")
    t = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    d = b.emit(Op.ARG, dt.i32, (), {"slot": 1})
    x = b.emit(Op.ARG, dt.f32, (), {"slot": 2})
    loop = parallel_for(b, 8)
    with b.inside(loop.blocks[0]):
        row = b.binary(Op.ADD, b.binary(Op.MUL, t, b.const(3, dt.i32)), b.const(1, dt.i32))  # moves (2 stmts)
        half = b.binary(Op.FLOORDIV, t, b.const(2, dt.i32))  # division by a safe constant: moves
        risky = b.binary(Op.FLOORDIV, t, d)  # may divide by zero in a loop that runs 0 times: stays
        scaled = b.binary(Op.MUL, x, x)  # floats stay
        col = b.binary(Op.ADD, loop, half)  # depends on the loop index: stays
        store(b, ptr(b, f, row, col), scaled)
        store(b, ptr(b, f, risky, loop), scaled)
    text = _before_after(golden, k, hoist)
    top = k.body.stmts
    assert all(s in top for s in (row, half)) and row.operands[0] in top
    assert all(s in loop.blocks[0].stmts for s in (risky, scaled, col))
    golden.check("hoist.txt", text)


def test_verify_reports_scope_and_type_errors():
    k, b = new_kernel("bad_scope")
    loop = serial_for(b, b.const(0, dt.i32), b.const(4, dt.i32))
    with b.inside(loop.blocks[0]):
        inner = b.binary(Op.MUL, loop, loop)
    b.emit(Op.RET_STORE, None, (inner,), {"slot": 0})  # a value of the loop body used after the loop
    with pytest.raises(IRVerifyError, match="outside its scope"):
        verify(k)

    k, b = new_kernel("bad_types")
    b.emit(Op.ADD, dt.i32, (b.const(1, dt.i32), b.const(1.0, dt.f32)))  # emit itself does not check
    with pytest.raises(IRVerifyError, match="mixes i32 and f32"):
        verify(k)


def test_verify_runs_without_SIMGRAD_VERIFY_and_sees_sibling_blocks(monkeypatch):
    """The pipeline verifies the frontend's output even outside tests (issue 21: a value computed in a loop
    used after it reached LLVM's verifier, or folded into a silently wrong constant). A value of one
    branch is not visible in the next branch either."""
    from simgrad.passes.manager import run_pipeline

    monkeypatch.setenv("SIMGRAD_VERIFY", "0")
    k, b = new_kernel("bad_scope")
    loop = serial_for(b, b.const(0, dt.i32), b.const(4, dt.i32))
    with b.inside(loop.blocks[0]):
        inner = b.binary(Op.MUL, b.const(3, dt.i32), b.const(2, dt.i32))
    b.emit(Op.RET_STORE, None, (inner,), {"slot": 0})
    with pytest.raises(IRVerifyError, match="outside its scope"):
        run_pipeline(k)

    k, b = new_kernel("sibling")
    cond = b.binary(Op.LT, b.const(0, dt.i32), b.const(1, dt.i32))
    branch = b.emit(Op.IF, None, (cond,), {}, nblocks=2)
    with b.inside(branch.blocks[0]):
        then = b.binary(Op.MUL, cond, cond)
    with b.inside(branch.blocks[1]):
        b.emit(Op.RET_STORE, None, (then,), {"slot": 0})
    with pytest.raises(IRVerifyError, match="outside its scope"):
        verify(k)


def test_verify_checks_constants_are_placed_nowhere():
    """A constant is a value usable anywhere only because it sits in no block: the verifier holds that."""
    k, b = new_kernel("const_ok")
    two = b.const(2, dt.i32)
    loop = serial_for(b, b.const(0, dt.i32), b.const(4, dt.i32))
    with b.inside(loop.blocks[0]):
        b.emit(Op.RET_STORE, None, (b.binary(Op.MUL, loop, two),), {"slot": 0})
    assert two.block is None and Op.CONST not in [s.op for s in walk(k.body)]
    verify(k)  # the constant made outside the loop is fine inside it

    k, b = new_kernel("const_placed")
    loop = serial_for(b, b.const(0, dt.i32), b.const(4, dt.i32))
    with b.inside(loop.blocks[0]):
        placed = Builder.detached(Op.CONST, dt.i32, (), {"value": 3}, None, b.block)
        b.block.stmts.append(placed)  # what a transform must not do
    b.emit(Op.RET_STORE, None, (placed,), {"slot": 0})
    with pytest.raises(IRVerifyError, match="placed in a block"):
        verify(k)


def _strategy_kernel(read_grid_m: bool):
    """One parallel loop with every kind of update, over fields of a fresh program."""
    ti.init(arch=ti.cpu)
    y = ti.field(ti.f32, shape=64, name="y")
    total = ti.field(ti.f32, shape=(), name="total")
    grid_v = ti.Vector.field(2, ti.f32, shape=16, name="grid_v")
    grid_m = ti.field(ti.f32, shape=16, name="grid_m")
    gx, gy = grid_v.comps
    k, b = new_kernel("strategies")
    s = b.emit(Op.ALLOCA, dt.f32)  # a kernel-scope local every iteration adds into
    one = b.const(1.0, dt.f32)
    loop = parallel_for(b, 64)
    with b.inside(loop.blocks[0]):
        atomic_add(b, ptr(b, y, loop), one)  # owned: plain
        atomic_add(b, ptr(b, total), one)  # one loop-invariant place: per-thread sum
        atomic_add(b, s, one)  # likewise
        mine = b.emit(Op.ALLOCA, dt.f32)
        atomic_add(b, mine, one)  # a local of the iteration: plain
        cell = b.binary(Op.MOD, loop, b.const(16, dt.i32))  # many iterations per cell
        atomic_add(b, ptr(b, gx, cell), one)  # two neighbouring f32 components: a pair
        atomic_add(b, ptr(b, gy, cell), one)
        atomic_add(b, ptr(b, grid_m, cell), one)  # only added into: per-thread copy, else atomic
        if read_grid_m:
            store(b, ptr(b, y, loop), load(b, ptr(b, grid_m, cell)))
    return k, loop


@pytest.mark.parametrize("read_grid_m", [False, True])
def test_parallel_strategy_annotations(golden, read_grid_m):
    k, loop = _strategy_kernel(read_grid_m)
    parallel_strategy(k)
    forms = [s.attrs["strategy"] for s in walk(k.body) if s.op is Op.ATOMIC]
    plan = loop.attrs["strategy"]
    assert isinstance(plan, LoopStrategy) and len(plan.reductions) == 2
    if read_grid_m:  # y is also stored at elements the iteration owns: still plain
        assert forms == ["plain", "reduce", "reduce", "plain", "private|pair", "private|pair", "atomic"]
        assert len(plan.regions) == 1 and plan.weight == 2  # grid_v's two components, one region
    else:
        assert forms == ["plain", "reduce", "reduce", "plain", "private|pair", "private|pair", "private|atomic"]
        assert len(plan.regions) == 2 and plan.weight == 3
    golden.check(f"strategy_read{int(read_grid_m)}.txt", golden.ir(k))


def test_parallel_strategy_debug_mode_has_no_pairs_and_serial_code_is_plain():
    k, loop = _strategy_kernel(read_grid_m=True)
    b = Builder(k.body)
    late = b.emit(Op.ALLOCA, dt.f32)
    atomic_add(b, late, b.const(2.0, dt.f32))  # serial code after the loop
    parallel_strategy(k, debug=True)
    forms = [s.attrs["strategy"] for s in walk(k.body) if s.op is Op.ATOMIC]
    assert forms == ["plain", "reduce", "reduce", "plain", "private|atomic", "private|atomic", "atomic", "plain"]


def test_owned_through_the_digits_of_a_flattened_loop():
    """`for i, j in g` is one loop over L with i = L // 8 and j = L % 8: g[i, j] is owned, h[j, i] too
    (still injective), r[i] is not (8 iterations share it), and neither is g[i % 4, j]: the chain of
    digits must end in one without modulus."""
    ti.init(arch=ti.cpu)
    g = ti.field(ti.f32, shape=(4, 8), name="g")
    h = ti.field(ti.f32, shape=(8, 4), name="h")
    r = ti.field(ti.f32, shape=4, name="r")
    q = ti.field(ti.f32, shape=(4, 8), name="q")
    k, b = new_kernel("digits")
    one = b.const(1.0, dt.f32)
    loop = parallel_for(b, 32)
    with b.inside(loop.blocks[0]):
        i = b.binary(Op.RAW_DIV, loop, b.const(8, dt.i32))
        j = b.binary(Op.RAW_MOD, loop, b.const(8, dt.i32))
        atomic_add(b, ptr(b, g, i, j), one)
        atomic_add(b, ptr(b, h, j, i), one)
        atomic_add(b, ptr(b, r, i), one)
        atomic_add(b, ptr(b, q, b.binary(Op.RAW_MOD, i, b.const(4, dt.i32)), j), one)
    parallel_strategy(k)
    forms = [s.attrs["strategy"] for s in walk(k.body) if s.op is Op.ATOMIC]
    assert forms == ["plain", "plain", "private|atomic", "private|atomic"]


def test_owned_through_digits_shifted_by_constants_where_every_write_agrees():
    """`for i, j in ti.ndrange((1, 5), (1, 9))` indexes with digits plus one (karman_vortex_street's
    update_macro_var): u[i + 1, j + 1] updated and stored there alone is owned. Writes that disagree on a varying
    index are shared even though each is injective: w[i] and w[i + 1] (iteration i + 1 writes what i writes
    second), a[i, 1] and a[2, i] (iterations 2 and 1 both write a[2, 1]). c[i, 0] and c[i, 1] agree on i: owned."""
    ti.init(arch=ti.cpu)
    u = ti.field(ti.f32, shape=(6, 10), name="u")
    w = ti.field(ti.f32, shape=40, name="w")
    a = ti.field(ti.f32, shape=(40, 40), name="a")
    c = ti.field(ti.f32, shape=(40, 2), name="c")
    k, b = new_kernel("shifted")
    one = b.const(1.0, dt.f32)
    loop = parallel_for(b, 32)
    with b.inside(loop.blocks[0]):
        i = b.binary(Op.ADD, b.binary(Op.RAW_DIV, loop, b.const(8, dt.i32)), b.const(1, dt.i32))
        j = b.binary(Op.ADD, b.binary(Op.RAW_MOD, loop, b.const(8, dt.i32)), b.const(1, dt.i32))
        store(b, ptr(b, u, i, j), one)
        atomic_add(b, ptr(b, u, i, j), one)
        atomic_add(b, ptr(b, w, loop), one)
        atomic_add(b, ptr(b, w, b.binary(Op.ADD, loop, b.const(1, dt.i32))), one)
        atomic_add(b, ptr(b, a, loop, b.const(1, dt.i32)), one)
        atomic_add(b, ptr(b, a, b.const(2, dt.i32), loop), one)
        atomic_add(b, ptr(b, c, loop, b.const(0, dt.i32)), one)
        atomic_add(b, ptr(b, c, loop, b.const(1, dt.i32)), one)
    parallel_strategy(k)
    forms = [s.attrs["strategy"] for s in walk(k.body) if s.op is Op.ATOMIC]
    assert forms == ["plain", "private|atomic", "private|atomic", "private|atomic", "private|atomic", "plain",
                     "plain"]


def _access_kernel():
    """A parallel loop over a 4x8 grid (flat index digits), reading a field in its own order (affine), a
    blocked field (division and remainder terms) and a loop-invariant element (offset before the loop)."""
    ti.init(arch=ti.cpu)
    g = ti.field(ti.f32, shape=(4, 8), name="g")
    blocked = ti.field(ti.f32, name="blocked")
    ti.root.dense(ti.ij, (2, 2)).dense(ti.ij, (2, 4)).place(blocked)
    total = ti.field(ti.f32, shape=(), name="total")
    k, b = new_kernel("access")
    t = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    loop = parallel_for(b, 32)
    with b.inside(loop.blocks[0]):
        i = b.binary(Op.RAW_DIV, loop, b.const(8, dt.i32))
        j = b.binary(Op.RAW_MOD, loop, b.const(8, dt.i32))
        v = load(b, ptr(b, g, i, j))
        store(b, ptr(b, blocked, i, j), v)
        atomic_add(b, ptr(b, g, t, b.const(1, dt.i32)), v)
        atomic_add(b, ptr(b, total), v)
    return k, loop


def test_lower_access_expands_fields_into_offsets(golden):
    from simgrad.ir.nodes import indices_of
    from simgrad.passes.lower_access import lower_access

    k, loop = _access_kernel()
    parallel_strategy(k)
    text = _before_after(golden, k, lower_access)
    ptrs = [s for s in walk(k.body) if s.op is Op.GLOBAL_PTR]
    assert all(s.attrs["lowered"] for s in ptrs) and [len(indices_of(s)) for s in ptrs] == [2, 2, 2, 0]
    affine, blocked, invariant, scalar = (s.operands[-1] for s in ptrs)
    assert affine.op is Op.MUL and affine.operands[0].operands[0] is loop  # L * 4: no division
    assert {s.op for s in walk(loop.blocks[0])} >= {Op.RAW_DIV, Op.RAW_MOD}  # the blocked layout's digits
    assert invariant in k.body.stmts and invariant.block is k.body  # computed before the loop
    assert scalar.op is Op.CONST and scalar.attrs["value"] == 0
    golden.check("lower_access.txt", text)


def test_lower_access_neighbours_and_slices_are_affine_in_the_loop_index():
    """`p[t, i - 1, j + 2]` in a loop over (i, j) digits: L * stride, a slice term `t * stride` and a
    constant (subtracted when negative), no division; `p[t, j, i]` (transposed) keeps its digits."""
    from simgrad.passes.lower_access import lower_access

    ti.init(arch=ti.cpu)
    p = ti.field(ti.f32, shape=(3, 4, 8), name="p")
    k, b = new_kernel("neighbours")
    t = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    loop = parallel_for(b, 32)
    with b.inside(loop.blocks[0]):
        i = b.binary(Op.RAW_DIV, loop, b.const(8, dt.i32))
        j = b.binary(Op.RAW_MOD, loop, b.const(8, dt.i32))
        up = b.binary(Op.SUB, i, b.const(1, dt.i32))
        right = b.binary(Op.ADD, j, b.const(2, dt.i32))
        v = load(b, ptr(b, p, t, up, right))
        store(b, ptr(b, p, t, j, b.binary(Op.RAW_MOD, i, b.const(8, dt.i32))), v)
    parallel_strategy(k)
    lower_access(k)
    verify(k)
    shifted, transposed = (s.operands[-1] for s in walk(k.body) if s.op is Op.GLOBAL_PTR)
    assert shifted.op is Op.SUB and shifted.operands[1].attrs["value"] == 4 * 8 - 2 * 4  # -1 row, +2 cols

    def reaches(x, want):
        return x is want or x.op is not Op.RANGE_FOR and any(reaches(o, want) for o in x.operands)

    def divides(x):
        return x.op in (Op.RAW_DIV, Op.RAW_MOD) or x.op is not Op.RANGE_FOR and any(divides(o) for o in x.operands)

    assert reaches(shifted, loop) and reaches(shifted, t) and not divides(shifted)
    assert divides(transposed)


def test_lower_access_debug_mode_checks_every_index_at_the_access():
    from simgrad.passes.lower_access import lower_access

    k, loop = _access_kernel()
    parallel_strategy(k, debug=True)
    lower_access(k, debug=True)
    verify(k)
    checks = [s for s in walk(k.body) if s.op is Op.CHECK_INDEX]
    assert len(checks) == 6 and all(c.block is not k.body for c in checks)  # nothing hoisted past a check
    assert [c.attrs["axis"] for c in checks] == [0, 1, 0, 1, 0, 1]
