"""Structural nodes (SNodes): the layout tree fields are placed in, as in Taichi.

`ti.root.dense(ti.ij, (4, 8)).place(a, b)` puts a and b side by side in each cell (AoS);
separate `place` calls on separate dense nodes give SoA. Sparse nodes (pointer, bitmasked, dynamic)
keep only a *container* in their parent's cell (slots, activity bits or a list header; see
ir/fieldref.py Level) and their cells' contents in the container (bitmasked) or in blocks from a
per-node pool (pointer, dynamic; runtime/sparse.py). A tree is materialised (its buffer allocated)
the first time a kernel or Python code touches one of its fields; after that it is frozen and
`ti.root` starts a fresh tree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from simgrad.dtypes import DataType
from simgrad.errors import SimgradError, SimgradValueError, TaichiRuntimeError, caller_loc
from simgrad.ir.fieldref import Level
from simgrad.lang.program import sync_for_host

if TYPE_CHECKING:
    from simgrad.lang.field import ScalarField


WHOLE_LIST_BYTES = 64 << 10  # a dynamic list this small is one chunk (SNode.chunk); tests set 0 to test chains


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


SPARSE_KINDS = ("pointer", "bitmasked", "dynamic")


class SNode:
    def __init__(self, parent: SNode | None, kind: str, axes_: tuple[int, ...] = (), sizes: tuple = ()):
        self._parent = parent
        self.kind = kind
        self.axes = axes_
        self.sizes = sizes
        self.children: list[SNode] = []
        self.field: ScalarField | None = None  # for 'place' nodes
        self.tree: SNodeTree | None = parent.tree if parent else None
        self.cell_size = 0
        self.offset_in_parent = 0
        self.align = 1
        self.block_size = 0  # pointer/dynamic: bytes of one block from the pool
        self.mask_offset = 0  # bitmasked: where the activity bits start in the container
        self.pool = -1  # pointer/dynamic: the program's pool for this node's blocks
        self.chunk_size: int | None = None  # dynamic: Taichi's chunk size (cells per chunk; None: the whole list)
        self.physical: DataType | None = None  # bit_struct / quant_array: the integer type of the cell (lang/quant.py)
        self.bitpack = None  # bit_struct: the ti.BitpackedFields it was made from
        self._ref: object = None  # its IR record once materialised (lang/sparse.py snode_ref)

    def parent(self, n: int = 1) -> SNode | None:
        """The n-th ancestor (Taichi's snode.parent(n)); None above the root."""
        node: SNode | None = self
        for _ in range(n):
            node = node._parent if node is not None else None
        if node is not None and node.kind == "root":  # as Taichi: any tree's root is ti.root
            from simgrad.lang.factories import root

            return root  # type: ignore[return-value]
        return node

    @property
    def is_sparse(self) -> bool:
        return self.kind in SPARSE_KINDS

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
        return self._child("dense", indices, dimensions)

    def pointer(self, indices, dimensions) -> SNode:
        """Cells allocated from a pool when first written (or ti.activate), freed by ti.deactivate."""
        return self._child("pointer", indices, dimensions)

    def bitmasked(self, indices, dimensions) -> SNode:
        """Cells stored densely with one activity bit each: a struct-for visits only the active ones."""
        return self._child("bitmasked", indices, dimensions)

    def dynamic(self, index, dimension, chunk_size=None) -> SNode:
        """A list along one axis of at most `dimension` cells: ti.append adds, ti.length counts."""
        if isinstance(index, (tuple, list)):
            if len(index) != 1:
                raise SimgradError("dynamic(): a dynamic SNode has exactly one axis", caller_loc())
            index = index[0]
        if chunk_size is not None and (isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer))
                                       or not 0 < chunk_size < 2**31):
            raise SimgradError(f"dynamic(): chunk_size must be a positive 32-bit integer, got {chunk_size!r}",
                               caller_loc())
        node = self._child("dynamic", index, dimension)
        node.chunk_size = None if chunk_size is None else int(chunk_size)
        return node

    @property
    def chunk(self) -> int:
        """A dynamic node's cells per chunk: Taichi's chunk_size (the whole list by default, as Taichi's), except
        that a list of at most WHOLE_LIST_BYTES is one chunk: its elements are then read by index from the
        list's one block, with no walk along a chain (a loop over marching_squares' 1024 edges in chunks of 32
        ran 1.5x slower walking); the memory a list may take stays that small."""
        c = min(self.chunk_size or self.num_cells, self.num_cells)
        if c < self.num_cells and 0 < self.cell_size * self.num_cells <= WHOLE_LIST_BYTES:
            return self.num_cells
        return c

    def quant_array(self, indices, dimensions, max_num_bits) -> SNode:
        """Cells of one quant field packed side by side into a single physical integer of max_num_bits bits
        (lang/quant.py): `quant_array(ti.i, 32, max_num_bits=32).place(x)` stores 32 1-bit elements in a u32."""
        from simgrad.lang.quant import physical_type

        node = self._child("quant_array", indices, dimensions)
        node.physical = physical_type(max_num_bits)
        return node

    def hash(self, *args, **kwargs):
        from simgrad.errors import SimgradNotSupportedError

        raise SimgradNotSupportedError("hash SNodes were removed from Taichi and are not built in simgrad",
                                       caller_loc())

    def _child(self, kind: str, indices, dimensions) -> SNode:
        self._check_open()
        if isinstance(indices, Axis):
            indices = (indices,)
        ax = tuple(a.index for a in indices)
        if isinstance(dimensions, (int, np.integer)):
            dimensions = (dimensions,) * len(ax)
        if any(isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 0 for d in dimensions):
            raise SimgradValueError(f"{kind}(): sizes must be non-negative integers, got {dimensions!r}",
                                    caller_loc())
        dims = tuple(int(d) for d in dimensions)
        if len(dims) == 1:  # one size for every axis, as Taichi's SNode::create_node broadcasts it
            dims = dims * len(ax)
        if len(dims) != len(ax):
            raise SimgradError(f"{kind}(): {len(ax)} axes but {len(dims)} sizes")
        child = SNode(self, kind, ax, dims)
        self.children.append(child)
        return child

    def place(self, *fields, offset=None) -> SNode:
        self._check_open()
        from simgrad.lang.field import Field
        from simgrad.lang.quant import BitpackedFields, check_array_member

        packs = [f for f in fields if isinstance(f, BitpackedFields)]
        for pack in packs:
            self._place_bitpack(pack, offset)
        fields = tuple(p for f in fields if not isinstance(f, BitpackedFields)
                       for p in (f.placeable() if isinstance(f, Field) else [f]))
        for f in fields:
            comps = f._components() if isinstance(f, Field) else None
            if comps is None:
                raise SimgradError(f"place() expects fields, got {type(f).__name__}")
            for c in comps:
                if c.snode is not None:
                    raise SimgradError(f"field {c.name} is placed twice")
                if self.kind == "quant_array":
                    check_array_member(self, c)
                elif getattr(c, "quant_type", None) is not None and self.kind != "bit_struct":
                    raise SimgradError(f"field {c.name} has a quant type: place it in a ti.BitpackedFields (then "
                                       "place that) or under ti.root.quant_array(...)", caller_loc())
                node = SNode(self, "place")
                node.field = c
                c.snode = node
                self.children.append(node)
            if offset is not None:
                f._set_offset(offset)
        return self

    def place_companions(self, fields, offset=None) -> None:
        """Place the gradient and dual of each of `fields` that was made with needs_grad / needs_dual here
        (a struct field made with a shape: its members' companions beside them). place() itself never does:
        as in Taichi, a field placed by the user needs its gradient placed too (or ti.root.lazy_grad())."""
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

    def _place_bitpack(self, pack, offset) -> None:
        """A BitpackedFields becomes one `bit_struct` node: a physical integer per cell of this node, each
        member field a place node in it (lang/quant.py slot_of reads the bits from the pack)."""
        if pack.placed:
            raise SimgradError("this BitpackedFields is placed twice", caller_loc())
        if not pack.fields():
            raise SimgradError("BitpackedFields placed with no fields in it", caller_loc())
        node = SNode(self, "bit_struct")
        node.physical = pack.physical
        node.bitpack = pack
        self.children.append(node)
        pack.placed = True
        node.place(*pack.fields(), offset=offset)

    @property
    def _num_dynamically_allocated(self) -> int:
        """Taichi's count of blocks ever allocated for this node (pointer/dynamic; 0 for others)."""
        return self.memory_usage()["touched_blocks"] if self.kind in ("pointer", "dynamic") else 0

    @property
    def _cell_size_bytes(self) -> int:
        """Taichi's layout inspection: the bytes of one cell of this node (a place node: its value's)."""
        self._lay_out()
        return self.field.dtype.nbytes if self.kind == "place" and self.field is not None else self.cell_size

    @property
    def _offset_bytes_in_parent_cell(self) -> int:
        """Taichi's layout inspection: where this node starts in a cell of its parent."""
        self._lay_out()
        return self.offset_in_parent

    def _lay_out(self) -> None:
        """Offsets as materialising will give them (laying out is a pure function of the tree's structure)."""
        if self.tree is not None and not self.tree.materialized:
            self.tree.root._layout()

    @property
    def _snode_tree_id(self) -> int:
        assert self.tree is not None
        return self.tree.id

    def memory_usage(self) -> dict[str, int]:
        """A sparse node's pool: blocks in use (`live_blocks`), blocks ever handed out (`touched_blocks`:
        resident memory, reused after deactivation, given back to the system by ti.reset / ti.init),
        `block_bytes` and `touched_bytes`."""
        if not self.is_sparse:
            raise SimgradError(f"memory_usage() is for pointer, bitmasked and dynamic nodes, not {self.kind}",
                               caller_loc())
        assert self.tree is not None
        self.tree.materialize()
        sync_for_host()  # the pool table is the kernels' (arch=cuda: device memory they may still be updating)
        return self.tree.program.sparse.usage_of(self.pool)

    def deactivate_all(self) -> None:
        """Deactivate every cell of every sparse node at or under this one (deepest first, so no block
        is freed while it still points to others). Freed blocks stay with their pool, zeroed, for the
        next activations (as Taichi keeps them): their pages are not faulted in again."""
        from simgrad.lang import scope_hooks

        if self.tree is None:
            return
        self.tree.materialize()
        nodes = [n for n in self._walk() if n.is_sparse]
        for n in sorted(nodes, key=lambda n: -len(n.path())):
            scope_hooks.sparse.deactivate_all(n)  # freed blocks are zeroed and kept for the next activations
            if n.kind != "bitmasked":
                sync_for_host()
                n.tree.program.sparse.restart_if_empty(n.pool)

    def lazy_grad(self) -> None:
        """Place the gradient of every field under this node that needs one, beside its primal."""
        for node in list(self._walk()):
            g = node.field.grad if node.kind == "place" else None
            if g is not None and g.snode is None and node.field.is_primal:
                node._parent.place(g)

    def lazy_dual(self) -> None:
        """Place the dual of every float field under this node, beside its primal (forward mode)."""
        for node in list(self._walk()):
            d = getattr(node.field, "dual", None) if node.kind == "place" else None
            if d is not None and d.snode is None and not node.field.is_dual:  # primals and gradients
                node._parent.place(d)

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
        """Assign offsets bottom-up; returns the bytes this node takes in a cell of its parent."""
        if self.kind == "place":
            assert self.field is not None
            size = self.field.dtype.nbytes
            self.align = size
            return size
        if self.kind in ("bit_struct", "quant_array"):  # one physical integer holds every cell's bits
            assert self.physical is not None
            for c in self.children:
                c.offset_in_parent = 0
            self.cell_size = 0 if self.kind == "quant_array" else self.physical.nbytes
            self.align = self.physical.nbytes
            return self.physical.nbytes
        off = 0
        align = 1
        for c in self.children:
            size = c._layout()
            off = (off + c.align - 1) // c.align * c.align
            c.offset_in_parent = off
            off += size
            align = max(align, c.align)
        self.cell_size = (off + align - 1) // align * align if off else 0
        if self.kind == "pointer":  # one 8-byte slot per cell; the cell itself is a block
            self.block_size = max(8, (self.cell_size + 7) // 8 * 8)
            self.align = 8
            return 8 * self.num_cells
        if self.kind == "dynamic":  # header: i32 length, i32 lock, the first chunk: {next chunk, cells}
            self.block_size = 8 + (self.cell_size * self.chunk + 7) // 8 * 8
            self.align = 8
            return 16
        self.align = align
        if self.kind == "bitmasked":
            self.mask_offset = (self.cell_size * self.num_cells + 3) // 4 * 4
            self.align = max(align, 4)
            return self.mask_offset + 4 * ((self.num_cells + 31) // 32)
        return self.cell_size * self.num_cells

    def path(self) -> list[SNode]:
        nodes = []
        n: SNode | None = self
        while n is not None:
            nodes.append(n)
            n = n._parent
        return nodes[::-1]

    @property
    def shape(self) -> tuple[int, ...]:
        """The index space of this node's cells (Taichi's snode.shape): per distinct axis on the path,
        the product of its sizes from the root down to here, in axis order."""
        sizes: dict[int, int] = {}
        for n in self.path():
            for a, s in zip(n.axes, n.sizes):
                sizes[a] = sizes.get(a, 1) * s
        return tuple(sizes[a] for a in sorted(sizes))

    def has_sparse_path(self) -> bool:
        return any(n.is_sparse for n in self.path())

    def levels(self) -> tuple[Level, ...]:
        """The path from the root down to this node as ir/fieldref.py Levels; an index of this node's
        shape names a cell at every level. Dense levels take their digits like access_terms."""
        path = self.path()[1:]
        if self.kind == "place":
            path = path[:-1]
        path = [n for n in path if n.kind != "bit_struct"]  # within a cell: the value offset covers it
        axes_ = sorted({a for n in path for a in n.axes})
        position = {a: p for p, a in enumerate(axes_)}
        below = dict.fromkeys(axes_, 1)  # product of the sizes along each axis under the current level
        out: list[tuple[SNode, list[AccessTerm]]] = []
        for n in reversed(path):
            terms = []
            weight = 1
            for ax, size in reversed(list(zip(n.axes, n.sizes))):
                terms.append(AccessTerm(position[ax], below[ax], size, weight))
                weight *= size
                below[ax] *= size
            out.append((n, terms))
        levels = []
        first_use: set[int] = set()
        for n, terms in reversed(out):  # outermost first: the outermost digit of an axis has no modulus
            terms = [AccessTerm(t.axis, t.divisor, 0 if t.axis not in first_use else t.modulus, t.stride)
                     for t in terms]
            first_use.update(t.axis for t in terms)
            total = 1
            for m in n.path()[1:]:
                total *= m.num_cells
            kind = "dense" if n.kind == "quant_array" else n.kind  # bits of one cell: 0-byte cells
            levels.append(Level(kind, n.offset_in_parent, tuple(terms[::-1]), n.cell_size, n.num_cells,
                                n.pool, n.mask_offset, total, n.chunk if n.kind == "dynamic" else 0))
        return tuple(levels)

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
            if n.kind == "quant_array":  # its cells are bits of one integer: digits above it skip its sizes
                for ax, s in zip(n.axes, n.sizes):
                    inner[position[ax]] *= s
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
        self.destroyed = False
        self._buffer: np.ndarray | None = None
        self.size = 0

    @property
    def buffer(self) -> np.ndarray | None:
        """The tree's memory for Python scope (a Tape's snapshot): after the device is done with it."""
        sync_for_host()
        return self._buffer

    @buffer.setter
    def buffer(self, v: np.ndarray | None) -> None:
        self._buffer = v

    def destroy(self) -> None:
        """`tree.destroy()` (Taichi's SNodeTree.destroy): its fields refuse every further use (a located
        TaichiRuntimeError), the tree's buffer is dropped and its memory returned (runtime/memory.py release), and
        every kernel compiles again (as Taichi clears
        its compiled functions), so none reaches the old memory. A second destroy is Taichi's error."""
        if self.destroyed:
            raise TaichiRuntimeError("SNode tree has been destroyed", caller_loc())
        from simgrad.lang.program import get_program

        if self.program is not get_program():  # a tree of a program ti.reset released: nothing to do (Taichi)
            return
        self.destroyed = True
        for node in self.root._walk():
            if node.kind == "place":
                node.field.view = None
                node.field.gather = None
        self.buffer = None
        self.program.memory.release(self.id)  # its pages go back to the system
        self.program.bump_generation()

    def materialize(self) -> None:
        if self.materialized:
            return
        self.size = max(self.root._layout(), 1)
        self._add_pools(self.root, 1)
        self.buffer = self.program.memory.allocate(self.size)
        self.program.memory.set_root(self.id, self.buffer)
        self.materialized = True
        for node in self.root._walk():
            if node.kind == "place":
                node.field._bind()


    def _add_pools(self, node: SNode, instances: int) -> None:
        """A pool for every sparse node: blocks for each cell a pointer could activate (or each chunk of each
        list of a dynamic node), and the zero and discard blocks every sparse node reads and writes through.
        A dynamic node gets no struct-for lists (a struct-for runs along its lists by their lengths)."""
        for c in node.children:
            if c.kind == "place":
                continue
            if c.is_sparse:
                blocks = {"pointer": instances * c.num_cells, "bitmasked": 0,
                          "dynamic": instances * -(-c.num_cells // c.chunk)}[c.kind]
                size = c.block_size if c.kind != "bitmasked" else c.cell_size
                lists = 0 if c.kind == "dynamic" else instances * c.num_cells
                c.pool = self.program.sparse.add_pool(size, blocks, lists, line=c.kind != "dynamic")
            self._add_pools(c, instances * c.num_cells)


def check_placed(field) -> None:
    if field.snode is None:
        raise SimgradError(f"field {field.name} is not placed in any SNode tree (call ti.root...place())")


def new_tree(program) -> SNodeTree:
    """A new SNode tree of `program` (lang/program.py holds the trees and imports no SNode code)."""
    tree = SNodeTree(program, len(program.trees))
    program.trees.append(tree)
    return tree


def root_tree(program) -> SNodeTree:
    """The tree `ti.root` builds into; a fresh one once the previous was materialised."""
    if program._open_tree is None or program._open_tree.materialized:
        program._open_tree = new_tree(program)
    return program._open_tree
