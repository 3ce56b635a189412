"""Assignable places inside a kernel: local variables, field/ndarray elements, and matrices of them.

The lowering visitor turns every target (`a`, `x[i]`, `v.x`, `m[i][j]`) into a Ref, so loads, stores
and atomic updates are written once, here."""

from __future__ import annotations

import itertools

from simgrad import dtypes as dt
from simgrad.errors import SimgradIndexError, SimgradTypeError
from simgrad.ir import context
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.field import ScalarField
from simgrad.lang.matrix import _SWIZZLE, Matrix, check_dynamic_index, check_swizzle, vector_key


class VarRef:
    """A mutable local (an ALLOCA)."""

    __slots__ = ("alloca",)

    def __init__(self, dtype: dt.DataType):
        b = context.builder()
        self.alloca = b.emit(Op.ALLOCA, dtype)

    @property
    def dtype(self):
        return self.alloca.type

    def load(self) -> Expr:
        return Expr(context.builder().emit(Op.LOCAL_LOAD, self.dtype, (self.alloca,)))

    def store(self, value) -> None:
        v = operators.cast_expr(operators.to_expr(value, self.dtype), self.dtype)
        context.builder().emit(Op.LOCAL_STORE, None, (self.alloca, v.stmt))

    def atomic(self, kind: str, value) -> Expr:
        if kind in ("add", "sub", "min", "max", "and", "or", "xor", "atomic_mul"):
            kind = "mul" if kind == "atomic_mul" else kind
            # an ATOMIC on the local: atomic if a parallel task shares it, a plain update otherwise
            v = operators.cast_expr(operators.to_expr(value, self.dtype), self.dtype)
            if kind == "sub":
                kind, v = "add", operators.neg(v)
            return Expr(context.builder().emit(Op.ATOMIC, self.dtype, (self.alloca, v.stmt), {"kind": kind}))
        old = self.load()
        self.store(_combine(kind, old, value))
        return old


class GlobalRef:
    """One scalar element of a field or an ndarray."""

    __slots__ = ("target", "indices", "dtype")

    def __init__(self, target, indices: list[Expr], dtype: dt.DataType):
        self.target, self.indices, self.dtype = target, indices, dtype

    def ptr(self):
        b = context.builder()
        t = self.target
        target = t.ref() if isinstance(t, ScalarField) else t  # the IR sees a field's FieldRef record
        attrs = {"target": target}
        if context.current().grad_stopped(target):
            attrs["stop_grad"] = True  # ti.stop_grad in this loop: autodiff treats the element as constant
        return b.emit(Op.GLOBAL_PTR, self.dtype, tuple(i.stmt for i in self.indices), attrs)

    def load(self) -> Expr:
        e = Expr(context.builder().emit(Op.GLOBAL_LOAD, self.dtype, (self.ptr(),)))
        return operators.cast_expr(e, dt.f32) if self.dtype is dt.f16 else e  # f16 is a storage type

    def store(self, value) -> None:
        v = operators.cast_expr(operators.to_expr(value, self.dtype), self.dtype)
        context.builder().emit(Op.GLOBAL_STORE, None, (self.ptr(), v.stmt))

    def atomic(self, kind: str, value) -> Expr:
        if kind in ("mul", "div", "floordiv", "mod", "pow", "shl", "shr"):
            old = self.load()
            self.store(_combine(kind, old, value))
            return old
        v = operators.cast_expr(operators.to_expr(value, self.dtype), self.dtype)
        if kind == "sub":
            kind, v = "add", operators.neg(v)
        kind = "mul" if kind == "atomic_mul" else kind  # ti.atomic_mul (`x *= v` is a plain update, as Taichi)
        if kind in ("and", "or", "xor") and self.dtype.is_float:
            raise SimgradTypeError("atomic bit operation on a float field", context.current_loc())
        s = context.builder().emit(Op.ATOMIC, self.dtype, (self.ptr(), v.stmt), {"kind": kind})
        return Expr(s)


