"""Structs as Taichi has them: `ti.types.struct(pos=vec3, m=ti.f32)`, `@ti.dataclass` classes (members from
annotations, ti.func methods), `ti.Struct` values and `ti.Struct.field` / `Type.field` fields.

A struct value is its members (scalars, matrices, nested structs); a struct field is one field per member
placed side by side under the same SNode, so kernels, autodiff and codegen see only ordinary fields.
Inside kernels the frontend handles struct locals and elements as refs of their members
(frontend/refs.py StructRef), which is what makes `p.pos += v` and `f[i].vel = w` assignments."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.errors import SimgradSyntaxError, SimgradTypeError, SimgradValueError, caller_loc
from simgrad.lang import operators
from simgrad.lang.field import Field, FieldElement, ScalarField
from simgrad.lang.matrix import Matrix
from simgrad.lang.types import MatrixType


def _member_type(t):
    if getattr(t, "_argpack", False):  # an argpack only passes kernel arguments (Taichi's message)
        raise SimgradValueError(f"Invalid data type {t!r}", caller_loc())
    if isinstance(t, (MatrixType, StructType)):
        return t
    if isinstance(t, dict):
        return StructType(t)
    try:
        return dt.from_any(t)
    except TypeError:
        raise SimgradTypeError(f"a struct member's type must be a scalar, vector/matrix or struct type, got "
                               f"{t!r}", caller_loc()) from None


class StructType:
    """The type of a struct: ordered members, and the ti.func methods of a @ti.dataclass."""

    def __init__(self, members: dict, methods: dict | None = None, name: str = "Struct"):
        self.members = {k: _member_type(v) for k, v in members.items()}
        self.methods = dict(methods or {})
        self.py_methods: dict = {}
        self.name = name

    def __call__(self, *args, **kwargs) -> Struct:
        """A value of this type: members by position or name (a dict or a struct works too), the rest 0."""
        one = args[0] if len(args) == 1 and not kwargs else None
        if isinstance(one, dict) or (isinstance(one, Struct) and one._type in (None, self)):
            kwargs = dict(args[0].items()) if isinstance(args[0], Struct) else dict(args[0])
            args = ()
        if len(args) > len(self.members):
            raise SimgradTypeError(f"{self.name} has {len(self.members)} members, got {len(args)} values",
                                   caller_loc())
        given = dict(zip(self.members, args))
        for k, v in kwargs.items():
            if k not in self.members:
                raise SimgradTypeError(f"{self.name} has no member '{k}' (members: {', '.join(self.members)})",
                                       caller_loc())
            given[k] = v
        return Struct._typed(self, {k: _convert(t, given.get(k, 0)) for k, t in self.members.items()})

    def leaves(self, prefix: tuple = ()) -> list[tuple[tuple, object]]:
        """(path, scalar or matrix type) of every non-struct member, nested structs flattened, in order."""
        out: list[tuple[tuple, object]] = []
        for k, t in self.members.items():
            out += t.leaves(prefix + (k,)) if isinstance(t, StructType) else [(prefix + (k,), t)]
        return out

    def from_leaves(self, values: list) -> Struct:
        """The struct whose leaves (in `leaves()` order) are `values`."""
        it = iter(values)

        def build(t: StructType) -> Struct:
            return Struct._typed(t, {k: build(m) if isinstance(m, StructType) else next(it)
                                     for k, m in t.members.items()})

        return build(self)

    def cast(self, value) -> Struct:
        return self(value)

    def field(self, shape=None, name: str = "", offset=None, needs_grad: bool = False, needs_dual: bool = False,
              layout=None) -> StructField:
        from simgrad.lang.factories import place_struct_field

        return place_struct_field(self, shape, name, offset, needs_grad, needs_dual)

    def __repr__(self) -> str:
        return f"<struct {self.name} {{{', '.join(f'{k}: {v}' for k, v in self.members.items())}}}>"


def _convert(t, v):
    if isinstance(t, StructType):
        # a value that is not a struct goes to the first member, as a positional argument would (Taichi's
        # `mystruct(1)` sets line.linedir to 1 and leaves the rest 0); it was dropped
        return v if isinstance(v, Struct) and v._type is t else t(v)
    if isinstance(t, MatrixType):
        return t.make(v)
    return operators.cast(v, t)


def _zero_dict(value) -> dict:
    return dict(value.items()) if isinstance(value, (Struct, StructElement)) else dict(value)


class Struct:
    """A struct value (`ti.Struct(a=1, v=vec)`, or made by a struct type); members are attributes."""

    def __init__(self, *args, **kwargs):
        entries = dict(args[0]) if args else {}
        entries.update(kwargs)
        object.__setattr__(self, "_type", None)
        object.__setattr__(self, "_values", entries)

    @classmethod
    def _typed(cls, stype: StructType, values: dict) -> Struct:
        s = cls.__new__(cls)
        object.__setattr__(s, "_type", stype)
        object.__setattr__(s, "_values", values)
        return s

    def __getattr__(self, name):
        values = object.__getattribute__(self, "_values")
        if name in values:
            return values[name]
        stype = object.__getattribute__(self, "_type")
        if stype is not None and name in stype.methods:
            return stype.methods[name].__get__(self)
        if stype is not None and name in stype.py_methods:
            return stype.py_methods[name].__get__(self)
        raise AttributeError(f"struct has no member '{name}'")

    def __setattr__(self, name, value):
        if name not in self._values:
            raise AttributeError(f"struct has no member '{name}'")
        t = self._type.members[name] if self._type is not None else None
        self._values[name] = _convert(t, value) if t is not None else value

    def keys(self):
        return self._values.keys()

    def items(self):
        return self._values.items()

    def to_dict(self) -> dict:
        return {k: (v.to_dict() if isinstance(v, Struct) else v.to_numpy() if isinstance(v, Matrix) else v)
                for k, v in self._values.items()}

    @staticmethod
    def field(members: dict, shape=None, name: str = "", offset=None, needs_grad: bool = False,
              needs_dual: bool = False, layout=None) -> StructField:
        """`ti.Struct.field({"pos": vec3, "m": ti.f32}, shape=n)`."""
        return StructType(members).field(shape, name, offset, needs_grad, needs_dual, layout)

    def __repr__(self) -> str:
        return "{" + ", ".join(f"'{k}': {v}" for k, v in self._values.items()) + "}"


class StructField(Field):
    """A field of structs: one field per member (`f.pos` is the member field), placed together."""

    def __init__(self, stype: StructType, members: dict, name: str):
        object.__setattr__(self, "stype", stype)
        object.__setattr__(self, "members", members)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "grad", None)
        object.__setattr__(self, "dual", None)
        object.__setattr__(self, "_needs_grad", False)

    @property
    def dtype(self):  # type: ignore[override]
        return self.stype

    def _components(self) -> list[ScalarField]:
        return [c for f in self.members.values() for c in f._components()]

    def _ready(self) -> bool:
        """Every member's memory is there (placed, materialised, its program alive): Python-scope access needs no
        _ensure, the cheap test in front of each `s[i].member`."""
        comps = self.__dict__.get("_comps")
        if comps is None:  # (the members never change once the field is made)
            comps = self._components()
            object.__setattr__(self, "_comps", comps)
        return all(c._materialised() for c in comps)

    def placeable(self) -> list[Field]:
        """The ordinary fields to place: every member's (nested structs flattened)."""
        out: list[Field] = []
        for f in self.members.values():
            out += f.placeable() if isinstance(f, StructField) else [f]
        return out

    def __getattr__(self, name):
        members = object.__getattribute__(self, "members")
        if name in members:
            return members[name]
        raise AttributeError(f"struct field {object.__getattribute__(self, 'name')} has no member '{name}'")

    def __setattr__(self, name, value):
        if name in self.members:
            raise AttributeError(f"member field '{name}' of {self.name} cannot be replaced; assign its elements")
        object.__setattr__(self, name, value)

    def adopt_name(self, name: str) -> None:
        if not self._auto_name:
            return
        object.__setattr__(self, "_auto_name", False)
        object.__setattr__(self, "name", name)
        for k, f in self.members.items():
            f._auto_name = True
            f.adopt_name(f"{name}.{k}")

    def _set_offset(self, offset):
        for f in self.members.values():
            f._set_offset(offset)

    def __getitem__(self, key):
        if not self._ready():
            self._ensure()
        return StructElement(self, key)

    def __setitem__(self, key, value):
        self._ensure()
        values = _zero_dict(value)
        for k, v in values.items():
            if k not in self.members:
                raise SimgradTypeError(f"struct field {self.name} has no member '{k}'", caller_loc())
            self.members[k][key] = v.to_dict() if isinstance(v, Struct) and isinstance(self.members[k],
                                                                                         StructField) else v

    def to_numpy(self) -> dict:
        return {k: f.to_numpy() for k, f in self.members.items()}

    def from_numpy(self, arrays: dict) -> None:
        for k, a in arrays.items():
            if k not in self.members:
                raise SimgradTypeError(f"struct field {self.name} has no member '{k}'", caller_loc())
            self.members[k].from_numpy(a)

    def fill(self, value) -> None:
        for f in self.members.values():
            f.fill(value)

    def to_torch(self, device=None) -> dict:
        return {k: f.to_torch(device) for k, f in self.members.items()}

    def from_torch(self, tensors: dict) -> None:
        """Each member from the tensor of its name (Taichi's dict form, as from_numpy)."""
        self.from_numpy({k: t.detach().cpu().numpy() for k, t in tensors.items()})

    def copy_from(self, other: StructField) -> None:
        self.from_numpy(other.to_numpy())

    def __repr__(self) -> str:
        return f"<StructField {self.name} {list(self.members)}>"


