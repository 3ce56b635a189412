"""The process-wide runtime state that `ti.init` creates: configuration, SNode trees, memory, the thread
pool, RNG states, the error buffer and the kernel profiler."""

from __future__ import annotations

import os
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from simgrad import dtypes as dt
from simgrad.runtime import abi
from simgrad.runtime.memory import Memory
from simgrad.runtime.sparse import MAX_RESERVE, SparseMemory

if TYPE_CHECKING:
    from simgrad.runtime.jit import CodeSpace

DEFAULT_TAPE_ENTRIES = 1 << 16


# Taichi 1.7.4's compile configuration (dir(ti.lang.impl.default_cfg()), less arch and the default types) with its
# defaults: ti.init takes each as an argument or a TI_<KEY> environment variable and current_cfg() reports it.
# Those simgrad acts on are read below; the others are kept as given (their effects are Taichi's code generator's).
TAICHI_CONFIG: dict = {
    "ad_stack_size": 0, "advanced_optimization": True, "allow_nv_shader_extension": True,
    "auto_mesh_local_default_occupacy": 4, "cache_loop_invariant_global_vars": True, "cfg_optimization": True,
    "check_out_of_bound": False, "cpu_block_dim_adaptive": True, "cpu_max_num_threads": 0, "cuda_stack_limit": 0,
    "debug": False, "default_cpu_block_dim": 32, "default_gpu_block_dim": 128, "demote_dense_struct_fors": True,
    "demote_no_access_mesh_fors": True, "detect_read_only": True, "device_memory_GB": 1.0,
    "device_memory_fraction": 0.0, "experimental_auto_mesh_local": False, "fast_math": True, "flatten_if": False,
    "force_scalarize_matrix": False, "gpu_max_reg": 0, "half2_vectorization": False, "kernel_profiler": False,
    "lower_access": True, "make_block_local": True, "make_cpu_multithreading_loop": True,
    "make_mesh_block_local": True, "make_thread_local": True, "max_block_dim": 0,
    "mesh_localize_all_attr_mappings": False, "mesh_localize_from_end_mapping": False,
    "mesh_localize_to_end_mapping": True, "move_loop_invariant_outside_if": False, "num_compile_threads": 4,
    "offline_cache": True, "offline_cache_cleaning_factor": 0.25, "offline_cache_cleaning_policy": "lru",
    "offline_cache_file_path": "", "offline_cache_max_size_of_files": 100 * 1024 * 1024, "opt_level": 1,
    "optimize_mesh_reordered_mapping": True, "print_accessor_ir": False, "print_ir": False,
    "print_ir_dbg_info": False, "print_kernel_amdgcn": False, "print_kernel_asm": False,
    "print_kernel_llvm_ir": False, "print_kernel_llvm_ir_optimized": False, "print_preprocessed_ir": False,
    "print_struct_llvm_ir": False, "quant_opt_atomic_demotion": True, "quant_opt_store_fusion": True,
    "random_seed": 0, "real_matrix_scalarize": True, "saturating_grid_dim": 0, "simplify_after_lower_access": True,
    "simplify_before_lower_access": True, "timeline": False, "use_llvm": True, "verbose": True,
    "verbose_kernel_launches": False, "vk_api_version": "",
}
# Taichi's _SpecialConfig: options of its Python layer, returned by ti.init(_test_mode=True)
SPECIAL_CONFIG: dict = {"log_level": "info", "gdb_trigger": False, "short_circuit_operators": True,
                        "print_full_traceback": False, "unrolling_limit": 32}
# simgrad's own options: flush_denormals (runtime/fpenv.py; Taichi always flushes, this is its way out);
# simt_lanes: iterations of a parallel loop whose while loops run in lock step on the CPU (passes/lanes.py; 0 off,
# -1 four vector registers' worth of the loop's widest values); fission_lanes: iterations of a parallel loop with
# scatters run W at a time, the part before the scatters vectorised (passes/fission.py; 0 off, -1 by the host)
SIMGRAD_CONFIG: dict = {"flush_denormals": True, "simt_lanes": -1, "fission_lanes": -1}
# accepted for older programs, without effect (not in Taichi 1.7.4's list)
LEGACY_OPTIONS = {"packed", "dynamic_index", "excepthook", "debug_info"}


class SpecialConfig:
    """What ti.init(_test_mode=True) returns, as Taichi's: the Python-layer options as set."""

    def __init__(self, kw: dict):
        for k, v in SPECIAL_CONFIG.items():
            setattr(self, k, kw.get(k, v))


def _from_environment(kw: dict) -> None:
    """TI_<KEY> for every option not given as an argument, as Taichi reads them ("0"/"1" for booleans)."""
    for key, default in {**TAICHI_CONFIG, **SPECIAL_CONFIG, **SIMGRAD_CONFIG}.items():
        value = os.environ.get("TI_" + key.upper(), "")
        if key in kw or not value:
            continue
        kw[key] = bool(int(value)) if isinstance(default, bool) else type(default)(value)
    for key, types in (("default_fp", {"32": dt.f32, "64": dt.f64}), ("default_ip", {"32": dt.i32, "64": dt.i64})):
        value = os.environ.get("TI_" + key.upper(), "")
        if value and kw.get(key) is None:
            if value not in types:
                raise ValueError(f"Invalid TI_{key.upper()}={value}, should be 32 or 64")
            kw[key] = types[value]