class MatrixRef:
    """A matrix (or vector) of scalar refs: a local matrix variable or one element of a matrix field."""

    __slots__ = ("refs", "n", "m", "clamp")

    def __init__(self, refs: list, n: int, m: int, clamp: bool = False):
        self.refs, self.n, self.m = refs, n, m
        # an element of a ti.types.ndarray(boundary="clamp") argument: run-time indices into it clamp too
        self.clamp = clamp

    @property
    def dtype(self):
        return self.refs[0].dtype

    def load(self) -> Matrix:
        return Matrix(n=self.n, m=self.m, _entries=[r.load() for r in self.refs])

    def _values(self, value) -> list:
        if isinstance(value, (list, tuple)):
            value = Matrix(list(value))
        if isinstance(value, Matrix):
            if value.shape != ((self.n,) if self.m == 0 else (self.n, self.m)):
                # never store a prefix: a 2-vector into a 3-vector must not leave the third entry behind
                raise SimgradTypeError(
                    f"cannot assign '{tensor_text(value.shape, _entry_type(value.entries[0]))}' to "
                    f"'{tensor_text((self.n,) if self.m == 0 else (self.n, self.m), self.dtype)}': a "
                    f"{value.shape} matrix to a {self.shape_text()} one", context.current_loc())
            return value.entries
        return [value] * len(self.refs)

    def shape_text(self) -> str:
        return f"({self.n},)" if self.m == 0 else f"({self.n}, {self.m})"

    def store(self, value) -> None:
        for r, v in zip(self.refs, self._values(value)):
            r.store(v)

    def atomic(self, kind: str, value) -> Matrix:
        olds = [r.atomic(kind, v) for r, v in zip(self.refs, self._values(value))]
        return Matrix(n=self.n, m=self.m, _entries=olds)

    def index(self, key):
        """The ref of `m[key]`: a scalar ref, a row (MatrixRef) for one index on a matrix, or the entries a
        compile-time slice picks (`v[1:]`, `m[0, :]`, `m[:2, 1:]`), assignable too."""
        key = vector_key(key)
        key = key if isinstance(key, tuple) else (key,)
        if any(isinstance(k, slice) for k in key):
            return self._slice(key)
        if any(isinstance(k, Expr) for k in key):
            raise SimgradTypeError(
                "matrix elements can only be assigned with compile-time indices here (use ti.static or "
                "a Python int)", context.current_loc()
            )
        if len(key) != (1 if self.m == 0 else 2):
            raise SimgradIndexError(f"Expected {1 if self.m == 0 else 2} indices, got {len(key)}: index a "
                                    f"{self.shape_text()} matrix as " + ("v[i]" if self.m == 0 else "m[i, j]"),
                                    context.current_loc())
        if self.m == 0:
            (i,) = key
            return self.refs[_check(i, self.n)]
        i, j = key
        return self.refs[_check(i, self.n) * self.m + _check(j, self.m)]

    def _slice(self, key: tuple):
        dims = (self.n,) if self.m == 0 else (self.n, self.m)
        if len(key) == 1 and self.m:
            key = (key[0], slice(None))
        if len(key) != len(dims):
            raise SimgradTypeError(f"{len(key)} indices for a matrix of shape {self.shape_text()}",
                                   context.current_loc())
        for k in key:
            if isinstance(k, slice) and any(isinstance(p, Expr) for p in (k.start, k.stop, k.step)):
                raise SimgradTypeError("slice bounds must be compile-time values (Taichi does not support "
                                       "variables in slice now)", context.current_loc())
        if any(isinstance(k, Expr) for k in key):  # m[:, j] = v with a run-time j: each entry chosen at run time
            rows = [list(range(*k.indices(d))) if isinstance(k, slice) else [k] for k, d in zip(key, dims)]
            refs = [DynamicElementRef(self, (i, j)) for i in rows[0] for j in rows[1]]
            return MatrixRef(refs, len(refs), 0)
        ranges = [list(range(*k.indices(d))) if isinstance(k, slice) else [_check(k, d)] for k, d in zip(key, dims)]
        if self.m == 0:
            return MatrixRef([self.refs[i] for i in ranges[0]], len(ranges[0]), 0)
        refs = [self.refs[i * self.m + j] for i in ranges[0] for j in ranges[1]]
        if all(isinstance(k, slice) for k in key):
            return MatrixRef(refs, len(ranges[0]), len(ranges[1]))
        return MatrixRef(refs, len(refs), 0)

    def swizzle(self, name: str):
        idx = [_SWIZZLE[c] for c in name]
        check_swizzle(name, idx, self.n)
        if len(idx) == 1:
            return self.refs[idx[0]]
        return MatrixRef([self.refs[i] for i in idx], len(idx), 0)


