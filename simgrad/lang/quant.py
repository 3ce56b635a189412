"""Quantized types (Taichi's QuanTaichi): `ti.types.quant.int / fixed / float`, `ti.BitpackedFields` and what
a quant field needs to know of where its bits are.

A quant field computes in an ordinary type (its `dtype`: i32/u32 for ints, f32 for fixed and floats) and
stores its value in a few bits of a physical integer cell (u8/u16/u32/u64) that a BitpackedFields (SNode kind
`bit_struct`) or `ti.root.quant_array` (kind `quant_array`) places. `slot_of(field)` describes those bits
as an ir/fieldref.py QuantSlot; passes/quant.py turns every access into integer IR on the cell."""

from __future__ import annotations

import builtins
from dataclasses import dataclass

from simgrad import dtypes as dt
from simgrad.errors import SimgradError, SimgradSyntaxError, SimgradTypeError, SimgradValueError, caller_loc
from simgrad.ir.fieldref import QuantSlot

i32 = dt.i32
_PHYSICAL = {8: dt.u8, 16: dt.u16, 32: dt.u32, 64: dt.u64}


@dataclass(frozen=True)
class QuantInt:
    """`ti.types.quant.int(bits, signed, compute)`: a `bits`-bit two's complement (or unsigned) integer."""

    bits: builtins.int
    signed: builtins.bool
    compute: dt.DataType

    @property
    def storage_bits(self) -> builtins.int:
        return self.bits

    def __repr__(self) -> str:
        return f"q{'i' if self.signed else 'u'}{self.bits}"


class _OnDigits:
    """A quant type whose bits and sign are those of its digits (fixed and float)."""

    digits: QuantInt

    @property
    def storage_bits(self) -> builtins.int:
        return self.digits.bits

    @property
    def signed(self) -> builtins.bool:
        return self.digits.signed


@dataclass(frozen=True)
class QuantFixed(_OnDigits):
    """`ti.types.quant.fixed(...)`: value = digits * scale, the digits a QuantInt (computed in i32)."""

    digits: QuantInt
    compute: dt.DataType
    scale: builtins.float

    def __repr__(self) -> str:
        return f"qfx(d={self.digits!r} c={self.compute} s={self.scale})"


@dataclass(frozen=True)
class QuantFloat(_OnDigits):
    """`ti.types.quant.float(exp, frac, signed)`: an unsigned exponent member (placed just before the digits,
    or shared with other floats) and `frac` digit bits (the sign bit among them when signed); f32 compute."""

    digits: QuantInt
    exponent: QuantInt
    compute: dt.DataType

    def __repr__(self) -> str:
        return f"qfl(d={self.digits!r} e={self.exponent!r} c={self.compute})"


QuantType = (QuantInt, QuantFixed, QuantFloat)


def _bits(name: str, bits, lo: builtins.int, hi: builtins.int) -> builtins.int:
    if isinstance(bits, builtins.bool) or not isinstance(bits, builtins.int) or not lo <= bits <= hi:
        raise SimgradValueError(f"quant.{name}: bits must be an integer in [{lo}, {hi}], got {bits!r}", caller_loc())
    return bits


def int(bits, signed=True, compute=None) -> QuantInt:  # noqa: A001 - Taichi's name
    """A quantized integer type of `bits` bits; computes in `compute` (default: i32 signed, u32 unsigned)."""
    _bits("int", bits, 1, 64)
    if compute is None:
        compute = dt.Defaults.ip if signed else dt.u32
    compute = dt.from_any(compute)
    if compute.is_float:
        raise SimgradTypeError(f"quant.int: compute type must be an integer type, got {compute}", caller_loc())
    return QuantInt(bits, builtins.bool(signed), compute)


