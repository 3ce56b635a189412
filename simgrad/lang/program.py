"""The process-wide runtime state that `ti.init` creates: configuration, SNode trees, memory, the thread
pool, RNG states, the error buffer and the kernel profiler."""

from __future__ import annotations

import os
import time
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from simgrad import dtypes as dt
from simgrad.runtime import abi
from simgrad.runtime.memory import Memory
from simgrad.runtime.sparse import MAX_RESERVE, SparseMemory

if TYPE_CHECKING:
    from simgrad.runtime.jit import CodeSpace

DEFAULT_TAPE_ENTRIES = 1 << 16


class Config:
    def __init__(self, **kw):
        self.arch = kw.get("arch")
        self.debug = bool(kw.get("debug", False))
        self.default_fp = dt.from_any(kw.get("default_fp") or dt.f32)
        self.default_ip = dt.from_any(kw.get("default_ip") or dt.i32)
        self.random_seed = int(kw.get("random_seed", 0))
        self.kernel_profiler = bool(kw.get("kernel_profiler", False))
        self.ad_stack_size = int(kw.get("ad_stack_size", 0) or 0)
        self.fast_math = bool(kw.get("fast_math", True))  # Taichi's default; see codegen.llvm.FAST_MATH_FLAGS
        self.offline_cache = bool(kw.get("offline_cache", True))
        self.offline_cache_file_path = kw.get("offline_cache_file_path")
        threads = kw.get("cpu_max_num_threads") or int(os.environ.get("SIMGRAD_NUM_THREADS", 0) or 0)
        self.num_threads = int(threads) if threads else (os.cpu_count() or 1)


class Profiler:
    """Per-kernel launch count and time (ti.profiler): host wall time on the CPU; on arch=cuda the device's time
    between two events recorded around the launch (CUDA events on a GPU), read when the records are asked for,
    so profiling does not make launches wait."""

    def __init__(self) -> None:
        self._records: dict[str, list[float]] = {}
        self._events: list[tuple[str, Any, Any, Any]] = []  # (kernel, device, start, end) not read yet
        self.device_time = False  # the records are device event times (arch=cuda)

    @property
    def records(self) -> dict[str, list[float]]:
        """Kernel name -> seconds per launch (device events read now: waits for the kernels they bracket)."""
        if self._events:
            events, self._events = self._events, []
            for name, device, start, end in events:
                self._records.setdefault(name, []).append(device.elapsed_ms(start, end) / 1e3)
                device.destroy_event(start)
                device.destroy_event(end)
        return self._records

    def add(self, name: str, seconds: float) -> None:
        self._records.setdefault(name, []).append(seconds)

    def add_events(self, name: str, device, start, end) -> None:
        self._events.append((name, device, start, end))
        self.device_time = True

    def clear(self) -> None:
        for _, device, start, end in self._events:
            device.destroy_event(start)
            device.destroy_event(end)
        self._events.clear()
        self._records.clear()

    def report(self) -> str:
        records = self.records
        clock = "device time, events" if self.device_time else "CPU wall time"
        lines = ["=" * 78, f"simgrad kernel profiler ({clock})", "=" * 78,
                 f"{'[%]':>7} {'total ms':>11} {'count':>8} {'avg ms':>10} {'min ms':>10} {'max ms':>10}  name"]
        total = sum(sum(v) for v in records.values()) or 1.0
        for name, ts in sorted(records.items(), key=lambda kv: -sum(kv[1])):
            s = sum(ts)
            lines.append(f"{100 * s / total:6.2f}% {1e3 * s:11.3f} {len(ts):8d} {1e3 * s / len(ts):10.4f} "
                         f"{1e3 * min(ts):10.4f} {1e3 * max(ts):10.4f}  {name}")
        lines.append("=" * 78)
        return "\n".join(lines)


