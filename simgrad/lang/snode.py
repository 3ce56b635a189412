"""Structural nodes (SNodes): the layout tree fields are placed in, as in Taichi.

`ti.root.dense(ti.ij, (4, 8)).place(a, b)` puts a and b side by side in each cell (AoS);
separate `place` calls on separate dense nodes give SoA. Only dense nodes exist today; a
node kind is a small class so pointer/bitmasked/dynamic nodes can join the tree later.
A tree is materialised (its buffer allocated) the first time a kernel or Python code
touches one of its fields; after that it is frozen and `ti.root` starts a fresh tree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from simgrad.errors import SimgradError, SimgradValueError, caller_loc

if TYPE_CHECKING:
    from simgrad.lang.field import ScalarField


@dataclass(frozen=True)
class Axis:
    index: int


i, j, k, l = (Axis(n) for n in range(4))  # noqa: E741
ij, ik, il, jk, jl, kl = ((i, j), (i, k), (i, l), (j, k), (j, l), (k, l))
ijk, ijl, ikl, jkl, ijkl = ((i, j, k), (i, j, l), (i, k, l), (j, k, l), (i, j, k, l))


def axes(*indices: int):
    return tuple(Axis(n) for n in indices)


@dataclass(frozen=True)
class AccessTerm:
    """One addend of an element's byte offset: ((I[axis] // divisor) % modulus) * stride.
    modulus 0 means no modulo (outermost digit along the axis)."""

    axis: int
    divisor: int
    modulus: int
    stride: int


class SNode:
    def __init__(self, parent: SNode | None, kind: str, axes_: tuple[int, ...] = (), sizes: tuple = ()):
        self.parent = parent
        self.kind = kind
        self.axes = axes_
        self.sizes = sizes
        self.children: list[SNode] = []
        self.field: ScalarField | None = None  # for 'place' nodes
        self.tree: SNodeTree | None = parent.tree if parent else None
        self.cell_size = 0
        self.offset_in_parent = 0
        self.align = 1

    @property
    def _name(self) -> str:
        """A place node's field name (a vector field's, for its components), else the kind."""
        if self.field is not None:
            return self.field.name.split("[")[0]
        return self.kind

    # -- building (Taichi API) -------------------------------------------------------------
    def _check_open(self):
        if self.tree is not None and self.tree.materialized:
            raise SimgradError(
                "this SNode tree is already in use by a kernel or Python access; place new fields "
                "before the first kernel launch, or build a new tree with ti.FieldsBuilder / ti.field"
            )

    def dense(self, indices, dimensions) -> SNode:
        self._check_open()
        if isinstance(indices, Axis):
            indices = (indices,)
        ax = tuple(a.index for a in indices)
        if isinstance(dimensions, int):
            dimensions = (dimensions,) * len(ax)
        if any(isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 0 for d in dimensions):
            raise SimgradValueError(f"dense(): sizes must be non-negative integers, got {dimensions!r}",
                                    caller_loc())
        dims = tuple(int(d) for d in dimensions)
        if len(dims) != len(ax):
            raise SimgradError(f"dense(): {len(ax)} axes but {len(dims)} sizes")
        child = SNode(self, "dense", ax, dims)
        self.children.append(child)
        return child

    def place(self, *fields, offset=None) -> SNode:
        self._check_open()
        from simgrad.lang.field import Field

        fields = tuple(p for f in fields for p in (f.placeable() if isinstance(f, Field) else [f]))
        for f in fields:
            comps = f._components() if isinstance(f, Field) else None
            if comps is None:
                raise SimgradError(f"place() expects fields, got {type(f).__name__}")
            for c in comps:
                if c.snode is not None:
                    raise SimgradError(f"field {c.name} is placed twice")
                node = SNode(self, "place")
                node.field = c
                c.snode = node
                self.children.append(node)
            if offset is not None:
                f._set_offset(offset)
        for f in fields:
            if getattr(f, "_needs_grad", False) and f.grad is not None and f.grad.snode is None:
                self.place(f.grad, offset=offset)
            dual = getattr(f, "dual", None)
            if getattr(f, "_needs_dual", False) and dual is not None and dual.snode is None:
                self.place(dual, offset=offset)
            gdual = getattr(f.grad, "dual", None) if getattr(f, "grad", None) is not None else None
            if getattr(f, "_needs_dual", False) and gdual is not None and gdual.snode is None and \
                    f.grad.snode is not None:
                self.place(gdual, offset=offset)
        return self

    def lazy_grad(self) -> None:
        """Place the gradient of every field under this node that needs one, beside its primal."""
        for node in list(self._walk()):
            g = node.field.grad if node.kind == "place" else None
            if g is not None and g.snode is None and node.field.is_primal:
                node.parent.place(g)

    def lazy_dual(self) -> None:
        """Place the dual of every float field under this node, beside its primal (forward mode)."""
        for node in list(self._walk()):
            d = getattr(node.field, "dual", None) if node.kind == "place" else None
            if d is not None and d.snode is None and not node.field.is_dual:  # primals and gradients
                node.parent.place(d)

    def _walk(self):
        yield self
        for c in self.children:
            yield from c._walk()

    # -- layout ----------------------------------------------------------------------------
    @property
    def num_cells(self) -> int:
        n = 1
        for s in self.sizes:
            n *= s
        return n

    def _layout(self) -> int:
        """Assign offsets bottom-up; returns this node's total size in bytes."""
        if self.kind == "place":
            assert self.field is not None
            size = self.field.dtype.nbytes
            self.align = size
            return size
        off = 0
        align = 1
        for c in self.children:
            size = c._layout()
            off = (off + c.align - 1) // c.align * c.align
            c.offset_in_parent = off
            off += size
            align = max(align, c.align)
        self.align = align
        self.cell_size = (off + align - 1) // align * align if off else 0
        return self.cell_size * self.num_cells

    def path(self) -> list[SNode]:
        nodes = []
        n: SNode | None = self
        while n is not None:
            nodes.append(n)
            n = n.parent
        return nodes[::-1]

    def access_terms(self) -> tuple[int, tuple[AccessTerm, ...], tuple[int, ...]]:
        """(constant byte offset, terms, shape) of a placed field, merged where strides compose."""
        path = self.path()
        const = sum(n.offset_in_parent for n in path)
        shape: dict[int, int] = {}
        for n in path:
            for a, s in zip(n.axes, n.sizes):
                shape[a] = shape.get(a, 1) * s
        # a field has as many indices as distinct axes on its path, in axis order (Taichi packs them):
        # dense(ti.k, n).dense(ti.l, m) gives x[a, b]
        position = {a: p for p, a in enumerate(sorted(shape))}
        ndim = len(position)
        inner = dict.fromkeys(range(ndim), 1)
        raw: list[AccessTerm] = []
        for n in reversed(path):  # innermost first
            if n.kind != "dense":
                continue
            row = n.cell_size
            for ax, s in reversed(list(zip(n.axes, n.sizes))):
                a = position[ax]
                raw.append(AccessTerm(a, inner[a], s, row))
                row *= s
                inner[a] *= s
        # per axis, outermost digit needs no modulo; merge digits whose strides compose
        terms: list[AccessTerm] = []
        for a in range(ndim):
            digits = [t for t in raw if t.axis == a]  # innermost first
            merged: list[AccessTerm] = []
            for t in digits:
                if merged and t.stride == merged[-1].stride * merged[-1].modulus:
                    prev = merged.pop()
                    t = AccessTerm(a, prev.divisor, prev.modulus * t.modulus, prev.stride)
                merged.append(t)
            if merged:
                last = merged[-1]
                merged[-1] = AccessTerm(a, last.divisor, 0, last.stride)
            terms.extend(merged)
        full_shape = tuple(shape[a] for a in sorted(shape))
        return const, tuple(terms), full_shape


class SNodeTree:
    """One root with its own buffer."""

    def __init__(self, program, tree_id: int):
        self.program = program
        self.id = tree_id
        self.root = SNode(None, "root")
        self.root.tree = self
        self.materialized = False
        self.buffer = None
        self.size = 0

    def materialize(self) -> None:
        if self.materialized:
            return
        self.size = max(self.root._layout(), 1)
        self.buffer = self.program.memory.allocate(self.size)
        self.program.memory.set_root(self.id, self.buffer)
        self.materialized = True
        for node in self.root._walk():
            if node.kind == "place":
                node.field._bind()


def check_placed(field) -> None:
    if field.snode is None:
        raise SimgradError(f"field {field.name} is not placed in any SNode tree (call ti.root...place())")
