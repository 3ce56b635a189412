"""The IR itself: the Builder's type checks and constant wrapping, walk order, and the printer's text."""

import pytest
from irkit import load, new_kernel, parallel_for, serial_for, store

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


def test_builder_refuses_mixed_and_wrong_operand_types():
    _k, b = new_kernel()
    i, x = b.const(1, dt.i32), b.const(1.0, dt.f32)
    with pytest.raises(SimgradTypeError, match="ADD on i32 and f32"):
        b.binary(Op.ADD, i, x)
    with pytest.raises(SimgradTypeError, match="'sqrt' takes real inputs only, got i32"):
        b.unary(Op.SQRT, i)
    with pytest.raises(SimgradTypeError, match="bit_and needs integer operands, got f32"):
        b.binary(Op.BIT_AND, x, x)
    with pytest.raises(SimgradTypeError, match="select on i32 and f32"):
        b.select(i, i, x)
    assert b.binary(Op.LT, x, x).type is dt.i32  # comparisons give i32 whatever they compare
    assert b.unary(Op.LOGICAL_NOT, x).type is dt.i32


def test_builder_constants_wrap_and_casts_of_constants_fold():
    _k, b = new_kernel()
    assert b.const(300, dt.i8).attrs["value"] == 44
    assert b.const(-1, dt.u8).attrs["value"] == 255
    assert b.const(2**31, dt.i32).attrs["value"] == -(2**31)
    assert b.const(3, dt.f32).attrs["value"] == 3.0 and isinstance(b.const(3, dt.f32).attrs["value"], float)
    c = b.cast(b.const(7, dt.i32), dt.f64)
    assert c.op is Op.CONST and c.type is dt.f64 and c.attrs["value"] == 7.0
    v = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    assert b.cast(v, dt.i32) is v and b.cast(v, dt.f32).op is Op.CAST


def _sample_kernel():
    """`s = 0; for i in range(n): if i % 2: s += i else: while True: break`, then return s."""
    k, b = new_kernel("sample")
    n = b.emit(Op.ARG, dt.i32, (), {"slot": 0})
    s = b.emit(Op.ALLOCA, dt.i32)
    store(b, s, b.const(0, dt.i32))
    loop = serial_for(b, b.const(0, dt.i32), n)
    with b.inside(loop.blocks[0]):
        odd = b.binary(Op.MOD, loop, b.const(2, dt.i32))
        branch = b.emit(Op.IF, None, (odd,), nblocks=2)
        with b.inside(branch.blocks[0]):
            b.emit(Op.ATOMIC, dt.i32, (s, loop), {"kind": "add"})
        with b.inside(branch.blocks[1]):
            w = b.emit(Op.WHILE, None, nblocks=1)
            with b.inside(w.blocks[0]):
                b.emit(Op.BREAK, None)
    b.emit(Op.RET_STORE, None, (load(b, s),), {"slot": 0})
    return k, loop, branch


def test_walk_is_depth_first_in_program_order():
    k, loop, branch = _sample_kernel()
    ops = [s.op for s in walk(k.body)]
    assert ops[:3] == [Op.ARG, Op.ALLOCA, Op.LOCAL_STORE] and Op.CONST not in ops  # constants: in no block
    assert ops.index(Op.RANGE_FOR) < ops.index(Op.MOD) < ops.index(Op.IF) < ops.index(Op.ATOMIC) \
        < ops.index(Op.WHILE) < ops.index(Op.BREAK) < ops.index(Op.RET_STORE)
    assert branch.blocks[0].parent is branch and loop.blocks[0].stmts[0].block is loop.blocks[0]


def test_printer_text(golden):
    k, _loop, _branch = _sample_kernel()
    golden.check("sample.txt", golden.ir(k))


def test_parallel_loop_attrs_print(golden):
    k, b = new_kernel("fill")
    loop = parallel_for(b, 8)
    with b.inside(loop.blocks[0]):
        b.binary(Op.MUL, loop, loop)
    text = golden.ir(k)
    assert "range_for" in text and "[parallel=True, top=True]" in text
    golden.check("parallel_loop.txt", text)