class Program:
    generation = 0
    released = False

    def __init__(self, **kw) -> None:
        Program.generation += 1
        self.generation = Program.generation
        self.config = Config(**kw)
        self._pool = None
        self._device = None
        self.set_default_types(self.config.default_fp, self.config.default_ip)
        self.memory = Memory(self.device.alloc_shared) if self.on_gpu else Memory()
        gb = kw.get("device_memory_GB")
        limit = int(gb * 2**30) if gb else MAX_RESERVE
        if self.on_gpu:  # a pool's body is device memory: at most a quarter of the GPU's unless asked for more
            device = self.device
            limit = limit if gb else min(limit, getattr(device, "total_memory", limit) // 4)
            self.sparse = SparseMemory(limit, lambda n, zeroed: device.alloc_shared(n).ctypes.data if zeroed
                                       else device.reserve(n))
        else:
            self.sparse = SparseMemory(limit)
        self.trees: list = []
        self._open_tree = None
        self.profiler = Profiler()
        self.compile_seconds = 0.0  # time spent instantiating kernels (compiles and kernel-cache hits)
        self.instantiations = 0  # kernel instances made (compiled or taken from the kernel cache)
        self.error = self.zeros(abi.ERR_WORDS, np.int64)
        self._rng: np.ndarray | None = None
        from simgrad.runtime.jit import get_jit

        self.jit = get_jit()
        self._code: CodeSpace | None = None  # its kernels' native code, made on first link
        self.jit.cache_enabled = self.config.offline_cache
        if self.config.offline_cache_file_path:
            from pathlib import Path

            self.jit.cache_dir = Path(self.config.offline_cache_file_path)

    # -- SNode trees -------------------------------------------------------------------------------
    def materialize_all(self) -> None:
        for t in self.trees:
            if not t.materialized:
                t.materialize()

    def get_total_compilation_time(self) -> float:
        """Seconds spent compiling kernels in this program (taichi's `impl.get_runtime().prog` asks it)."""
        return self.compile_seconds

    def profiled_launch(self, name: str, launch, args):
        """`launch(*args)` with its time in the profiler: device events around it on arch=cuda (the launch does
        not wait for them), the host clock otherwise."""
        if self.on_gpu:
            d = self.device
            start = d.event()
            out = launch(*args)
            self.profiler.add_events(name, d, start, d.event())
            return out
        t0 = time.perf_counter()
        out = launch(*args)
        self.profiler.add(name, time.perf_counter() - t0)
        return out

    def sync(self) -> None:
        """ti.sync(): wait for the kernels launched so far (on the CPU they finish before their launch returns);
        a device fault of one that did not wait is raised here."""
        if self.on_gpu:
            self.device.synchronize()

    # -- native services ---------------------------------------------------------------------------
    def link(self, obj: bytes, symbols: list[str]) -> dict[str, int]:
        """Link a kernel's object code into this program's code space; addresses of `symbols`."""
        if self._code is None:
            from simgrad.runtime.jit import CodeSpace

            self._code = CodeSpace(self.jit)
        return self._code.link(obj, symbols)

    def set_default_types(self, fp=None, ip=None) -> None:
        """default_fp / default_ip (ti.init, or get_runtime().default_ip = ... as Taichi's tests do)."""
        if fp is not None:
            self.config.default_fp = dt.Defaults.fp = dt.from_any(fp)
        if ip is not None:
            self.config.default_ip = dt.Defaults.ip = dt.from_any(ip)

    def bump_generation(self) -> None:
        """A new generation of this program: every kernel drops its instances and compiles again (an SNode
        tree was destroyed)."""
        Program.generation += 1
        self.generation = Program.generation

    def release(self) -> None:
        """Free this program's native code (ti.reset / the next ti.init). Kernels notice the new program
        generation and compile again; fields of this program refuse further use. Kernels still queued on the
        device finish first (their code is freed here)."""
        if self._device is not None and self._device.pending:
            self._device.synchronize()
        self.released = True
        for tree in self.trees:  # Python-scope access of its fields goes the checked way from now on
            for node in tree.root._walk():
                if node.kind == "place":
                    node.field.view = None
                    node.field.gather = None
        if self._code is not None:
            self._code.close()
            self._code = None
        self.sparse.release()

    @property
    def on_gpu(self) -> bool:
        """arch=cuda: kernels run on the program's device (the GPU or the simulated one)."""
        return getattr(self.config.arch, "name", None) == "cuda"

    @property
    def gpu_sim(self) -> bool:
        """arch=cuda runs on the simulated GPU (SIMGRAD_GPU_SIM=1, or no usable GPU runtime): decided once, with
        the device."""
        from simgrad.runtime.device import HostDriver

        return isinstance(self.device, HostDriver)

    @property
    def device(self):
        """The device arch=cuda launches on (runtime/device.py): the GPU, or the simulated one on the host."""
        if self._device is None:
            from simgrad.lang.archs import gpu_mode
            from simgrad.runtime import device

            self._device = device.CudaDriver() if gpu_mode() == "cuda" else \
                device.HostDriver(deferred=self.on_gpu and device.sim_deferred())
        return self._device

    @property
    def pool(self):
        if self._pool is None:
            from simgrad.runtime.threadpool import get_pool

            self._pool = get_pool(self.config.num_threads)
        return self._pool

    @property
    def rng_states(self) -> np.ndarray:
        """xorshift128 state per thread, seeded from random_seed."""
        if self._rng is None:  # one per pool thread (the serial code: the last), one per GPU thread on arch=cuda
            if self.on_gpu:
                from simgrad.runtime.device import max_threads

                n = max_threads(self.device) + 1
            else:
                n = max(self.pool.num_threads, 1) + 1
            gen = np.random.default_rng(self.config.random_seed)
            self._rng = self.zeros((n, 4), np.uint32)
            self._rng[:] = gen.integers(1, 2**32 - 1, size=(n, 4), dtype=np.uint32)
        return self._rng

    def zeros(self, shape, dtype) -> np.ndarray:
        """A zeroed array kernels can use: host memory, or the device's shared memory on arch=cuda."""
        if not self.on_gpu:
            return np.zeros(shape, dtype)
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        n = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        return self.device.alloc_shared(n).view(dtype).reshape(shape)

    def context_header(self) -> list[int]:
        """The header slots of every kernel context (abi.HEADER_SLOTS; the tape slots belong to each launcher)."""
        return [self.memory.roots_address, self.error.ctypes.data, self.rng_states.ctypes.data,
                self.pool.parallel_for_address, self.pool.cancel_address, self.sparse.address]

    @property
    def tape_capacity(self) -> int:
        return self.config.ad_stack_size or DEFAULT_TAPE_ENTRIES


_program: Program | None = None
_async_device = None  # the current program's device when it is asynchronous (what sync_for_host asks)


def get_program() -> Program:
    if _program is None:
        _set_program(Program())
    assert _program is not None
    return _program


def sync_for_host() -> None:
    """The one hook in front of Python-scope access of device memory (field views and tree buffers,
    lang/field.py and lang/snode.py; ndarray data, lang/ndarray.py): on an asynchronous device, wait for the
    kernels still queued before the host reads or writes what they may use, as Taichi synchronizes there."""
    d = _async_device  # None on the CPU and the synchronous simulated GPU: one global read
    if d is not None and d.pending:
        d.synchronize()


def _set_program(p: Program | None) -> None:
    global _program, _async_device
    _program = p
    d = p._device if p is not None else None
    _async_device = d if d is not None and d.asynchronous else None


def require_init(what: str) -> Program:
    """The program fields and ndarrays are created in: Taichi 1.7.4 refuses to create one before ti.init() (or
    after ti.reset()) with this TaichiRuntimeError, where simgrad used to start a default program silently."""
    if _program is None:
        from simgrad.errors import TaichiRuntimeError, caller_loc

        raise TaichiRuntimeError(f"Cannot create {what}, maybe you forgot to call `ti.init()` first?", caller_loc())
    return _program


def init(arch=None, **kw) -> Program:
    from simgrad.lang import archs

    known = {"arch", "debug", "default_fp", "default_ip", "random_seed", "kernel_profiler", "ad_stack_size",
             "offline_cache", "offline_cache_file_path", "cpu_max_num_threads", "log_level", "device_memory_GB",
             "device_memory_fraction", "flatten_if", "fast_math", "advanced_optimization", "packed",
             "dynamic_index", "print_ir", "verbose", "check_out_of_bound", "excepthook", "cfg_optimization",
             "short_circuit_operators", "real_matrix_scalarize", "debug_info", "opt_level"}
    unknown = sorted(set(kw) - known)
    if unknown:
        warnings.warn(f"ti.init: ignoring unknown arguments {unknown}", stacklevel=3)
    kw["arch"] = archs.resolve(arch)
    if _program is not None:
        _program.release()
    if kw.get("check_out_of_bound"):
        kw["debug"] = True
    p = Program(**kw)
    _set_program(p)
    return p


def reset() -> None:
    if _program is not None:
        _program.release()
    _set_program(None)
