"""How the arguments of one kernel instantiation reach its context buffer: a *packing* per parameter (the
kind of parameter picks it, compiler/params.py) writes the launcher lines that store the argument's words,
and the run-time checks those lines call. The launcher (runtime/launch.py) only concatenates what the
packings give it, so a new argument kind needs no edit there; packings are pickled with the kernel cache's
metadata (plain attributes, classes importable by name).

A packing has `name` (the launch function's parameter), `launch_code(gen, src)` (source lines; `src` is the
Python expression holding the argument) and `slot_values(value)` (the context slot -> value of the scalar
words it fills from `value`, for the Tape's slice watching; {} when it has none)."""

from __future__ import annotations

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import ArgumentValueError, SimgradRuntimeError, SimgradTypeError, caller_loc
from simgrad.runtime.abi import CTX_ARGS
from simgrad.runtime.tensors import tensor_grad_info, tensor_info


class LaunchCode:
    """What a packing writes launcher lines with: the generated function's globals (`env`), the typed views of
    the context buffer, the kernel's name (for messages) and the lines that run after the native call."""

    def __init__(self, kernel_name: str, env: dict, views: dict, on_device: bool = False, staging=None):
        self.kernel_name = kernel_name
        self.on_device = on_device  # the kernel runs on an asynchronous GPU: host arrays are staged
        self.env = env
        self.views = views
        self.before: list[str] = []  # lines before the packing
        self.after: list[str] = []
        self.positions: dict[str, int] = {}  # each launch parameter's position (Taichi's messages name it)
        # runtime/gpu_launch.py Staging: host arrays copied to the device and back (on_device only)
        self.staging = staging

    def stage(self) -> str:
        """The launcher's name of the function that gives a host array's device copy ("None" off the device);
        the first use adds the staging's start and its copy back after the call."""
        if self.staging is None:
            return "None"
        if "_stage" not in self.env:
            self.env["_stage"] = self.staging.stage
            self.env["_stage_begin"], self.env["_stage_finish"] = self.staging.begin, self.staging.finish
            self.before.append("_stage_begin()")
            self.after.append("_stage_finish()")
        return "_stage"

    @staticmethod
    def word(slot: int) -> int:
        """The index in the launcher's `_buf` (the context as 64-bit words) of argument slot `slot`."""
        return CTX_ARGS + slot

    def view(self, t: dt.DataType) -> tuple[str, int]:
        """(name in the launcher, words per 8-byte slot) of the buffer's view as type `t`."""
        self.env[f"_v_{t.name}"] = self.views[t.name]
        return f"_v_{t.name}", 8 // t.nbytes


class Packing:
    """A parameter that fills no context slot (a ti.template(): its value was compiled in)."""

    def __init__(self, name: str, path: tuple = ()):
        self.name = name
        # a leaf of a struct argument (or of any object): its value is `arg.path[0].path[1]...`
        self.path = path

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        return []

    def slot_values(self, value) -> dict:
        return {}

    def _leaf(self, gen: LaunchCode, src: str) -> tuple[str, list[str]]:
        """(local name, lines) of the value this packing reads: `src` itself, or its member at `path`."""
        if not self.path:
            return src, []
        gen.env["_member"] = member
        local = f"{src}__{'__'.join(self.path)}"
        return local, [f"{local} = _member({src}, {self.path!r})"]


class ScalarPacking(Packing):
    """One scalar in one slot, checked as Taichi checks it (no None/str/array for a float, no float of any
    kind for an integer)."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, path: tuple = ()):
        super().__init__(name, path)
        self.slot, self.dtype = slot, dtype

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        v, lines = self._leaf(gen, src)
        t = self.dtype
        view, scale = gen.view(t)
        kernel = gen.kernel_name
        # exact Python numbers pass with one class test; anything else is checked
        exact, check = ("float", "_check_float") if t.is_float else ("int", "_check_int")
        gen.env[check] = check_float if t.is_float else check_int
        gen.env["_bad"] = bad_arg
        where = f"{kernel!r}, {v!r}, {v}, {t.name!r}, {None if self.path else gen.positions.get(self.name)!r}"
        return lines + [f"if {v}.__class__ is not {exact}: {check}({where})",
                        # a u1 is any nonzero integer as 1 (as Taichi converts it)
                        f"try: {view}[{gen.word(self.slot) * scale}] = {'1 if ' + v + ' else 0' if t is dt.u1 else v}",
                        f"except (TypeError, ValueError, OverflowError): _bad({where})"]

    def slot_values(self, value) -> dict:
        return {self.slot: member(value, self.path)}


class MatrixPacking(Packing):
    """A vector or matrix argument: its `count` entries, row-major, in consecutive slots."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, count: int, path: tuple = ()):
        super().__init__(name, path)
        self.slot, self.dtype, self.count = slot, dtype, count

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        v, lines = self._leaf(gen, src)
        t = self.dtype
        view, scale = gen.view(t)
        gen.env["_np_flat"] = flat_matrix if t.is_float else flat_matrix_int
        lines.append(f"_m = _np_flat({v}, {self.count}, {gen.kernel_name!r}, {v!r})")
        lines += [f"{view}[{gen.word(self.slot + k) * scale}] = _m[{k}]" for k in range(self.count)]
        return lines


