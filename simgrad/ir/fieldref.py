"""What the IR knows of a field or an ndarray argument: records of where and how elements are laid out.

A GLOBAL_PTR of a field refers to a FieldRef (attrs["target"]), built by the frontend from the lang-level
field (lang/field.py ScalarField.ref()). Passes, autodiff and codegen read only this record, never the
Field: that is what keeps them free of `simgrad.lang`. A field under sparse SNodes (pointer, bitmasked,
dynamic) also carries its path as `levels`, which passes/lower_access.py walks level by level."""

from __future__ import annotations

from dataclasses import dataclass, field

from simgrad.dtypes import DataType


@dataclass(frozen=True)
class Level:
    """One SNode on the path of a field that has sparse SNodes on it, outermost first.

    The node's *container* sits `offset` bytes into a cell of its parent (the tree's root buffer for the
    first level). Its `terms` (AccessTerm: axis, divisor, modulus, stride) give the number of the cell an
    index names, in cells (strides count cells, not bytes). Per kind, the container holds:
    dense: the cells, `cell_size` bytes each; bitmasked: the cells, then one activity bit per cell in u32
    words at `mask_offset`; pointer: one 8-byte slot per cell pointing to the cell's block (allocated
    from pool `pool` when the cell is activated, null while inactive); dynamic: a 16-byte header (i32
    length, i32 lock, then the pointer to the first of a chain of chunks from `pool`, each an 8-byte link to
    the next and `chunk` cells, allocated as writes reach them; `ncells` is the list's most cells)."""

    kind: str
    offset: int
    terms: tuple
    cell_size: int
    ncells: int
    pool: int = -1
    mask_offset: int = 0
    total_cells: int = 0  # cells of this node in the whole tree (the length of its struct-for lists)
    chunk: int = 0  # dynamic: cells per chunk

    @property
    def sparse(self) -> bool:
        return self.kind != "dense"


@dataclass(frozen=True)
class QuantSlot:
    """Where a quant field's value sits in its physical cell (an unsigned integer of type `physical`; the
    field's layout addresses the cell) and how it is coded (lang/quant.py; passes/quant.py expands accesses).

    kind: "int" (two's complement or unsigned `bits` bits), "fixed" (digits of `bits` bits times `scale`) or
    "float" (`bits` digits, the sign bit among them when signed, and an unsigned exponent of `exp_bits` bits
    at bit `exp_offset`). `offset`: the first bit. A quant_array element adds `number * bits`, with
    number = sum((I[position] % modulus) * weight) over `array`. A float whose exponent is shared lists
    every member using it in `shared` as (bit offset, bits, signed), itself included. `compute`: the type
    kernels see (the field's dtype). `used`: how many low bits of the cell its members take (the rest are
    always zero)."""

    kind: str
    physical: DataType
    bits: int
    signed: bool
    offset: int
    array: tuple = ()
    scale: float = 1.0
    exp_bits: int = 0
    exp_offset: int = 0
    shared: tuple = ()
    compute: DataType | None = None
    used: int = 0


@dataclass(frozen=True)
class SNodeRef:
    """An SNode as the IR sees it (the target of ti.activate / is_active / deactivate / append / length):
    the levels from the root down to it and the number of indices that address its cells."""

    name: str
    tree_id: int
    levels: tuple
    ndim: int

    def ir_name(self) -> str:
        return self.name


@dataclass(eq=False)
class FieldRef:
    name: str
    dtype: DataType
    #: (tree id, constant byte offset, access terms (lang/snode.py AccessTerm), shape)
    layout: tuple
    #: index offsets of the field (ti.field(..., offset=...)), None when all zero
    offset: tuple | None = None
    #: the record of the placed gradient field, None when there is none
    grad: FieldRef | None = None
    #: the lang-level field this describes; opaque below lang (Tape validation reads values through it)
    owner: object = field(default=None, repr=False)
    #: the record of the placed dual (forward-mode tangent) field, None when there is none
    dual: FieldRef | None = None
    #: the SNodes of the path when one of them is sparse (Level, outermost first), else () (dense:
    #: `layout` says everything); then the value sits `value_offset` bytes into a cell of the last level
    levels: tuple = ()
    value_offset: int = 0
    #: a quant field's bits in its physical cell (the layout then addresses the cell), None otherwise
    quant: QuantSlot | None = None

    @property
    def sparse(self) -> bool:
        return bool(self.levels)

    @property
    def shape(self) -> tuple:
        return self.layout[3]

    def ir_name(self) -> str:
        return self.name


@dataclass(eq=False)
class ArrayRef:
    """One scalar component of an ndarray argument's elements (a GLOBAL_PTR's target; ARRAY_SHAPE names any
    component of the argument): the base pointer is context slot `slot`, the run-time extents follow it."""

    name: str
    slot: int
    dtype: DataType
    ndim: int
    element_shape: tuple = ()
    comp: int = 0
    #: the same component of the argument's gradient array (its base in another slot), None when none
    grad: ArrayRef | None = None
    #: the slot whose following slots hold the extents (a gradient array reads its primal's)
    shape_slot: int = -1

    @property
    def extents_slot(self) -> int:
        return self.slot if self.shape_slot < 0 else self.shape_slot

    @property
    def num_components(self) -> int:
        n = 1
        for e in self.element_shape:
            n *= e
        return n

    def ir_name(self) -> str:
        return f"arg{self.slot}.{self.comp}" if self.num_components > 1 else f"arg{self.slot}"
