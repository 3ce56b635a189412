"""Per-instantiation launchers: Python source generated once per kernel instantiation that packs the
arguments into the context buffer and makes one native call. No generic per-argument loop per call."""

from __future__ import annotations

import ctypes
import re
import struct
import threading

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import (
    SimgradAssertionError,
    SimgradOutOfBoundError,
    SimgradRuntimeError,
    SimgradTypeError,
    caller_loc,
)
from simgrad.runtime.abi import (
    CTX_ARGS,
    CTX_NTHREADS,
    CTX_TAPE,
    CTX_TAPE_CAP,
    CTX_TAPE_SERIAL,
    ERR_ARGS,
    ERR_INTERRUPTED,
    HEADER_SLOTS,
)

# One launch at a time in the process: ctypes releases the GIL during the native call, and the context and
# error buffers and the thread pool's job slot are shared by every launch. Uncontended it costs ~0.1 us;
# a kernel is parallel inside, so serialising launches from several Python threads loses little.
LAUNCH_LOCK = threading.Lock()

_VIEW_OF = {8: "i8", 16: "i16", 32: "i32", 64: "i64"}

_LIBC_FREE = ctypes.CDLL(None).free
_LIBC_FREE.argtypes = [ctypes.c_void_p]
_LIBC_FREE.restype = None


