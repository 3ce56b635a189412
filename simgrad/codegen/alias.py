"""What LLVM cannot see of field memory, told as metadata: distinct places of dense fields never overlap
(scoped noalias: `!alias.scope` / `!noalias` on their stores and plain updates; plain loads carry none, as with
them LLVM stopped vectorising vortex_rings' advect loop, 2x slower), and a tree's root points at a
64-byte aligned buffer that holds every element of its fields (`!dereferenceable` / `!align` on the root's
load). Without them a store to one field made LLVM reload every other one, and a load under a branch (a
uniform `gravity[None]` in `if grid_m[i, j] > 0:`) could not be hoisted: the vectoriser turned it into a
masked gather from one address and kept each store of the body as a masked scatter.

Only plain dense elements take part (no sparse walk, no quant cell, no ndarray, whose buffers a caller
may pass twice): an access without a scope is never assumed apart from anything."""

from __future__ import annotations

from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Stmt
from simgrad.ir.ops import Op

#: metadata ids from here on (codegen numbers branch weights from !1 and unroll hints from !1000 up)
FIRST_ID = 900000


def dense_place(ptr: Stmt) -> FieldRef | None:
    """The field whose element `ptr` addresses when it is a plain dense element (not sparse, not quant,
    not an absolute address), else None."""
    if ptr.op is not Op.GLOBAL_PTR or ptr.attrs.get("absolute"):
        return None
    t = ptr.attrs.get("target")
    if not isinstance(t, FieldRef) or t.levels or t.quant is not None:
        return None
    return t


def field_end(t: FieldRef) -> int:
    """Bytes from the tree's root to the end of the field's last element (its largest offset plus its
    size): every index the field's shape allows lands below it, padding cells included; 0 for an empty field."""
    _tree, const, terms, shape = t.layout
    if not all(shape):  # an empty field: its tree may have no bytes at all
        return 0
    end = const
    for term in terms:
        top = max(shape[term.axis] - 1, 0) // term.divisor
        if term.modulus:
            top = min(top, term.modulus - 1)
        end += top * term.stride
    return end + t.dtype.bits // 8 if t.dtype.bits >= 8 else end + 1


class MemoryFacts:
    """The metadata of one module: a scope per dense place accessed (keyed by tree and byte offset, so
    the components of a vector field are apart), its noalias list (every other place), and per tree the
    bytes its root is dereferenceable for."""

    def __init__(self) -> None:
        self.scopes: dict[tuple[int, int], int] = {}

    def _metadata(self, key: tuple[int, int]) -> str:
        """`, !alias.scope !A, !noalias !B` of the place `key` (tree, byte offset), its scope made on first use."""
        k = self.scopes.setdefault(key, len(self.scopes))
        return f", !alias.scope !{FIRST_ID + 3 + 3 * k}, !noalias !{FIRST_ID + 4 + 3 * k}"

    def access(self, ptr: Stmt, llvm_ty: str) -> str:
        """The metadata of a load/store of type llvm_ty through ptr, or ''."""
        t = dense_place(ptr)
        if t is None or llvm_ty != t.dtype.llvm:  # a wider access could reach a neighbour place
            return ""
        return self._metadata((t.layout[0], t.layout[1]))

    def page_map(self) -> str:
        """The metadata of a store to a per-thread page map of scatter copies (codegen/privatize.py): apart
        from every field place."""
        return self._metadata((-1, -1))

    def globals(self) -> list[str]:
        if not self.scopes:
            return []
        dom = FIRST_ID
        out = [f'!{dom} = distinct !{{!{dom}, !"simgrad fields"}}']
        ids = {k: FIRST_ID + 2 + 3 * k for k in self.scopes.values()}
        for (tree, off), k in self.scopes.items():
            name = "page maps" if tree < 0 else f"tree {tree} byte {off}"
            out.append(f'!{ids[k]} = distinct !{{!{ids[k]}, !{dom}, !"{name}"}}')
            out.append(f"!{ids[k] + 1} = !{{!{ids[k]}}}")
            others = ", ".join(f"!{ids[j]}" for j in ids if j != k)
            out.append(f"!{ids[k] + 2} = !{{{others}}}")
        return out


def root_facts(nbytes: int) -> str:
    """The metadata of a tree root's load when its fields reach `nbytes` into the buffer."""
    return f", !dereferenceable !{{i64 {nbytes}}}, !align !{{i64 64}}"
