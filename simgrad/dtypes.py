"""Scalar types of the language and Taichi's promotion rules, with their numpy and LLVM spellings."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


class DataType:
    """A scalar type. Instances are unique, so `is` comparison works and they hash cheaply."""

    __slots__ = ("name", "np", "bits", "is_float", "is_signed", "llvm")

    def __init__(self, name: str, np_dtype, bits: int, is_float: bool, is_signed: bool, llvm: str):
        self.name = name
        self.np = np.dtype(np_dtype)
        self.bits = bits
        self.is_float = is_float
        self.is_signed = is_signed
        self.llvm = llvm

    @property
    def is_int(self) -> bool:
        return not self.is_float

    @property
    def nbytes(self) -> int:
        return self.np.itemsize

    def __repr__(self) -> str:
        return self.name

    def to_string(self) -> str:
        """Taichi's name of the type (`ti.f32.to_string() == str(ti.f32) == "f32"`)."""
        return self.name

    def __call__(self, *args, **kwargs):
        """`ti.f32(1)` casts like Taichi (a Python value in Python scope, an IR cast or typed literal in a kernel:
        lang/operators.py type_call)."""
        if cast_hook is None:
            raise RuntimeError("simgrad.lang is not loaded: `import simgrad` before casting with a type")
        return cast_hook(self, args, kwargs)

    def __reduce__(self):
        return (_by_name, (self.name,))


# how `ti.f32(x)` casts: lang/operators.py installs its `cast` here (dtypes sits below lang and imports none of it)
cast_hook: Callable[[DataType, tuple, dict], Any] | None = None

i8 = DataType("i8", np.int8, 8, False, True, "i8")
i16 = DataType("i16", np.int16, 16, False, True, "i16")
i32 = DataType("i32", np.int32, 32, False, True, "i32")
i64 = DataType("i64", np.int64, 64, False, True, "i64")
u1 = DataType("u1", np.bool_, 1, False, False, "i1")
u8 = DataType("u8", np.uint8, 8, False, False, "i8")
u16 = DataType("u16", np.uint16, 16, False, False, "i16")
u32 = DataType("u32", np.uint32, 32, False, False, "i32")
u64 = DataType("u64", np.uint64, 64, False, False, "i64")
f16 = DataType("f16", np.float16, 16, True, True, "half")
f32 = DataType("f32", np.float32, 32, True, True, "float")
f64 = DataType("f64", np.float64, 64, True, True, "double")

ALL = (i8, i16, i32, i64, u1, u8, u16, u32, u64, f16, f32, f64)
_NAMES = {t.name: t for t in ALL}
_FROM_NP = {t.np: t for t in ALL}


def _by_name(name: str) -> DataType:
    return _NAMES[name]


class Defaults:
    """Default types of Python literals; `ti.init(default_fp=..., default_ip=...)` sets them."""

    fp: DataType = f32
    ip: DataType = i32


class _DefaultUnsigned:
    """Taichi's default_up: the unsigned type of default_ip's width (ti.math.uvec2 follows it, as in Taichi)."""

    def __repr__(self) -> str:
        return "default_up"

    def __reduce__(self) -> str:
        return "default_up"


default_up = _DefaultUnsigned()


def from_any(t) -> DataType:
    """Accept our types, numpy dtypes and the Python builtins `int`/`float`/`bool` as type names."""
    if isinstance(t, DataType):
        return t
    if t is int:
        return Defaults.ip
    if t is default_up:
        return {8: u8, 16: u16, 32: u32, 64: u64}[Defaults.ip.bits]
    if t is float:
        return Defaults.fp
    if t is bool:
        return u1  # as Taichi (cook_dtype)
    try:
        return _FROM_NP[np.dtype(t)]
    except TypeError:
        pass
    except KeyError:
        pass
    raise TypeError(f"{t!r} is not a scalar type (use ti.f32, ti.i32, ...)")


def from_numpy(dt) -> DataType:
    return _FROM_NP[np.dtype(dt)]


def promote(a: DataType, b: DataType) -> DataType:
    """Taichi's binary promotion: floats win (the wider float); among ints, the wider, and at equal
    width the unsigned one."""
    if a is b:
        return a
    if a.is_float or b.is_float:
        if a.is_float and b.is_float:
            return a if a.bits >= b.bits else b
        return a if a.is_float else b
    if a is u1:
        return b
    if b is u1:
        return a
    if a.bits != b.bits:
        return a if a.bits > b.bits else b
    return a if not a.is_signed else b