class Launcher:
    """Holds the context buffer of one kernel instantiation and the generated `launch` function."""

    def __init__(self, kernel_name: str, params: list, entry_address: int, nslots: int, returns: list,
                 error_table: list, program, ret_matrix: object = None, private_slots: int = 0):
        self.kernel_name = kernel_name
        self.params = params  # SlotParam per kernel parameter (Tape validation maps ARG slots to values)
        self.ret_matrix = ret_matrix  # (n, m) for a matrix, a StructType for a struct: the values come back as a tuple
        self.error_table = error_table
        self.program = program
        self.buf = np.zeros(CTX_ARGS + nslots + len(returns) + 1 + private_slots, dtype=np.int64)
        # the slots past the returns hold the privatised loops' per-thread copies, kept between launches
        self._private = slice(CTX_ARGS + nslots + len(returns) + 1, len(self.buf))
        self.buf[list(HEADER_SLOTS)] = program.context_header()
        self.buf[CTX_NTHREADS] = program.pool.num_threads
        self.tape: np.ndarray | None = None
        self.ret_slot = CTX_ARGS + nslots
        self.views = {t.name: self.buf.view(t.np) for t in dt.ALL if t is not dt.u1}
        self.entry = ctypes.CFUNCTYPE(None, ctypes.c_void_p)(entry_address)
        self.launch = self._generate(params, returns)

    def __del__(self):
        """Free the private copies the native code allocated (calloc) into this launcher's context."""
        try:
            for p in self.buf[self._private]:
                if p:
                    _LIBC_FREE(int(p))
        except Exception:  # interpreter shutdown
            pass

    def attach_tape(self, entries: int) -> None:
        """A private tape for this adjoint kernel: one region per thread plus one for the serial part."""
        regions = self.program.pool.num_threads + 1
        tape = self.tape = np.zeros(regions * entries, dtype=np.int64)
        self.buf[CTX_TAPE] = tape.ctypes.data
        self.buf[CTX_TAPE_CAP] = entries
        self.buf[CTX_TAPE_SERIAL] = tape.ctypes.data + 8 * entries * (regions - 1)

    def _generate(self, params: list, returns: list):
        env = {"_buf": self.buf, "_call": self.entry, "_addr": self.buf.ctypes.data, "_err": self.program.error,
               "_fail": self.fail, "_array": _array_info, "_bad": _bad_arg,
               "_interrupted": self.clear_interrupt, "_check_float": _check_float, "_check_int": _check_int,
               "_acquire": LAUNCH_LOCK.acquire, "_release": LAUNCH_LOCK.release}
        lines = []
        names = []
        after: list[str] = []  # checks after the call (a sparse matrix builder past its capacity)
        for p in params:
            if p.kind == "struct":  # its leaves follow as their own params
                names.append(p.name)
                continue
            if p.of is not None:  # a leaf of a struct argument
                env["_member"] = _member
                lines.append(f"    {p.name} = _member({p.of}, {p.path!r})")
            else:
                names.append(p.name)
            if p.kind == "scalar":
                t = p.dtype
                scale = 8 // t.nbytes
                env[f"_v_{t.name}"] = self.views[t.name]
                # exact Python numbers pass with one class test; anything else is checked (Taichi refuses None,
                # strings, arrays, and floats of any kind for an integer parameter rather than truncating)
                exact, check = ("float", "_check_float") if t.is_float else ("int", "_check_int")
                lines.append(f"    if {p.name}.__class__ is not {exact}: {check}({self.kernel_name!r}, {p.name!r}, "
                             f"{p.name}, {t.name!r})")
                lines.append(f"    try: _v_{t.name}[{(CTX_ARGS + p.slot) * scale}] = {p.name}")
                lines.append(f"    except (TypeError, ValueError, OverflowError): _bad({self.kernel_name!r}, "
                             f"{p.name!r}, {p.name}, {t.name!r})")
            elif p.kind == "matrix":
                t = p.dtype
                scale = 8 // t.nbytes
                env[f"_v_{t.name}"] = self.views[t.name]
                lines.append(f"    _m = _np_flat({p.name}, {p.count}, {self.kernel_name!r}, {p.name!r})")
                for k in range(p.count):
                    lines.append(f"    _v_{t.name}[{(CTX_ARGS + p.slot + k) * scale}] = _m[{k}]")
                env["_np_flat"] = _flat_matrix_int if not t.is_float else _flat_matrix
            elif p.kind == "ndarray":
                lines.append(f"    _p, _s = _array({p.name}, {self.kernel_name!r}, {p.name!r}, {p.ndim_total})")
                lines.append(f"    _buf[{CTX_ARGS + p.slot}] = _p")
                for d in range(p.ndim):
                    lines.append(f"    _buf[{CTX_ARGS + p.slot + 1 + d}] = _s[{d}]")
                if getattr(p, "grad_slot", -1) >= 0:
                    env["_grad_of"] = _grad_info
                    lines.append(f"    _buf[{CTX_ARGS + p.grad_slot}] = _grad_of({p.name}, _s, {self.kernel_name!r}, "
                                 f"{p.name!r}, {p.ndim_total})")
            elif p.kind == "builder":
                # the triplet count, rows, columns and values: base pointer and extent each
                env["_builder"], env["_builder_done"] = _builder_info, _builder_done
                lines.append(f"    _buf[{CTX_ARGS + p.slot}:{CTX_ARGS + p.slot + 8}] = _builder({p.name}, "
                             f"{self.kernel_name!r}, {p.name!r}, {p.dtype.name!r})")
                after.append(f"    _builder_done({p.name}, {self.kernel_name!r}, {p.name!r})")
        lines.append("    _call(_addr)")
        lines.append("    if _err[0]: _fail()")
        lines += after
        if returns:
            rets = []
            for k, t in enumerate(returns):
                scale = 8 // t.nbytes
                env[f"_v_{t.name}"] = self.views[t.name]
                rets.append(f"_v_{t.name}[{(self.ret_slot + k) * scale}].item()")
            if len(returns) == 1 and self.ret_matrix is None:
                lines.append(f"    return {rets[0]}")
            else:
                lines.append(f"    return ({', '.join(rets)},)")
        body = "\n".join("    " + ln for ln in lines)
        # Python raises a Ctrl-C's KeyboardInterrupt right after the native call returns, before the error
        # check: the interrupted kernel's report must not be left for the next launch
        src = (f"def launch({', '.join(names)}):\n    _acquire()\n    try:\n{body}\n"
               "    except KeyboardInterrupt:\n        _interrupted()\n        raise\n"
               "    finally:\n        _release()\n")
        exec(compile(src, f"<launcher {self.kernel_name}>", "exec"), env)
        return env["launch"]

    def clear_interrupt(self) -> None:
        if self.program.error[0] == ERR_INTERRUPTED:
            self.program.error[:] = 0

    def fail(self):
        code, value = int(self.program.error[0]), int(self.program.error[1])
        saved = self.program.error.copy()
        self.program.error[:] = 0
        if code == ERR_INTERRUPTED:
            raise KeyboardInterrupt(f"kernel {self.kernel_name} was interrupted")
        kind, loc, detail = self.error_table[code - 1] if 0 < code <= len(self.error_table) else ("?", None, "")
        if kind == "index":
            name, dim, shape = detail
            where = f"of ndarray {name}" if shape == "ndarray" else f"of {name} (shape {shape})"
            raise SimgradOutOfBoundError(f"Out of bound access: index {value} is out of bounds in dimension "
                                         f"{dim} {where}", loc)
        if kind == "assert":
            if not isinstance(detail, str):
                detail = assert_message(detail, saved[ERR_ARGS:].tolist())
            raise SimgradAssertionError(f"assertion failed: {detail}", loc)
        if kind == "adstack":
            raise SimgradRuntimeError(detail, loc)
        if kind == "sparse_pool":
            raise SimgradRuntimeError(f"out of memory for {detail} SNode blocks: its pool holds {value} blocks "
                                      "and all are in use (deactivate cells, or raise ti.init(device_memory_GB=...))",
                                      loc)
        raise SimgradRuntimeError(f"kernel {self.kernel_name} reported error {code}", loc)


def _bad_arg(kernel, param, value, type_name):
    if isinstance(value, int):
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' = {value} is out of range for {type_name}",
                               caller_loc())
    raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects a {type_name} scalar, got "
                           f"{type(value).__name__}", caller_loc())


def _check_float(kernel, param, value, type_name):
    if not isinstance(value, (int, float, np.integer, np.floating)):  # bool is an int
        _bad_arg(kernel, param, value, type_name)


def _check_int(kernel, param, value, type_name):
    if not isinstance(value, (int, np.integer)):
        _bad_arg(kernel, param, value, type_name)


