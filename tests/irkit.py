"""Small helpers for tests that build IR directly with the Builder (tests/ir, tests/passes, tests/codegen)."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.builder import Builder
from simgrad.ir.nodes import Kernel, Stmt
from simgrad.ir.ops import Op


def new_kernel(name: str = "k") -> tuple[Kernel, Builder]:
    k = Kernel(name)
    k.ret_slot = 0
    return k, Builder(k.body)


def parallel_for(b: Builder, n: int, t: dt.DataType = dt.i32) -> Stmt:
    """A top-level parallel loop over [0, n), as the frontend makes them; enter it with `b.inside`."""
    return b.emit(Op.RANGE_FOR, t, (b.const(0, t), b.const(n, t)), {"parallel": True, "top": True}, nblocks=1)


def serial_for(b: Builder, begin: Stmt, end: Stmt) -> Stmt:
    return b.emit(Op.RANGE_FOR, begin.type, (begin, end), {"parallel": False}, nblocks=1)


def target(field):
    """What a GLOBAL_PTR of `field` refers to (its trees materialised first)."""
    from simgrad.lang.program import get_program

    get_program().materialize_all()
    return field.ref()


def ptr(b: Builder, field, *indices: Stmt) -> Stmt:
    return b.emit(Op.GLOBAL_PTR, field.dtype, indices, {"target": target(field)})


def atomic_add(b: Builder, place: Stmt, value: Stmt) -> Stmt:
    return b.emit(Op.ATOMIC, value.type, (place, value), {"kind": "add"})


def load(b: Builder, place: Stmt) -> Stmt:
    op = Op.LOCAL_LOAD if place.op is Op.ALLOCA else Op.GLOBAL_LOAD
    return b.emit(op, place.type, (place,))


def store(b: Builder, place: Stmt, value: Stmt) -> None:
    b.emit(Op.LOCAL_STORE if place.op is Op.ALLOCA else Op.GLOBAL_STORE, None, (place, value))
