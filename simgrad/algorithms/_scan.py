# mypy: disable-error-code="valid-type, index"
"""ti.algorithms.PrefixSumExecutor: Taichi's inclusive in-place prefix sum of an i32 field or ndarray, as
two simgrad kernels over blocks: each block's sum (parallel), then each block scans its elements starting
from the sum of the blocks before it (parallel over blocks, serial inside one).

Taichi 1.7.4 runs it on CUDA and Vulkan only (warp shuffles) and raises for the CPU; simgrad runs it on its
targets. Like Taichi it takes i32 only (raising Taichi's RuntimeError for other dtypes) and wraps on
overflow as i32 addition does."""

import simgrad as ti
from simgrad.algorithms._containers import Array1D, annotation, not_on_a_tape, python_scope
from simgrad.errors import SimgradRuntimeError, SimgradTypeError, SimgradValueError, caller_loc

_BLOCK = 65536  # elements per block, at most _MAX_BLOCKS blocks
_MAX_BLOCKS = 256
_KERNELS: dict = {}


def _kernels(kind: str):
    """The two scan kernels for a field or an ndarray argument."""
    if kind in _KERNELS:
        return _KERNELS[kind]
    ann = annotation(kind)

    @ti.kernel
    def block_sums(a: ann, off: ti.i32, n: ti.i32, nb: ti.i32, bs: ti.i32, sums: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):
            acc = 0
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                acc += a[i + off]
            sums[b] = acc

    @ti.kernel
    def block_scans(a: ann, off: ti.i32, n: ti.i32, nb: ti.i32, bs: ti.i32, sums: ti.types.ndarray()):
        ti.loop_config(block_dim=1)
        for b in range(nb):
            acc = 0
            for c in range(b):  # the blocks before this one (at most _MAX_BLOCKS)
                acc += sums[c]
            for i in range(b * bs, ti.min(b * bs + bs, n)):
                acc += a[i + off]
                a[i + off] = acc

    _KERNELS[kind] = block_sums, block_scans
    return _KERNELS[kind]


@ti.data_oriented
class PrefixSumExecutor:
    """Parallel prefix sum (scan) helper: `PrefixSumExecutor(length).run(arr)` replaces the first `length`
    elements of the 1-D i32 field or ndarray `arr` by their inclusive prefix sums."""

    def __init__(self, length: int):
        if isinstance(length, bool) or not isinstance(length, int) or length < 0:
            raise SimgradValueError(f"PrefixSumExecutor's length must be a non-negative integer, got {length!r}",
                                    caller_loc())
        self.sorting_length = length  # Taichi's name
        self._nb = max(1, min(_MAX_BLOCKS, -(-length // _BLOCK)))
        self._bs = -(-length // self._nb) if length else 1
        self._sums = ti.ndarray(ti.i32, self._nb)

    def run(self, input_arr) -> None:
        python_scope("PrefixSumExecutor.run")
        if getattr(input_arr, "dtype", None) != ti.i32:  # Taichi's check and message, made first as there
            raise SimgradRuntimeError("Only ti.i32 type is supported for prefix sum.", caller_loc())
        a = Array1D(input_arr, "PrefixSumExecutor.run's array")
        if a.entry_shape:
            raise SimgradTypeError(f"PrefixSumExecutor.run takes scalars, got entries of shape {a.entry_shape}",
                                   caller_loc())
        not_on_a_tape("PrefixSumExecutor.run", a)
        n = self.sorting_length
        if a.n < n:
            raise SimgradValueError(f"PrefixSumExecutor({n}).run: the array has only {a.n} elements",
                                    caller_loc())
        if n == 0:
            return
        block_sums, block_scans = _kernels(a.kind)
        block_sums(input_arr, a.offset, n, self._nb, self._bs, self._sums)
        block_scans(input_arr, a.offset, n, self._nb, self._bs, self._sums)