def _flat_matrix(value, count, kernel, param):
    a = np.asarray(value.to_numpy() if hasattr(value, "to_numpy") else value).reshape(-1)
    if a.size != count:
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects {count} entries, got {a.size}")
    return a.tolist()


def _flat_matrix_int(value, count, kernel, param):
    vals = _flat_matrix(value, count, kernel, param)
    if any(isinstance(v, float) for v in vals):
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects integer entries, got floats")
    return vals


def _member(value, path):
    """value.a.b for a struct argument's leaf (struct values, struct field elements and dicts)."""
    for name in path:
        value = value[name] if isinstance(value, dict) else getattr(value, name)
    return value


def _grad_info(a, shape, kernel, param, ndim):
    """The base address of the gradient of ndarray argument `a` (a ti.ndarray's .grad, a tensor's .grad, made
    zero when the tensor has none yet, as Taichi does)."""
    grad = getattr(a, "grad", None)
    if grad is None and hasattr(a, "data_ptr") and getattr(a, "requires_grad", False):
        import torch

        grad = a.grad = torch.zeros_like(a)
    if grad is None:
        raise SimgradTypeError(f"kernel {kernel}: ndarray argument '{param}' has no gradient")
    ptr, gshape = _array_info(grad, kernel, param + ".grad", ndim)
    if tuple(gshape) != tuple(shape):
        raise SimgradTypeError(f"kernel {kernel}: the gradient of '{param}' has shape {tuple(gshape)}, "
                               f"its array {tuple(shape)}")
    return ptr


def _array_info(a, kernel, param, ndim):
    if isinstance(a, np.ndarray):
        if not a.flags.c_contiguous:
            raise SimgradTypeError(f"kernel {kernel}: ndarray argument '{param}' must be C-contiguous "
                                   "(use np.ascontiguousarray)")
        return a.ctypes.data, a.shape
    if hasattr(a, "data_ptr") and hasattr(a, "is_contiguous"):  # a torch tensor
        if a.device.type != "cpu" or not a.is_contiguous():
            raise SimgradTypeError(f"kernel {kernel}: tensor argument '{param}' must be a contiguous CPU tensor")
        return a.data_ptr(), tuple(a.shape)
    if hasattr(a, "_ndarray"):
        return _array_info(a._ndarray, kernel, param, ndim)
    raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects an ndarray, got {type(a).__name__}")


def assert_message(template: list, values: list) -> str:
    """The message of a failed assert from its template (frontend/printing.py FormattedString.template)
    and the values the kernel reported (raw 64-bit words: floats as f64 bits, integers extended)."""
    out = []
    for p in template:
        if isinstance(p, str):
            out.append(p)
            continue
        k, conv, tname = p
        t = dt._by_name(tname)
        raw = int(values[k]) & (2**64 - 1)
        if t.is_float:
            x = struct.unpack("<d", struct.pack("<Q", raw))[0]
            if conv is None:  # shortest text that reads back as the same value of its type (as Taichi)
                out.append(repr(float(x)) if t.bits == 64 else str(t.np.type(x)))
                continue
            value: float | int = x
        else:
            value = raw if not t.is_signed else raw - (1 << 64) if raw >> 63 else raw
            if t is dt.u1:
                value = int(bool(value))
            elif conv is not None and conv[-1] in "xXo" and value < 0:  # printf shows the bits
                value &= (1 << t.bits) - 1
        if conv is None:
            out.append(str(value))
            continue
        c = re.sub(r"(hh|h|ll|l|j|z|t|L)(?=[a-zA-Z]$)", "", conv)
        if c[-1] in "aA":
            h = float(value).hex()
            out.append(h.upper() if c[-1] == "A" else h)
        else:
            out.append((c[:-1] + "d" if c[-1] == "u" else c) % value)
    return "".join(out)


def _builder_info(a, kernel, param, type_name):
    """The context slots of a sparse matrix builder argument: (pointer, extent) of its triplet count, rows,
    columns and values (lang: simgrad/linalg/sparse_matrix.py TripletStore)."""
    t = getattr(a, "_triplets", None)
    if t is None or t.dtype.name != type_name:
        got = type(a).__name__ if t is None else f"a builder of {t.dtype.name}"
        raise SimgradTypeError(f"kernel {kernel}: argument '{param}' expects a ti.linalg.SparseMatrixBuilder of "
                               f"{type_name}, got {got}", caller_loc())
    cap = t.capacity
    return (t.count.ctypes.data, 1, t.rows.ctypes.data, cap, t.cols.ctypes.data, cap, t.values.ctypes.data, cap)


def _builder_done(a, kernel, param):
    """After the launch: a builder whose count passed its capacity dropped the triplets past it; say so."""
    t = a._triplets
    n = int(t.count[0])
    if n > t.capacity:
        raise SimgradRuntimeError(f"kernel {kernel}: sparse matrix builder '{param}' was given {n} triplets, more "
                                  f"than its max_num_triplets={t.capacity}; the {n - t.capacity} past it were not "
                                  "stored (create the builder with a larger max_num_triplets)", caller_loc())