class StructElement:
    """`f[i]` of a struct field in Python scope: a live view; member assignment writes through."""

    __slots__ = ("_field", "_key")

    def __init__(self, field: StructField, key):
        object.__setattr__(self, "_field", field)
        object.__setattr__(self, "_key", key)

    def __getattr__(self, name):
        f = self._field.members.get(name)
        if f is None:
            raise AttributeError(f"struct field {self._field.name} has no member '{name}'")
        return f[self._key]

    def __setattr__(self, name, value):
        f = self._field.members.get(name)
        if f is None:
            raise AttributeError(f"struct field {self._field.name} has no member '{name}'")
        f[self._key] = value

    def keys(self):
        return self._field.members.keys()

    def items(self):
        return [(k, getattr(self, k)) for k in self._field.members]

    def to_dict(self) -> dict:
        out = {}
        for k, v in self.items():
            out[k] = v.to_dict() if isinstance(v, StructElement) else v.to_numpy() if isinstance(
                v, FieldElement) else v
        return out

    def __repr__(self) -> str:
        return repr(self.to_dict())


def struct_type(members: dict) -> StructType:
    """`ti.types.struct(**members)`, with Taichi's `__struct_methods` entry (a dict of methods) taken out."""
    members = dict(members)
    methods = members.pop("__struct_methods", None) or {}
    if not isinstance(methods, dict):
        raise SimgradTypeError(f"__struct_methods must be a dict of name: function, got {methods!r}", caller_loc())
    stype = StructType(members)
    _add_methods(stype, methods)
    return stype


def _add_methods(stype: StructType, namespace: dict) -> None:
    from simgrad.lang.functions import Func

    stype.methods = {k: v for k, v in namespace.items() if isinstance(v, Func)}
    # plain Python methods work on Python-scope struct values (`b.add_python(b)`)
    stype.py_methods = {k: v for k, v in namespace.items()
                        if callable(v) and not isinstance(v, Func) and not k.startswith("__")}


def dataclass(cls):
    """@ti.dataclass: a struct type from the class's annotations; its ti.func methods become the struct's
    methods (called on struct values, locals and field elements, `self` being the struct)."""

    ann = dict(getattr(cls, "__annotations__", {}))
    defaults = [k for k in ann if k in vars(cls)]
    if defaults:
        raise SimgradSyntaxError(f"Default value in @dataclass is not supported (member '{defaults[0]}' of "
                                 f"{cls.__name__})", caller_loc())
    stype = StructType(ann, name=cls.__name__)
    _add_methods(stype, vars(cls))
    return stype


def is_struct_value(v) -> bool:
    return isinstance(v, Struct)


def member_zero(t):
    """A zero of member type `t` (what an unset member holds)."""
    return _convert(t, 0)


