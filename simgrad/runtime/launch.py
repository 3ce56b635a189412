"""Per-instantiation launchers: Python source generated once per kernel instantiation that packs the
arguments into the context buffer and makes one native call. No generic per-argument loop per call."""

from __future__ import annotations

import ctypes
import itertools
import re
import struct
import threading

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import (
    SimgradAssertionError,
    SimgradOutOfBoundError,
    SimgradRuntimeError,
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
from simgrad.runtime.args import LaunchCode

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

    reads_errors = True  # the error buffer is read after the call (a kernel on the CPU can always be interrupted)

    def __init__(self, kernel_name: str, params: list, entry_address: int, nslots: int, returns: list,
                 error_table: list, program, ret_matrix: object = None, private_slots: int = 0,
                 scratch_slots: int = 0):
        self.kernel_name = kernel_name
        self.params = params  # each parameter's Packing (runtime/args.py); the Tape reads ARG slots' values
        self.ret_matrix = ret_matrix  # (n, m) for a matrix, a StructType for a struct: the values come back as a tuple
        self.error_table = error_table
        self.program = program
        self.buf = np.zeros(CTX_ARGS + nslots + len(returns) + 1 + private_slots + scratch_slots, dtype=np.int64)
        # the slots past the returns hold the privatised loops' per-thread copies, kept between launches;
        # then the GPU target's scratch words (values that cross its kernels: codegen/nvptx.py)
        start = CTX_ARGS + nslots + len(returns) + 1
        # each slot holds the address of a holder {pointer to every thread's copies or page maps, their capacity
        # in bytes, the pages the last sum found marked, -1 before one} (codegen/privatize.py _held): contexts
        # copied for replay (Sequence) share the holders, so the native code may replace a too small allocation
        # without leaving a copy pointing at freed memory
        self._holders = np.zeros((private_slots, 3), dtype=np.int64)
        self._holders[:, 2] = -1
        if private_slots:
            self.buf[start:start + private_slots] = self._holders.ctypes.data + 24 * np.arange(private_slots)
        self.buf[list(HEADER_SLOTS)] = program.context_header()
        self.buf[CTX_NTHREADS] = program.pool.num_threads
        self.tape: np.ndarray | None = None
        self.ret_slot = CTX_ARGS + nslots
        # a u1 travels as one byte, 0 or 1 (LLVM's i1 in memory), read back as an int as Taichi returns it
        self.views = {t.name: self.buf.view(np.uint8 if t is dt.u1 else t.np) for t in dt.ALL}
        self.entry_address = entry_address
        self.entry = self.native_entry(entry_address)
        self.pack = None  # pack(*args): the context words alone, when nothing but the native call follows them
        self.launch = self._generate(params, returns)

    def native_entry(self, address: int):
        """What the generated launch calls with the context's address: the kernel's native entry."""
        return ctypes.CFUNCTYPE(None, ctypes.c_void_p)(address)

    def __del__(self):
        """Free the private copies the native code allocated (calloc) into this launcher's context."""
        try:
            for p in self._holders[:, 0]:
                if p:
                    _LIBC_FREE(int(p))
        except Exception:  # interpreter shutdown
            pass

    def attach_tape(self, entries: int) -> None:
        """A private tape for this adjoint kernel: one region per thread plus one for the serial part, each on
        cache lines of its own. (Two threads' 5-entry tapes on one line, pushed and popped every iteration, made
        diffmpm3d's p2g.grad take 6.1 ms a launch instead of 2.9, in the runs where numpy placed them so.)"""
        regions = self.program.pool.num_threads + 1
        entries = -(-entries // 8) * 8  # whole 64-byte lines
        store = np.zeros(regions * entries + 8, dtype=np.int64)  # (the view below keeps it alive)
        start = (-store.ctypes.data % 64) // 8  # the first line boundary in it
        tape = self.tape = store[start:start + regions * entries]
        self.buf[CTX_TAPE] = tape.ctypes.data
        self.buf[CTX_TAPE_CAP] = entries
        self.buf[CTX_TAPE_SERIAL] = tape.ctypes.data + 8 * entries * (regions - 1)

    def launch_code(self, env: dict) -> LaunchCode:
        """What the packings write their lines with (the GPU launcher's stages host arrays)."""
        return LaunchCode(self.kernel_name, env, self.views)

    def call_lines(self, env: dict) -> list[str]:
        """The launcher's lines that run the kernel once the context is packed: one native call here; the GPU
        launcher's upload, its segments' launches and its wait (runtime/gpu_launch.py)."""
        return ["_call(_addr)"]

    def _generate(self, params: list, returns: list):
        env = {"_buf": self.buf, "_call": self.entry, "_addr": self.buf.ctypes.data, "_err": self.program.error,
               "_fail": self.fail, "_interrupted": self.clear_interrupt,
               "_acquire": LAUNCH_LOCK.acquire, "_release": LAUNCH_LOCK.release}
        gen = self.launch_code(env)
        names = [p.name for p in params]
        gen.positions = {n: k for k, n in enumerate(names)}
        # each parameter's packing (runtime/args.py) writes its own lines: no per-argument loop per call
        lines = ["    " + ln for p in params for ln in p.launch_code(gen, p.name)]
        lines = ["    " + ln for ln in gen.before] + lines
        lines += ["    " + ln for ln in self.call_lines(env)]
        if self.reads_errors:
            lines.append("    if _err[0]: _fail()")
        lines += ["    " + ln for ln in gen.after]
        if returns:
            rets = []
            for k, t in enumerate(returns):
                view, scale = gen.view(t)
                rets.append(f"{view}[{(self.ret_slot + k) * scale}].item()")
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
        if not gen.after and not returns:
            packing = "\n".join("    " + ln for p in params for ln in p.launch_code(gen, p.name)) or "    pass"
            exec(compile(f"def pack({', '.join(names)}):\n{packing}\n", f"<packer {self.kernel_name}>", "exec"), env)
            self.pack = env["pack"]
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
        if kind in ("adstack", "recursion"):
            raise SimgradRuntimeError(detail, loc)
        if kind == "sparse_pool":
            raise SimgradRuntimeError(f"out of memory for {detail} SNode blocks: its pool holds {value} blocks "
                                      "and all are in use (deactivate cells, or raise ti.init(device_memory_GB=...))",
                                      loc)
        raise SimgradRuntimeError(f"kernel {self.kernel_name} reported error {code}", loc)










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



_SEQUENCE = ctypes.CFUNCTYPE(ctypes.c_int64, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p)
_sequence_fn = None


class Sequence:
    """Launches captured for replay in one native call (lang/graph.py): each step's context is a copy of its
    launcher's, packed with that step's arguments, so one kernel may appear with different arguments."""

    @classmethod
    def packed(cls, steps) -> Sequence | None:
        """The Sequence of (launcher, arguments) steps, each context packed now; None when a launcher cannot be
        packed alone (Python must run after its launch)."""
        launchers, contexts = [], []
        for launcher, args in steps:
            if launcher is None or launcher.pack is None:
                return None
            launcher.pack(*args)
            launchers.append(launcher)
            contexts.append(launcher.buf.copy())
        return cls(launchers, contexts)

    def __init__(self, launchers: list[Launcher], contexts: list[np.ndarray]):
        self.launchers = launchers
        self.contexts = contexts  # kept alive: the steps point into them
        self.steps = np.array([w for ln, c in zip(launchers, contexts) for w in (ln.entry_address, c.ctypes.data)],
                              dtype=np.uint64)
        self.error = launchers[0].program.error if launchers else None
        # the native call's arguments, taken once (numpy's .ctypes costs microseconds per use)
        self._args = (self.steps.ctypes.data, len(launchers), self.error.ctypes.data if self.error is not None else 0)

    def run(self) -> None:
        global _sequence_fn
        if not self.launchers:
            return
        if _sequence_fn is None:
            from simgrad.runtime import ll
            from simgrad.runtime.jit import get_jit

            _sequence_fn = _SEQUENCE(get_jit().load(ll.load("sequence"), ["simgrad_run_sequence"])[
                "simgrad_run_sequence"])
        with LAUNCH_LOCK:
            try:
                k = _sequence_fn(*self._args)
            except KeyboardInterrupt:
                self.launchers[0].clear_interrupt()
                raise
        if k < len(self.launchers):
            self.launchers[k].fail()


_VOLATILE = itertools.count()
_PLAIN = frozenset((float, int, bool))


def same_replay_key(a, b) -> bool:
    """``replay_key(a) == replay_key(b)`` without building the keys for plain Python numbers (a Tape compares
    thousands of recorded launch arguments per backward pass: lang/tape.py)."""
    if type(a) in _PLAIN and type(b) is type(a):
        return a == b and (a != 0 or bool(np.signbit(a)) == bool(np.signbit(b)))
    return replay_key(a) == replay_key(b)


def replay_key(value):
    """What must not change for a captured Sequence to be replayed with `value` as an argument: a scalar's type
    and value; the identity of a numpy array, a ti.ndarray, a field or a template object (their context words
    stay valid while they live). A torch tensor or other DLPack object gets a key equal to nothing: its data and
    its `.grad` can be replaced under the same object (optimizer.zero_grad(set_to_none=True)), so it is packed
    anew every time."""
    if type(value) in _PLAIN or isinstance(value, (bool, int, float, str, type(None))) or np.isscalar(value):
        # -0.0 == 0.0, but a context packed with one must not stand for the other (1 / x, atan2)
        return (type(value).__name__, value, value == 0 and bool(np.signbit(value)))
    if not isinstance(value, np.ndarray) and not hasattr(value, "_ndarray_data") and (
            hasattr(value, "__dlpack__") or hasattr(value, "data_ptr") or hasattr(value, "__cuda_array_interface__")):
        return ("volatile", next(_VOLATILE))
    return ("object", id(value))