class StructPacking(Packing):
    """A struct argument: its leaves (scalar and matrix packings with their member paths), in order."""

    def __init__(self, name: str, leaves: list[Packing]):
        super().__init__(name)
        self.leaves = leaves

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        return [ln for leaf in self.leaves for ln in leaf.launch_code(gen, src)]

    def slot_values(self, value) -> dict:
        return {k: v for leaf in self.leaves for k, v in leaf.slot_values(value).items()}


class ArgPackPacking(Packing):
    """A ti.types.argpack argument: each member's own packing, applied to the member (`pack.a`)."""

    def __init__(self, name: str, members: list[tuple[str, Packing]]):
        super().__init__(name)
        self.members = members

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        lines = []
        for k, packing in self.members:
            local = f"{src}__{k}"
            lines.append(f"{local} = {src}.{k}")
            lines += packing.launch_code(gen, local)
        return lines

    def slot_values(self, value) -> dict:
        return {s: v for k, p in self.members for s, v in p.slot_values(getattr(value, k)).items()}


class ArrayPacking(Packing):
    """An ndarray argument by reference: its base pointer, one extent per array axis (the element axes are
    compiled in), and its gradient's base pointer when the kernel sees one (`grad_slot`, else -1)."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, ndim: int, ndim_total: int, grad_slot: int = -1):
        super().__init__(name)
        self.slot, self.dtype, self.ndim, self.ndim_total, self.grad_slot = slot, dtype, ndim, ndim_total, grad_slot

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        kernel = gen.kernel_name
        gen.env["_array"] = array_info
        stage = gen.stage()
        lines = [f"_p, _s = _array({src}, {kernel!r}, {self.name!r}, {self.ndim_total}, {stage})",
                 f"_buf[{gen.word(self.slot)}] = _p"]
        lines += [f"_buf[{gen.word(self.slot + 1 + d)}] = _s[{d}]" for d in range(self.ndim)]
        if self.grad_slot >= 0:
            gen.env["_grad_of"] = grad_info
            lines.append(f"_buf[{gen.word(self.grad_slot)}] = _grad_of({src}, _s, {kernel!r}, {self.name!r}, "
                         f"{self.ndim_total}, {stage})")
        return lines


class TensorPacking(ArrayPacking):
    """A torch tensor, DLPack array or ti.ad.with_grad pair by reference (runtime/tensors.py): the ndarray
    words, from checks of the foreign array's layout and device (`pair`: the value is `arg.value`, the
    gradient `arg.grad`)."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, ndim: int, ndim_total: int, grad_slot: int = -1,
                 pair: bool = False):
        super().__init__(name, slot, dtype, ndim, ndim_total, grad_slot)
        self.pair = pair

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        kernel = gen.kernel_name
        gen.env["_tensor"], gen.env["_tensor_grad"] = tensor_info, tensor_grad_info
        value = f"{src}.value" if self.pair else src
        stage = gen.stage()
        lines = [f"_p, _s = _tensor({value}, {kernel!r}, {self.name!r}, {stage})",
                 f"_buf[{gen.word(self.slot)}] = _p"]
        lines += [f"_buf[{gen.word(self.slot + 1 + d)}] = _s[{d}]" for d in range(self.ndim)]
        if self.grad_slot >= 0:
            lines.append(f"_buf[{gen.word(self.grad_slot)}] = _tensor_grad({src}, _s, {kernel!r}, {self.name!r}, "
                         f"{stage})")
        return lines


