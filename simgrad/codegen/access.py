"""Addresses of field and ndarray elements. passes/lower_access.py has expanded each access into its byte
offset in the IR; what is left here is the base the offset applies to, and the debug-mode index check."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.codegen.alias import dense_place, field_end
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Stmt
from simgrad.ir.ops import Op
from simgrad.passes.privatize import PAGE_SHIFT


def lower_check_index(gen, f, s) -> str:
    """Debug mode: record an IndexError for this source line and use index 0 instead of a wild access.
    The reported index is the user's (field offsets added back)."""
    idx, extent = (f.v(o) for o in s.operands)
    code = gen.error_code("index", s.loc, (s.attrs["field"], s.attrs["axis"], s.attrs["shape"]))
    ok, oki = f.tmp("inb"), f.tmp("inbi")
    f.emit(f"{ok} = icmp ult i64 {idx}, {extent}")
    f.emit(f"{oki} = zext i1 {ok} to i32")
    shown = idx
    if s.attrs["offset"]:
        shown = f.tmp("uix")
        f.emit(f"{shown} = add i64 {idx}, {s.attrs['offset']}")
    gen._check(f, oki, code, shown)
    safe = f.tmp("ixs")
    f.emit(f"{safe} = select i1 {ok}, i64 {idx}, i64 0")
    return safe


def lower_global_ptr(gen, f, s) -> str:
    """The element's address: its tree's root (or this thread's private copy of the field, codegen/
    privatize.py) or its ndarray's base (or this thread's copy of the array), plus the byte offset the IR
    computed."""
    if not s.attrs.get("lowered"):
        raise AssertionError(f"internal: {s!r} reached codegen without passes/lower_access.py")
    off = f.v(s.operands[-1])
    target = s.attrs["target"]
    p = f.tmp("ptr")
    if s.attrs.get("absolute"):  # a sparse field's element: the walk computed its address
        based = pointer_and_offsets(f, s.operands[-1])
        if based is None:
            f.emit(f"{p} = inttoptr i64 {off} to ptr")
        else:
            base, terms = based
            total = terms[0] if terms else "0"
            for t in terms[1:]:
                nxt = f.tmp("aoff")
                f.emit(f"{nxt} = add i64 {total}, {t}")
                total = nxt
            f.emit(f"{p} = getelementptr i8, ptr {base}, i64 {total}")
    elif isinstance(target, FieldRef):
        private = f.private_root_of(s)
        if private is not None:  # its root points before the copy: no inbounds
            f.emit(f"{p} = getelementptr i8, ptr {private}, i64 {off}")
            mark_page(f, private, off)
        else:
            if dense_place(s) is not None:
                f.reaches(target.layout[0], field_end(target))
            f.emit(f"{p} = getelementptr inbounds i8, ptr {f.root(target.layout[0])}, i64 {off}")
    else:
        private = f.private_root_of(s)  # this thread's copy of the whole ndarray, or the array itself
        f.emit(f"{p} = getelementptr inbounds i8, ptr {private or f.array_base(target)}, i64 {off}")
        if private is not None:
            mark_page(f, private, off)
    return p


def mark_page(f, root: str, off: str) -> None:
    """Mark the page of this thread's copy (a target's per-thread copies, codegen/privatize.py) that an update
    at byte offset `off` from `root` goes to."""
    marks = f.private_marks[root]
    if marks is None:
        return
    mine, neg = marks
    rel, page, at = f.tmp("pgo"), f.tmp("pg"), f.tmp("pgm")
    f.emit(f"{rel} = add i64 {off}, {neg}")
    f.emit(f"{page} = lshr i64 {rel}, {PAGE_SHIFT}")
    f.emit(f"{at} = getelementptr inbounds i8, ptr {mine}, i64 {page}")
    f.emit(f"store i8 1, ptr {at}{f.gen.module.facts.page_map()}")


def pointer_and_offsets(f, x: Stmt, depth: int = 0) -> tuple[str, tuple[str, ...]] | None:
    """A sparse element's u64 address as (pointer, i64 terms) of which it is the sum: its walk's last lookup
    (a SPARSE_CELL's block, or the tree's root: f.addr_base, codegen/sparse.py) plus the u64 ADDs on top
    (members, dense levels below). A getelementptr from that pointer keeps what LLVM knows of it: loads along a
    dynamic list are then consecutive (LLVM vectorises a loop over the list with wide loads, not gathers),
    where `inttoptr` of the sum hides the stride from SCEV. None when the address is not such a sum (a value
    another GPU segment computed, a lookup emitted in another function)."""
    hit = f.addr_base.get(x)
    if hit is not None:
        return hit
    if x.op is not Op.ADD or x.type is not dt.u64 or depth > 32 or x not in f.names:
        return None
    a, b = x.operands
    for one, other in ((a, b), (b, a)):
        got = pointer_and_offsets(f, one, depth + 1)
        if got is not None:
            return got[0], (*got[1], f.v(other))
    return None
