"""What the IR knows of a field: a record of where and how its elements are laid out.

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

    @property
    def shape(self) -> tuple:
        return self.layout[3]

    def ir_name(self) -> str:
        return self.name
