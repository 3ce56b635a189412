"""Python-scope access to fields under sparse SNodes, by compiled kernels (the lang stage reaches them
through lang/scope_hooks.py). Such fields have no numpy view: an element may live in a pool block or not
exist at all. Reads of inactive cells give 0 and activate nothing; writes activate, as in kernels.

- `x[i, j]` and `x[i, j] = v`: one-element kernels (indices and value in a small ndarray);
- `to_numpy`: the active cells into a zeroed array (a struct-for, as Taichi's: a bitmasked cell keeps its
  value when deactivated, yet to_numpy shows 0 there);
- `from_numpy` and `fill(v)`: write the active cells only (struct-fors, as Taichi's: from_numpy activates
  nothing and drops the array's values at inactive cells);
- `deactivate_all(node)`: a struct-for over the node's active cells deactivating each one.
None of them is recorded by a Tape."""

from __future__ import annotations

import numpy as np

from simgrad.compiler.kernel import kernel
from simgrad.lang import ad_hooks, scope_hooks
from simgrad.lang.loops import grouped, static
from simgrad.lang.matrix import Vector
from simgrad.lang.sparse import deactivate
from simgrad.lang.types import ndarray, template


@kernel
def _read(f: template(), idx: ndarray(), out: ndarray()):  # type: ignore[valid-type]
    out[0] = f[Vector([idx[k] for k in static(range(len(f.shape)))])]


@kernel
def _write(f: template(), idx: ndarray(), val: ndarray()):  # type: ignore[valid-type]
    f[Vector([idx[k] for k in static(range(len(f.shape)))])] = val[0]


@kernel
def _to_numpy(f: template(), out: ndarray(), off: template()):  # type: ignore[valid-type]
    for I in grouped(f):
        out[I - off] = f[I]


@kernel
def _from_numpy(f: template(), arr: ndarray(), off: template()):  # type: ignore[valid-type]
    for I in grouped(f):
        f[I] = arr[I - off]


@kernel
def _fill(f: template(), val: ndarray()):  # type: ignore[valid-type]
    for I in grouped(f):
        f[I] = val[0]


@kernel
def _deactivate_all(node: template()):  # type: ignore[valid-type]
    for I in grouped(node):
        deactivate(node, I)


class _Unrecorded:
    def __enter__(self):
        self.outer, ad_hooks.recorder = ad_hooks.recorder, None

    def __exit__(self, *exc):
        ad_hooks.recorder = self.outer


def _offset(f):
    from simgrad.lang.matrix import Matrix

    return Matrix(list(f.offset)) if f.offset else Matrix([0] * len(f.shape))


class SparseScope:
    """What lang/field.py and lang/snode.py call for sparse fields and nodes."""

    @staticmethod
    def get(f, key: tuple):
        out = np.zeros(1, dtype=f.dtype.np)
        with _Unrecorded():
            _read(f, np.asarray(key, dtype=np.int32), out)
        return out[0].item()

    @staticmethod
    def set(f, key: tuple, value) -> None:
        with _Unrecorded():
            _write(f, np.asarray(key, dtype=np.int32), np.asarray([value], dtype=f.dtype.np))

    @staticmethod
    def to_numpy(f) -> np.ndarray:
        out = np.zeros(f.shape, dtype=f.dtype.np)
        with _Unrecorded():
            _to_numpy(f, out, _offset(f))
        return out

    @staticmethod
    def from_numpy(f, arr: np.ndarray) -> None:
        with _Unrecorded():
            _from_numpy(f, np.ascontiguousarray(arr, dtype=f.dtype.np), _offset(f))

    @staticmethod
    def fill(f, value) -> None:
        with _Unrecorded():
            _fill(f, np.asarray([value], dtype=f.dtype.np))

    @staticmethod
    def deactivate_all(node) -> None:
        with _Unrecorded():
            _deactivate_all(node)


scope_hooks.sparse = SparseScope()