def fixed(bits, signed=True, max_value=1.0, compute=None, scale=None) -> QuantFixed:
    """A quantized fixed-point type: `bits` digits times `scale` (default max_value / 2**(bits - signed))."""
    _bits("fixed", bits, 1, 32)
    compute = dt.from_any(compute) if compute is not None else dt.Defaults.fp
    if not compute.is_float:
        raise SimgradTypeError(f"quant.fixed: compute type must be a float type, got {compute}", caller_loc())
    digits = QuantInt(bits, builtins.bool(signed), dt.i32)
    if scale is None:
        scale = max_value / 2 ** (bits - 1) if signed else max_value / 2**bits
    return QuantFixed(digits, compute, builtins.float(scale))


def float(exp, frac, signed=True, compute=None) -> QuantFloat:  # noqa: A001 - Taichi's name
    """A quantized float: `exp` exponent bits (<= 8) and `frac` bits of digits, the sign included."""
    _bits("float", exp, 1, 8)
    _bits("float", frac, 1, 24)
    compute = dt.from_any(compute) if compute is not None else dt.Defaults.fp
    if compute is not dt.f32:
        raise SimgradTypeError(f"quant.float computes in f32 only (as Taichi), got {compute}", caller_loc())
    digits = QuantInt(frac, builtins.bool(signed), dt.i32)  # the sign bit, when signed, is one of `frac`
    if frac - (1 if signed else 0) > 23:
        raise SimgradValueError(f"quant.float: at most 23 digit bits besides the sign, got frac={frac}", caller_loc())
    return QuantFloat(digits, QuantInt(exp, False, dt.i32), compute)


def is_quant(t) -> builtins.bool:
    return isinstance(t, QuantType)


# -- placing ---------------------------------------------------------------------------------------------
class BitpackedFields:
    """`ti.BitpackedFields(max_num_bits)`: quant fields packed into one physical integer per cell, in the
    order placed (a float's exponent just before its digits; floats placed with shared_exponent=True share
    the first one's exponent)."""

    def __init__(self, max_num_bits):
        if max_num_bits not in _PHYSICAL:
            raise SimgradError(f"BitpackedFields: max_num_bits must be 8, 16, 32 or 64, got {max_num_bits!r}",
                               caller_loc())
        self.physical = _PHYSICAL[max_num_bits]
        self.members: list = []  # (field or None for an exponent, quant type, bit offset)
        self.total = 0
        self.placed = False

    def _add(self, field, qtype, bits: builtins.int) -> builtins.int:
        at = self.total
        self.total += bits
        if self.total > self.physical.bits:
            raise SimgradError(f"BitpackedFields overflows: {self.total} bits used out of {self.physical.bits}",
                               caller_loc())
        self.members.append([field, qtype, at, None])
        return len(self.members) - 1

    def place(self, *fields, shared_exponent=False) -> None:
        if self.placed:
            raise SimgradError("BitpackedFields.place after the BitpackedFields was placed in an SNode", caller_loc())
        comps = []
        for f in fields:
            if not hasattr(f, "_components"):  # a Field (lang/field.py imports this module)
                raise SimgradTypeError(f"BitpackedFields.place takes quant fields, got {type(f).__name__}",
                                       caller_loc())
            comps += f._components()
        for c in comps:
            q = getattr(c, "quant_type", None)
            if q is None:
                raise SimgradTypeError(f"BitpackedFields.place: field {c.name} has type {c.dtype}, not a quant "
                                       "type (ti.types.quant.int / fixed / float)", caller_loc())
            if c.snode is not None or any(m[0] is c for m in self.members):
                raise SimgradError(f"field {c.name} is placed twice", caller_loc())
        if shared_exponent and len(comps) <= 1:
            raise SimgradSyntaxError("At least 2 fields need to be placed when shared_exponent=True", caller_loc())
        shared = -1
        for c in comps:
            q = c.quant_type
            if isinstance(q, QuantFloat):
                if shared_exponent and shared >= 0:
                    if self.members[shared][1] != q.exponent:
                        raise SimgradTypeError("QuantFloatTypes with shared exponents must have exactly the same "
                                               "exponent type", caller_loc())
                    exp = shared
                else:
                    exp = self._add(None, q.exponent, q.exponent.bits)
                    if shared_exponent:
                        shared = exp
                k = self._add(c, q, q.digits.bits)
                self.members[k][3] = exp
            else:
                if shared_exponent:
                    raise SimgradTypeError(f"shared_exponent=True places quant floats only; {c.name} is {q!r}",
                                           caller_loc())
                self._add(c, q, q.storage_bits)

    def fields(self) -> list:
        return [m[0] for m in self.members if m[0] is not None]


