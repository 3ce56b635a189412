"""Addresses of field and ndarray elements (the dense SNode path as address arithmetic), with bounds
checks in debug mode."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.ops import Op
from simgrad.passes.digits import digit_chain


def _i64(f, idx_name: str, t: dt.DataType) -> str:
    if t is dt.i64:
        return idx_name
    r = f.tmp("ix")
    f.emit(f"{r} = sext {t.llvm} {idx_name} to i64")
    return r


def _bounds_check(gen, f, s, k: int, idx: str, extent: str, shape_text: str, offset: int = 0) -> str:
    """Debug mode: record an IndexError for this source line and use index 0 instead of a wild access.
    The reported index is the user's (field offsets added back)."""
    target = s.attrs["target"]
    name = target.name
    code = gen.error_code("index", s.loc, (name, k, shape_text))
    ok = f.tmp("inb")
    f.emit(f"{ok} = icmp ult i64 {idx}, {extent}")
    oki = f.tmp("inbi")
    f.emit(f"{oki} = zext i1 {ok} to i32")
    shown = idx
    if offset:
        shown = f.tmp("uix")
        f.emit(f"{shown} = add i64 {idx}, {offset}")
    gen._check(f, oki, code, shown)
    safe = f.tmp("ixs")
    f.emit(f"{safe} = select i1 {ok}, i64 {idx}, i64 0")
    return safe


def lower_global_ptr(gen, f, s) -> str:
    target = s.attrs["target"]
    idx = [_i64(f, f.v(o), o.type) for o in s.operands]
    if isinstance(target, FieldRef):
        tree_id, const, terms, shape = target.layout
        if gen.debug:
            offset = target.offset or (0,) * len(shape)
            text = str(shape) + (f" with offset {tuple(offset)}" if any(offset) else "")
            idx = [_bounds_check(gen, f, s, k, i, str(shape[k]), text, offset[k]) for k, i in enumerate(idx)]
        off = str(const)
        stride = None if gen.debug else _linear_stride(f, s, terms)
        if stride is not None:  # the address is affine in the loop index: LLVM can vectorise the loop
            lin, m, a = _i64(f, f.v(f.loop), f.loop.type), f.tmp("of"), f.tmp("of")
            f.emit(f"{m} = mul nsw i64 {lin}, {stride}")
            f.emit(f"{a} = add nsw i64 {const}, {m}")
            terms, off = (), a
        for t in terms:
            d = idx[t.axis]
            if t.divisor != 1:
                q = f.tmp("dg")
                f.emit(f"{q} = udiv i64 {d}, {t.divisor}")
                d = q
            if t.modulus:
                q = f.tmp("dg")
                f.emit(f"{q} = urem i64 {d}, {t.modulus}")
                d = q
            m, a = f.tmp("of"), f.tmp("of")
            f.emit(f"{m} = mul nuw nsw i64 {d}, {t.stride}")
            f.emit(f"{a} = add nuw nsw i64 {off}, {m}")
            off = a
        p = f.tmp("ptr")
        private = f.private_root_of(s)
        if private is not None:  # this thread's copy (codegen/privatize.py); its root points before it
            f.emit(f"{p} = getelementptr i8, ptr {private}, i64 {off}")
        else:
            f.emit(f"{p} = getelementptr inbounds i8, ptr {f.root(tree_id)}, i64 {off}")
        return p
    # an ndarray argument: C-contiguous, element components as trailing dimensions
    arg = target.arg
    extents = [f.array_shape(arg, k) for k in range(arg.ndim)]
    if gen.debug:
        idx = [_bounds_check(gen, f, s, k, i, extents[k], "ndarray") for k, i in enumerate(idx)]
    lin = "0"
    for k, i in enumerate(idx):
        if k:
            m = f.tmp("lin")
            f.emit(f"{m} = mul nsw i64 {lin}, {extents[k]}")
            lin = m
        a = f.tmp("lin")
        f.emit(f"{a} = add nsw i64 {lin}, {i}")
        lin = a
    ncomp = arg.num_components
    if ncomp > 1:
        m = f.tmp("lin")
        f.emit(f"{m} = mul nsw i64 {lin}, {ncomp}")
        a = f.tmp("lin")
        f.emit(f"{a} = add nsw i64 {m}, {target.comp}")
        lin = a
    p = f.tmp("ptr")
    f.emit(f"{p} = getelementptr inbounds {arg.dtype.llvm}, ptr {f.array_base(arg)}, i64 {lin}")
    return p


def _linear_stride(f, s, terms) -> int | None:
    """The byte stride `st` when the element address is `const + L * st` for the task's loop index L:
    the indices are the digits `(L // d) % m` of a flattened struct-for (the loop starting at 0) and the
    field's strides follow the same digits (a dense field iterated in its own order). Else None."""
    loop = f.loop
    if loop is None or loop.operands[0].op is not Op.CONST or loop.operands[0].attrs["value"] != 0:
        return None
    if len(terms) != len(s.operands) or any(t.divisor != 1 or t.modulus for t in terms):
        return None
    values = [s.operands[t.axis] for t in terms]
    chain = digit_chain(values, loop)
    if chain is None or len(chain) != len(terms):  # every index one digit of the chain
        return None
    unit = terms[chain[0][0]].stride
    if any(terms[k].stride != divisor * unit for k, divisor, _mod in chain):
        return None
    return unit