def check_require_version(require_version: str) -> None:
    """ti.init(require_version="major.minor[.patch][rest]"): the Taichi version simgrad follows must be at least
    that (Taichi compares its own version; simgrad implements Taichi 1.7.4's language)."""
    from simgrad._lib.core import TAICHI_VERSION

    digits = require_version
    for i, c in enumerate(require_version):
        if not (c.isdigit() or c == "."):
            digits = require_version[:i]
            break
    try:
        parts = [int(n) for n in digits.split(".")]
        wanted = (parts[0], parts[1], parts[2] if len(parts) > 2 else 0)
    except (ValueError, IndexError):
        raise ValueError("The require_version should be formatted following PEP 440, and include major, minor, "
                         f"and patch number, e.g., major.minor.patch (got {require_version!r})") from None
    if TAICHI_VERSION < wanted:
        have = ".".join(map(str, TAICHI_VERSION))
        raise RuntimeError(f"Taichi version mismatch: required >= {require_version}, simgrad implements {have}")


class Config:
    def __init__(self, **kw):
        for key, default in TAICHI_CONFIG.items():
            setattr(self, key, kw.get(key, default))
        self.arch = kw.get("arch")
        self.debug = bool(kw.get("debug", False))
        self.default_fp = dt.from_any(kw.get("default_fp") or dt.f32)
        self.default_ip = dt.from_any(kw.get("default_ip") or dt.i32)
        self.random_seed = int(kw.get("random_seed", 0))
        self.kernel_profiler = bool(kw.get("kernel_profiler", False))
        self.ad_stack_size = int(kw.get("ad_stack_size", 0) or 0)
        self.fast_math = bool(kw.get("fast_math", True))  # Taichi's default; see codegen.llvm.FAST_MATH_FLAGS
        self.flush_denormals = bool(kw.get("flush_denormals", SIMGRAD_CONFIG["flush_denormals"]))
        self.simt_lanes = _lanes(kw.get("simt_lanes", SIMGRAD_CONFIG["simt_lanes"]))
        self.fission_lanes = _lanes(kw.get("fission_lanes", SIMGRAD_CONFIG["fission_lanes"]), "fission_lanes")
        self.offline_cache = bool(kw.get("offline_cache", True))
        self.offline_cache_file_path = kw.get("offline_cache_file_path")
        threads = kw.get("cpu_max_num_threads") or int(os.environ.get("SIMGRAD_NUM_THREADS", 0) or 0)
        self.num_threads = int(threads) if threads else (os.cpu_count() or 1)
        self.cpu_max_num_threads = self.num_threads


def _lanes(value, name: str = "simt_lanes") -> int:
    lanes = int(value)
    if lanes != -1 and (lanes < 0 or lanes & (lanes - 1) or lanes == 1 or lanes > 64):
        raise ValueError(f"{name} must be -1 (by the host's vector registers), 0 (off) or a power of two from 2 "
                         f"to 64, got {value!r}")
    return lanes


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
        self.memory = (Memory(self.device.alloc_shared, lambda a: self.device.free(a.ctypes.data)) if self.on_gpu
                       else Memory())
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
        # fields made without a shape since the last kernel compile, checked then (lang/factories.py Pending)
        self.pending_fields: list = []
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
        if self.pending_fields:
            self.check_pending_fields()
        for t in self.trees:
            if not t.materialized:
                t.materialize()

    def check_pending_fields(self) -> None:
        """Taichi's checks when its fields are materialised: every field made since the last check is placed,
        with its gradient (dual) when made with needs_grad (needs_dual), and a matrix field's entries have one
        shape. A failure is a TaichiRuntimeError naming where each field was made, and stays until fixed."""
        from simgrad.errors import SimgradRuntimeError

        for kind in ("field", "grad", "dual", "shape"):
            bad = [p for p in self.pending_fields if p.problem(kind)]
            if bad:
                raise SimgradRuntimeError(bad[0].message(kind, bad), bad[0].loc)
        self.pending_fields = []

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

            self._device = device.CudaDriver(stack_bytes=int(self.config.cuda_stack_limit or 0)) \
                if gpu_mode() == "cuda" else \
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


def init(arch=None, default_fp=None, default_ip=None, _test_mode=False, enable_fallback=True, require_version=None,
         **kw):
    """ti.init: Taichi's options (TAICHI_CONFIG, SPECIAL_CONFIG) as arguments or TI_<KEY> environment variables;
    an option Taichi does not know either is its KeyError. Returns the program (Taichi returns None), or with
    `_test_mode` the SpecialConfig."""
    from simgrad.lang import archs

    if require_version is not None:
        check_require_version(require_version)
    if "default_up" in kw:
        raise KeyError("'default_up' is always the unsigned type of 'default_ip'. Please set 'default_ip' instead.")
    kw["default_fp"], kw["default_ip"] = default_fp, default_ip
    unknown = [k for k in kw if k not in TAICHI_CONFIG and k not in SPECIAL_CONFIG and k not in LEGACY_OPTIONS
               and k not in SIMGRAD_CONFIG and k not in ("default_fp", "default_ip")]
    if unknown:
        raise KeyError(f"Unrecognized keyword argument(s) for ti.init: {', '.join(unknown)}")
    _from_environment(kw)
    spec = SpecialConfig(kw)
    if not _test_mode:
        from simgrad.lang.logging import set_logging_level

        set_logging_level(spec.log_level)
    kw["arch"] = archs.resolve(arch, enable_fallback)
    if _program is not None:
        _program.release()
    if kw.get("check_out_of_bound"):
        kw["debug"] = True
    p = Program(**kw)
    _set_program(p)
    return spec if _test_mode else p


def reset() -> None:
    if _program is not None:
        _program.release()
    _set_program(None)
