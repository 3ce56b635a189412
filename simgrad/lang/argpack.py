"""`ti.types.argpack`: a kernel parameter type that bundles other parameters (scalars, vectors, structs,
ndarrays, argpacks) under one name, as Taichi 1.7.4 has it. A pack is only a way of passing arguments: each
member travels as the parameter it would be on its own (compiler/params.py ArgPackParam), so it is neither a
struct member nor a return type."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError, caller_loc
from simgrad.lang.struct import StructType
from simgrad.lang.types import MatrixType, NdarrayType


def _type_text(t) -> str:
    return t.name if isinstance(t, dt.DataType) else repr(t)


class ArgPackType:
    """The members' names and parameter types, in order; calling it makes an ArgPack value."""

    _argpack = True  # what lang/struct.py refuses as a member type (it cannot import this module)

    def __init__(self, members: dict):
        self.members: dict = {}
        for k, t in members.items():
            if isinstance(t, (MatrixType, StructType, NdarrayType, ArgPackType)) or t is NdarrayType:
                self.members[k] = t
            elif isinstance(t, dict):
                self.members[k] = StructType(t)
            else:
                try:
                    self.members[k] = dt.from_any(t)
                except TypeError:
                    raise SimgradTypeError(f"an argpack member must be a scalar, vector/matrix, struct, ndarray "
                                           f"or argpack type, got {t!r}", caller_loc()) from None

    def __call__(self, *args, **kwargs) -> ArgPack:
        if len(args) > len(self.members):
            raise SimgradTypeError(f"{self!r} has {len(self.members)} members, got {len(args)} values", caller_loc())
        given = dict(zip(self.members, args))
        for k, v in kwargs.items():
            if k not in self.members:
                raise SimgradTypeError(f"{self!r} has no member '{k}' (members: {', '.join(self.members)})",
                                       caller_loc())
            given[k] = v
        missing = [k for k in self.members if k not in given]
        if missing:
            raise SimgradTypeError(f"{self!r}: no value for member(s) {', '.join(missing)}", caller_loc())
        return ArgPack(self, {k: given[k] for k in self.members})

    def __repr__(self) -> str:
        return "<ti.ArgPackType " + ", ".join(f"{k}={_type_text(t)}" for k, t in self.members.items()) + ">"


class ArgPack:
    """A value of an ArgPackType: its members as attributes (the kernel's parameter reads them)."""

    def __init__(self, ptype: ArgPackType, values: dict):
        self._type = ptype
        self.__dict__.update(values)

    def __repr__(self) -> str:
        return "<ti.ArgPack " + ", ".join(f"{k}={getattr(self, k)!r}" for k in self._type.members) + ">"


def argpack(**members) -> ArgPackType:
    """`ti.types.argpack(a=ti.i32, v=ti.math.vec3, arr=ti.types.ndarray(...))`."""
    return ArgPackType(members)
