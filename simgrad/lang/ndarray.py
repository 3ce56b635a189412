"""ti.ndarray objects: arrays that kernels take by reference (`ti.types.ndarray()` parameters), with Taichi's
Python-scope API. The data is one C-contiguous numpy array (host memory, the device's on arch=cuda) whose
trailing axes are the element's (a vector or matrix); kernels receive its address and shape (runtime/args.py
reads `_ndarray_data`). Python scope reaches it through `_ndarray`, which first waits for the kernels still
running on an asynchronous device (lang/program.py sync_for_host), as Taichi's ndarray access synchronizes."""

from __future__ import annotations

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import SimgradIndexError, SimgradRuntimeError, SimgradTypeError, caller_loc
from simgrad.lang.field import FieldElement
from simgrad.lang.program import get_program, require_init, sync_for_host
from simgrad.lang.types import MatrixType


class _Component:
    """One entry of every element, indexable by the outer index: what FieldElement reads and writes."""

    def __init__(self, arr: Ndarray, entry: tuple):
        self.arr, self.entry = arr, entry

    def __getitem__(self, key):
        return self.arr._ndarray[key + self.entry].item()

    def __setitem__(self, key, value) -> None:
        self.arr._ndarray[key + self.entry] = value


class Ndarray:
    """An n-dimensional array of scalars, vectors or matrices; `shape` is the outer shape (as Taichi)."""

    def __init__(self, dtype, shape, element_shape: tuple = (), needs_grad: bool = False):
        require_init("ndarray")
        self.dtype = dt.from_any(dtype)
        self.shape = (shape,) if isinstance(shape, (int, np.integer, float)) else tuple(shape)
        if any(isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 < n < 2**31
               for n in self.shape):
            raise SimgradRuntimeError(f"{shape!r} is not a valid shape for ndarray: each extent must be an "
                                      "integer in [1, 2**31)", caller_loc())
        self.shape = tuple(int(n) for n in self.shape)
        self.element_shape = tuple(element_shape)
        self.n = self.element_shape[0] if self.element_shape else 0
        self.m = self.element_shape[1] if len(self.element_shape) > 1 else 0
        self.ncols = self.m  # what element views read (0: vectors)
        self.name = "ndarray"
        self._ndarray_data = get_program().zeros(self.shape + self.element_shape, self.dtype.np)
        self._data_address = self._ndarray_data.ctypes.data  # what a launch packs (numpy's .ctypes costs us)
        self.comps = [_Component(self, e) for e in np.ndindex(*self.element_shape)] if self.element_shape else []
        self.grad: Ndarray | None = None
        if needs_grad:
            if not self.dtype.is_float:
                raise SimgradRuntimeError(f"{self.dtype} is not supported for ndarray with needs_grad=True: "
                                          "gradients need a floating-point type", caller_loc())
            # the adjoint buffer kernels' .grad accumulate into (and a Tape seeds, for a loss)
            grad = self.grad = object.__new__(type(self))
            Ndarray.__init__(grad, self.dtype, self.shape, self.element_shape)

    @property
    def _ndarray(self) -> np.ndarray:
        """The data for Python scope (element access, to/from_numpy, fill, linalg): after the device is done."""
        sync_for_host()
        return self._ndarray_data

    @property
    def element_type(self):
        if not self.element_shape:
            return self.dtype
        return MatrixType(self.n, self.m, self.dtype)

    def _key(self, key) -> tuple:
        if key is None and not self.shape:  # x[None] of a 0-d ndarray
            return ()
        key = key if isinstance(key, tuple) else (key,)
        if len(key) != len(self.shape):
            raise SimgradIndexError(f"{len(self.shape)}d ndarray indexed with {len(key)}d indices: {key!r}",
                                    caller_loc())
        for k, (i, n) in enumerate(zip(key, self.shape)):
            if not isinstance(i, (int, np.integer)) or not 0 <= i < n:
                raise SimgradIndexError(f"index {i!r} of axis {k} is out of bounds for the ndarray of shape "
                                        f"{self.shape}", caller_loc())
        return tuple(int(i) for i in key)

    def __getitem__(self, key):
        key = self._key(key)
        if not self.element_shape:
            return self._ndarray[key].item()
        return FieldElement(self, key)  # a live view: element assignment writes through

    def __setitem__(self, key, value) -> None:
        key = self._key(key)
        v = value.to_numpy() if hasattr(value, "to_numpy") else np.asarray(value)
        if v.shape not in ((), self.element_shape):
            raise SimgradTypeError(f"cannot store a value of shape {v.shape} in an ndarray element of shape "
                                   f"{self.element_shape}", caller_loc())
        self._ndarray[key] = v

    def _get_element_size(self) -> int:
        """Bytes per element (Taichi's name)."""
        return int(self.dtype.np.itemsize * max(1, int(np.prod(self.element_shape))))

    def _get_nelement(self) -> int:
        return int(np.prod(self.shape))

    def to_numpy(self) -> np.ndarray:
        return self._ndarray.copy()

    def from_numpy(self, arr) -> None:
        a = np.asarray(arr)
        if a.shape != self._ndarray.shape:
            raise SimgradTypeError(f"from_numpy: expected an array of shape {self._ndarray.shape}, got {a.shape}",
                                   caller_loc())
        self._ndarray[...] = a

    def fill(self, value) -> None:
        self._ndarray[...] = value

    def copy_from(self, other: Ndarray) -> None:
        self.from_numpy(other._ndarray)

    def to_torch(self, device=None):
        import torch

        return torch.from_numpy(self.to_numpy()).to(device) if device else torch.from_numpy(self.to_numpy())

    def get_type(self):
        from simgrad.lang.types import NdarrayType

        return NdarrayType(self.element_type, len(self.shape))

    def __repr__(self) -> str:
        return f"<ndarray {self.element_type} shape={self.shape}>"

    def __str__(self) -> str:
        """`print(a)` prints what Taichi 1.7.4 prints for an ndarray (its repr, not the values)."""
        es = self.element_shape
        if not es:
            return "<ti.ndarray>"
        if len(es) == 1:
            return f"<{es[0]} Layout.AOS ti.Vector.ndarray>"
        return f"<{es[0]}x{es[1]} Layout.AOS ti.Matrix.ndarray>"


class ScalarNdarray(Ndarray):
    def __init__(self, dtype, arr_shape, needs_grad: bool = False):
        super().__init__(dtype, arr_shape, (), needs_grad)


class VectorNdarray(Ndarray):
    def __init__(self, n: int, dtype, shape, needs_grad: bool = False):
        super().__init__(dtype, shape, (n,), needs_grad)


class MatrixNdarray(Ndarray):
    def __init__(self, n: int, m: int, dtype, shape, needs_grad: bool = False):
        super().__init__(dtype, shape, (n, m), needs_grad)


def ndarray(dtype, shape, needs_grad: bool = False) -> Ndarray:
    """`ti.ndarray(ti.f32, shape)`, or of vectors/matrices with `ti.math.vec3`/`ti.types.matrix(...)`."""
    if isinstance(dtype, MatrixType):
        if dtype.m:
            return MatrixNdarray(dtype.n, dtype.m, dtype.dtype, shape, needs_grad)
        return VectorNdarray(dtype.n, dtype.dtype, shape, needs_grad)
    return ScalarNdarray(dtype, shape, needs_grad)