def slot_of(field) -> QuantSlot:
    """Where a placed quant field's bits are: its node's parent is the bit_struct or quant_array cell."""
    q = field.quant_type
    node = field.snode
    cell = node._parent
    assert cell is not None and cell.kind in ("bit_struct", "quant_array"), f"internal: {field.name} not packed"
    scale = q.scale if isinstance(q, QuantFixed) else 1.0
    kind = "int" if isinstance(q, QuantInt) else "fixed" if isinstance(q, QuantFixed) else "float"
    if cell.kind == "quant_array":
        position = {a: p for p, a in enumerate(sorted({a for n in cell.path() for a in n.axes}))}
        terms, weight = [], 1
        for a, size in reversed(list(zip(cell.axes, cell.sizes))):
            terms.append((position[a], size, weight))
            weight *= size
        return QuantSlot(kind, cell.physical, q.storage_bits, q.signed, 0, tuple(terms[::-1]), scale,
                         compute=field.dtype, used=cell.num_cells * q.storage_bits)
    pack: BitpackedFields = cell.bitpack
    me = next(m for m in pack.members if m[0] is field)
    if kind != "float":
        return QuantSlot(kind, cell.physical, q.storage_bits, q.signed, me[2], (), scale, compute=field.dtype,
                         used=pack.total)
    exp = me[3]
    users = tuple((m[2], m[1].digits.bits, m[1].signed) for m in pack.members if m[3] == exp)
    return QuantSlot(kind, cell.physical, q.storage_bits, q.signed, me[2], (), scale, q.exponent.bits,
                     pack.members[exp][2], users if len(users) > 1 else (), compute=field.dtype, used=pack.total)


def check_array_member(node, field) -> None:
    """`quant_array(...).place(x)`: one quant int or fixed field whose elements fit the physical cell."""
    q = getattr(field, "quant_type", None)
    if not isinstance(q, (QuantInt, QuantFixed)):
        raise SimgradTypeError(f"quant_array places a quant int or fixed field, got {field.name} of type "
                               f"{q!r}" if q is not None else f"quant_array places a quant int or fixed field, "
                               f"got {field.name} of type {field.dtype}", caller_loc())
    if node.children:
        raise SimgradError("a quant_array holds exactly one field", caller_loc())
    if node.num_cells * q.storage_bits > node.physical.bits:
        raise SimgradError(f"quant_array of {node.num_cells} x {q.storage_bits} bits does not fit max_num_bits="
                           f"{node.physical.bits}", caller_loc())


def physical_type(max_num_bits) -> dt.DataType:
    if max_num_bits not in _PHYSICAL:
        raise SimgradError(f"quant_array: max_num_bits must be 8, 16, 32 or 64, got {max_num_bits!r}", caller_loc())
    return _PHYSICAL[max_num_bits]


class _QuantNamespace:
    """`ti.types.quant`: the module's public names (Taichi: fixed, float, i32, impl, int; `impl`, Taichi's
    ti.lang.impl, is set by the public namespace)."""

    int = staticmethod(int)
    fixed = staticmethod(fixed)
    float = staticmethod(float)
    i32 = dt.i32
    impl: object = None

    def __dir__(self):
        return ["fixed", "float", "i32", "impl", "int"]


quant = _QuantNamespace()
