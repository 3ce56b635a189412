"""What the IR knows of a field or an ndarray argument: records of where and how elements are laid out.

A GLOBAL_PTR of a field refers to a FieldRef (attrs["target"]), built by the frontend from the lang-level
field (lang/field.py ScalarField.ref()). Passes, autodiff and codegen read only this record, never the
Field: that is what keeps them free of `simgrad.lang`, and where sparse SNode kinds will plug in (their
per-level kinds go in `kinds`; passes/lower_access.py expands by kind)."""

from __future__ import annotations

from dataclasses import dataclass, field

from simgrad.dtypes import DataType


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
    #: SNode kind of each level on the path, outermost first
    kinds: tuple = ("dense",)
    #: the lang-level field this describes; opaque below lang (Tape validation reads values through it)
    owner: object = field(default=None, repr=False)
    #: the record of the placed dual (forward-mode tangent) field, None when there is none
    dual: FieldRef | None = None

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