class BuilderPacking(Packing):
    """A ti.linalg.SparseMatrixBuilder: (pointer, extent) of its triplet count, rows, columns and values in 8
    slots; after the call, a count past the capacity is an error (the excess was never stored)."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType):
        super().__init__(name)
        self.slot, self.dtype = slot, dtype

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        kernel = gen.kernel_name
        gen.env["_builder"], gen.env["_builder_done"] = builder_info, builder_done
        if gen.on_device:  # the count is the device's: wait for the kernel (its triplets are device memory)
            gen.after.append("_sync()")
        gen.after.append(f"_builder_done({src}, {kernel!r}, {self.name!r})")
        return [f"_buf[{gen.word(self.slot)}:{gen.word(self.slot + 8)}] = _builder({src}, {kernel!r}, "
                f"{self.name!r}, {self.dtype.name!r})"]


# -- run-time checks and conversions the launchers call ---------------------------------------------------
def bad_arg(kernel, param, value, type_name, pos=None):
    if isinstance(value, int):
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' = {value} is out of range for {type_name}",
                               caller_loc())
    taichi = "" if pos is None else \
        f" (Argument ({pos},) (type={type(value)}) cannot be converted into required type {type_name})"
    raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects a {type_name} scalar, got "
                           f"{type(value).__name__}{taichi}", caller_loc())


def check_float(kernel, param, value, type_name, pos=None):
    if not isinstance(value, (int, float, np.integer, np.floating)):  # bool is an int
        bad_arg(kernel, param, value, type_name, pos)


def check_int(kernel, param, value, type_name, pos=None):
    if not isinstance(value, (int, np.integer)):
        bad_arg(kernel, param, value, type_name, pos)


def flat_matrix(value, count, kernel, param):
    a = np.asarray(value.to_numpy() if hasattr(value, "to_numpy") else value).reshape(-1)
    if a.size != count:
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects {count} entries, got {a.size}")
    return a.tolist()


def flat_matrix_int(value, count, kernel, param):
    vals = flat_matrix(value, count, kernel, param)
    if any(isinstance(v, float) for v in vals):
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects integer entries, got floats")
    return vals


def member(value, path):
    """value.a.b for a struct argument's leaf (struct values, struct field elements and dicts)."""
    for name in path:
        value = value[name] if isinstance(value, dict) else getattr(value, name)
    return value


def grad_info(a, shape, kernel, param, ndim, stage=None):
    """The base address of the gradient of ndarray argument `a` (a ti.ndarray's .grad; tensors: TensorPacking)."""
    grad = getattr(a, "grad", None)
    if grad is None:
        raise SimgradTypeError(f"kernel {kernel}: ndarray argument '{param}' has no gradient")
    ptr, gshape = array_info(grad, kernel, param + ".grad", ndim, stage)
    if tuple(gshape) != tuple(shape):
        raise SimgradTypeError(f"kernel {kernel}: the gradient of '{param}' has shape {tuple(gshape)}, "
                               f"its array {tuple(shape)}")
    return ptr


class FortranOrderArray(SimgradTypeError):
    """A Fortran-ordered numpy argument (`a.T`): Kernel.__call__ runs the launch again on C-ordered copies and
    writes them back, as Taichi does; the launcher itself stays free of that check's cost for C arrays."""


def array_info(a, kernel, param, ndim, stage=None):
    """(base address, shape) of an ndarray argument: a numpy array or a ti.ndarray (tensors: TensorPacking).
    `stage` (an asynchronous device's launcher): a numpy array's device copy (runtime/gpu_launch.py Staging)."""
    if isinstance(a, np.ndarray):
        if not a.flags.c_contiguous:
            if a.flags.f_contiguous:  # a transposed array: the kernel runs on a C-ordered copy (compiler/kernel.py)
                raise FortranOrderArray(f"kernel {kernel}: ndarray argument '{param}' is in Fortran order")
            raise ArgumentValueError(f"kernel {kernel}: ndarray argument '{param}' is not C-contiguous: Non "
                                     "contiguous numpy arrays are not supported, please call np.ascontiguousarray(arr) "
                                     "before passing it into the kernel", caller_loc())
        return (a.ctypes.data if stage is None else stage(a)), a.shape
    if hasattr(a, "_ndarray_data"):  # device memory already: no staging, and no synchronization
        return a._data_address, a._ndarray_data.shape  # a ti.ndarray (lang/ndarray.py) keeps its data's address
    raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects an ndarray, got {type(a).__name__} "
                           f"(Invalid type for argument {param}, got {a})")


def builder_info(a, kernel, param, type_name):
    """The context slots of a sparse matrix builder argument: (pointer, extent) of its triplet count, rows,
    columns and values (lang: simgrad/linalg/sparse_matrix.py TripletStore)."""
    t = getattr(a, "_triplets", None)
    if t is None or t.dtype.name != type_name:
        got = type(a).__name__ if t is None else f"a builder of {t.dtype.name}"
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects a ti.linalg.SparseMatrixBuilder of "
                               f"{type_name}, got {got}", caller_loc())
    cap = t.capacity
    return (t.count.ctypes.data, 1, t.rows.ctypes.data, cap, t.cols.ctypes.data, cap, t.values.ctypes.data, cap)


def builder_done(a, kernel, param):
    """After the launch: a builder whose count passed its capacity dropped the triplets past it; say so."""
    t = a._triplets
    n = int(t.count[0])
    if n > t.capacity:
        raise SimgradRuntimeError(f"kernel {kernel}: sparse matrix builder '{param}' was given {n} triplets, more "
                                  f"than its max_num_triplets={t.capacity}; the {n - t.capacity} past it were not "
                                  "stored (create the builder with a larger max_num_triplets)", caller_loc())