def tensor_text(shape: tuple, dtype) -> str:
    """An element type as Taichi's messages print it: [Tensor (3) i32], [Tensor (2, 2) f32]; a scalar: f32."""
    return f"[Tensor ({', '.join(str(d) for d in shape)}) {dtype}]" if shape else str(dtype)


def _entry_type(v):
    if isinstance(v, Expr):
        return v.dtype
    return "i32" if isinstance(v, int) else "f32" if isinstance(v, float) else type(v).__name__


class StructRef:
    """A struct of refs, one per member: a struct local, or an element of a struct field. Loads build a
    struct value; stores and updates go member by member."""

    __slots__ = ("stype", "members")

    def __init__(self, stype, members: dict):
        self.stype, self.members = stype, members

    def load(self):
        from simgrad.lang.struct import Struct

        return Struct._typed(self.stype, {k: r.load() for k, r in self.members.items()})

    def store(self, value) -> None:
        values = dict(value.items()) if hasattr(value, "items") else None
        if values is None or set(values) - set(self.members):
            raise SimgradTypeError(f"cannot assign {type(value).__name__} to a struct of members "
                                   f"{', '.join(self.members)}", context.current_loc())
        for k, v in values.items():
            self.members[k].store(v)

    def atomic(self, kind: str, value):
        raise SimgradTypeError(f"augmented assignment on a whole struct ({kind}); update its members",
                               context.current_loc())

    def member(self, name: str):
        return self.members.get(name)


class DynamicElementRef:
    """`v[i]` of a matrix ref with a run-time index (`for i in range(3): v[i] += 1`). Loads select among
    the entries; stores and updates go to each candidate entry under `i == k` (matrices are small)."""

    __slots__ = ("base", "key")

    def __init__(self, base: MatrixRef, key: tuple):
        if base.clamp and base.m == 0:
            key = tuple(operators.max(0, operators.min(k, base.n - 1)) for k in key)
        elif base.clamp and len(key) == 2:  # as Taichi: the row-major flat index is clamped
            flat = operators.add(operators.mul(key[0], base.m), key[1])
            flat = operators.max(0, operators.min(flat, base.n * base.m - 1))
            key = (operators.floordiv(flat, base.m), operators.mod(flat, base.m))
        self.base, self.key = base, key

    @property
    def dtype(self):
        return self.base.dtype

    def load(self):
        return self.base.load()[self.key if len(self.key) > 1 else self.key[0]]

    def _each(self, update) -> None:
        dims = (self.base.n,) if self.base.m == 0 else (self.base.n, self.base.m)
        if len(self.key) > len(dims):
            raise SimgradTypeError(f"{len(self.key)} indices for a matrix of shape {dims}",
                                   context.current_loc())
        check_dynamic_index(self.key, dims)  # debug mode: out of range is an error, not a dropped store
        choices = [range(d) if isinstance(k, Expr) else [int(k)] for k, d in zip(self.key, dims)]
        b = context.builder()
        for combo in itertools.product(*choices):
            cond = None
            for k, c in zip(self.key, combo):
                if isinstance(k, Expr):
                    hit = operators.eq(k, c)
                    cond = hit if cond is None else operators.bit_and(cond, hit)
            assert cond is not None  # some index is a run-time value, else the element is known
            stmt = b.emit(Op.IF, None, (cond.stmt,), nblocks=2)
            with b.inside(stmt.blocks[0]):
                update(self.base.index(combo))

    def store(self, value) -> None:
        self._each(lambda r: r.store(value))

    def atomic(self, kind: str, value):
        old = self.load()
        self._each(lambda r: r.atomic(kind, value))
        return old


def _check(i, n: int) -> int:
    i = int(i)
    if not -n <= i < n:
        raise IndexError(f"matrix index {i} out of range ({n})")
    return i % n


_COMBINE = {
    "add": operators.add, "sub": operators.sub, "mul": operators.mul, "div": operators.truediv,
    "floordiv": operators.floordiv, "mod": operators.mod, "pow": operators.pow, "and": operators.bit_and,
    "or": operators.bit_or, "xor": operators.bit_xor,
    "shl": operators.shl, "shr": operators.shr, "min": operators.min, "max": operators.max,
}


def _combine(kind: str, old, value):
    return _COMBINE[kind](old, value)


# the refs a local variable name can be bound to (assignable in place)
LOCAL_REFS = (VarRef, MatrixRef, StructRef)
