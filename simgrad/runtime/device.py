"""The device interface of arch=cuda (issue 22): memory, copies, modules, launches, events, errors.

Two implementations of one small interface: `CudaDriver` on the CUDA driver API through cuda-python
(`cuda.bindings.driver`, imported only when a GPU is asked for: the optional extra `simgrad[cuda]`), and
`HostDriver`, the simulated GPU (SIMGRAD_GPU_SIM=1): host memory, and a launch runs the grid's blocks x
threads on the CPU, each thread with its own special registers `{tid, ntid, ctaid, nctaid}` (the layout
codegen/nvptx.py reads with `sim=True`). Driver errors become located Python errors (`DeviceError` and its
subclasses, at the user's line).
"""

from __future__ import annotations

import ctypes
import functools
import mmap
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from simgrad.errors import SimgradError, caller_loc

# The real-GPU runtime (runtime/gpu_launch.py over CudaDriver, fields in managed memory) is written but has not
# run on a GPU yet: a present GPU is used only with SIMGRAD_CUDA_RUNTIME=1 (the device check's switch, benchmarks/
# gpu/run_on_device.sh); otherwise ti.init(arch=ti.cuda) falls back (or runs on the simulated GPU with
# SIMGRAD_GPU_SIM=1). True once a device run has shown it.
CUDA_RUNTIME_READY = False


def cuda_runtime_enabled() -> bool:
    return CUDA_RUNTIME_READY or os.environ.get("SIMGRAD_CUDA_RUNTIME", "") not in ("", "0")


class DeviceError(SimgradError, RuntimeError):
    """A failure the device reported (a bad launch, a faulting kernel), at the user's line."""


class DeviceMemoryError(DeviceError, MemoryError):
    """The device is out of memory."""


def sim_requested() -> bool:
    return os.environ.get("SIMGRAD_GPU_SIM", "") not in ("", "0")


def sim_deferred() -> bool:
    """SIMGRAD_GPU_SIM=async: the simulated GPU queues its work until a synchronize (HostDriver(deferred=True)),
    so a Python-scope access that reads device memory without synchronizing first reads stale data in tests."""
    return os.environ.get("SIMGRAD_GPU_SIM", "") == "async"


def cuda_available() -> bool:
    """A CUDA driver that initialises and at least one device (cuda-python installed)."""
    try:
        from cuda.bindings import driver as cu  # type: ignore[import-not-found]
    except Exception:
        return False
    try:
        (err,) = cu.cuInit(0)
        if int(err) != 0:
            return False
        err, n = cu.cuDeviceGetCount()
        return int(err) == 0 and n > 0
    except Exception:
        return False


class Device:
    """What the GPU runtime needs of a device. Pointers are ints (device addresses)."""

    name = "device"
    asynchronous = False  # launches return before the kernel ends (the host must synchronize to see results)
    pending = False  # work was queued since the last synchronize (what the host's access hook asks)

    def alloc(self, nbytes: int) -> int:
        raise NotImplementedError

    def free(self, ptr: int) -> None:
        raise NotImplementedError

    def alloc_shared(self, nbytes: int) -> np.ndarray:
        """Zeroed memory the host reads and writes as this array and kernels use at the same address (CUDA
        managed memory): field trees, ndarrays, the roots table, the error buffer, random states."""
        raise NotImplementedError

    def reserve(self, nbytes: int) -> int:
        """Memory for a sparse pool that kernels use (the host only reads its table): not necessarily zeroed,
        pages need not be resident until touched."""
        raise NotImplementedError

    def to_device(self, dst: int, src: np.ndarray) -> None:
        raise NotImplementedError

    def to_host(self, dst: np.ndarray, src: int) -> None:
        raise NotImplementedError

    def upload(self, dst: int, src: np.ndarray) -> None:
        """Copy `src` to device address `dst` in stream order (after the work queued before it, before the work
        queued after it) without waiting for the device; `src` may be changed as soon as this returns."""
        raise NotImplementedError

    def load_module(self, image: Any, symbols: list[str]) -> dict[str, Any]:
        """Load a module (PTX text on the GPU, native function addresses on the host): symbol -> function."""
        raise NotImplementedError

    def launch(self, fn: Any, grid: int, block: int, ctx: int) -> None:
        """Run `fn(ctx)` on grid x block threads (asynchronously on the GPU)."""
        raise NotImplementedError

    def prepare_launch(self, fn: Any, grid: int, block: int, ctx: int) -> Callable[[], object]:
        """`launch(fn, grid, block, ctx)` as a call without arguments, its checks and parameters made once (a
        launcher's segment: runtime/gpu_launch.py)."""
        return functools.partial(self.launch, fn, grid, block, ctx)

    def prepare_upload(self, dst: int, src: np.ndarray) -> Callable[[], object]:
        """`upload(dst, src)` as a call without arguments (`src`: the launcher's context, alive as long)."""
        return functools.partial(self.upload, dst, src)

    def synchronize(self) -> None:
        raise NotImplementedError

    def event(self) -> Any:
        """A timing event recorded now (in stream order)."""
        raise NotImplementedError

    def elapsed_ms(self, start: Any, end: Any) -> float:
        """Milliseconds between two recorded events (waits for `end`)."""
        raise NotImplementedError

    def destroy_event(self, e: Any) -> None:
        """Release an event once its times were read."""


_GRID_FN = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64)


class HostEvent:
    """A timing event of the HostDriver: the host clock when the queue reached it (None until then)."""

    __slots__ = ("t",)

    def __init__(self, t: float | None = None) -> None:
        self.t = t


class HostDriver(Device):
    """The simulated GPU: host memory; a launch runs the grid's blocks on the thread pool and, in a block, its
    threads one after another, each with its own special registers (runtime/ll/sim_grid.ll).

    By default launches run at once (the host sees their effects as after a cuCtxSynchronize). `deferred=True`
    (SIMGRAD_GPU_SIM=async) makes it an asynchronous device that queues launches, uploads and events and runs
    them only at synchronize(), or before a synchronous copy (as cuMemcpyHtoD/DtoH wait for the stream): a
    Python-scope access that forgot to synchronize reads stale values, which tests then see."""

    name = "simulated GPU (host)"
    compute_capability = (0, 0)

    def __init__(self, deferred: bool = False) -> None:
        self._blocks: dict[int, np.ndarray] = {}
        self._reserved: dict[int, mmap.mmap] = {}
        self._grid: Any = None
        self.launches = 0  # kernels launched (tests count them)
        self.deferred = self.asynchronous = deferred
        self.syncs = 0  # synchronize() calls that ran queued work (tests count them)
        self._queue: list[tuple] = []

    @property
    def pending(self) -> bool:  # type: ignore[override]
        return bool(self._queue)

    def alloc(self, nbytes: int) -> int:
        buf = np.zeros(max(int(nbytes), 1) + 64, dtype=np.uint8)
        ptr = (buf.ctypes.data + 63) & ~63
        self._blocks[ptr] = buf
        return ptr

    def free(self, ptr: int) -> None:
        if ptr not in self._blocks:
            raise DeviceError(f"free of an address this device did not allocate: {ptr:#x}", caller_loc())
        if self._queue:  # queued work may still use it: freed in its turn
            self._queue.append(("free", ptr))
        else:
            del self._blocks[ptr]

    def alloc_shared(self, nbytes: int) -> np.ndarray:
        ptr = self.alloc(nbytes)
        return np.ctypeslib.as_array((ctypes.c_uint8 * max(int(nbytes), 1)).from_address(ptr))[:nbytes]

    def reserve(self, nbytes: int) -> int:
        """Address space without commitment (as a GPU's managed memory, pages are made on first touch)."""
        flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | getattr(mmap, "MAP_NORESERVE", 0x4000)
        region = mmap.mmap(-1, max(int(nbytes), 1), flags=flags)
        ptr = ctypes.addressof(ctypes.c_char.from_buffer(region))
        self._reserved[ptr] = region
        return ptr

    def owns(self, ptr: int) -> bool:
        """Whether `ptr` lies in memory this device allocated (tests check kernels see only device memory)."""
        return any(base <= ptr < base + len(buf) - 64 for base, buf in self._blocks.items()) or \
            any(base <= ptr < base + len(region) for base, region in self._reserved.items())

    def to_device(self, dst: int, src: np.ndarray) -> None:
        self.synchronize()
        src = np.ascontiguousarray(src)
        ctypes.memmove(dst, src.ctypes.data, src.nbytes)

    def to_host(self, dst: np.ndarray, src: int) -> None:
        if not dst.flags.c_contiguous:
            raise ValueError("to_host needs a C-contiguous array")
        self.synchronize()
        ctypes.memmove(dst.ctypes.data, src, dst.nbytes)

    def upload(self, dst: int, src: np.ndarray) -> None:
        if not self.deferred:
            return self.to_device(dst, src)
        self._queue.append(("copy", dst, np.array(src, copy=True, order="C")))  # the bytes as they are now

    def load_module(self, image: Any, symbols: list[str]) -> dict[str, Any]:
        """`image` maps symbols to native addresses of `void fn(ptr ctx, ptr sreg)` (already linked)."""
        missing = [s for s in symbols if not image.get(s)]
        if missing:
            raise DeviceError(f"module has no functions {missing}", caller_loc())
        return {s: int(image[s]) for s in symbols}

    def launch(self, fn: Any, grid: int, block: int, ctx: int) -> None:
        """`fn` is the native address of `void fn(ptr ctx, ptr sreg)`; `ctx` a context whose header holds the
        thread pool's parallel_for (runtime/abi.py CTX_PFOR), as every kernel context does."""
        self._check_config(grid, block)
        self._launch(fn, grid, block, ctx)

    def prepare_launch(self, fn: Any, grid: int, block: int, ctx: int) -> Callable[[], object]:
        self._check_config(grid, block)
        return functools.partial(self._launch, fn, grid, block, ctx)

    def prepare_upload(self, dst: int, src: np.ndarray) -> Callable[[], object]:
        if self.deferred or not src.flags.c_contiguous:
            return functools.partial(self.upload, dst, src)
        return functools.partial(ctypes.memmove, dst, src.ctypes.data, src.nbytes)

    @staticmethod
    def _check_config(grid: int, block: int) -> None:
        if grid < 1 or block < 1 or block > 1024:
            raise DeviceError(f"invalid launch configuration: grid={grid}, block={block} (block must be 1..1024)",
                              caller_loc())

    def _launch(self, fn: Any, grid: int, block: int, ctx: int) -> None:
        self.launches += 1
        if self._grid is None:  # the grid runner, loaded at the first launch (queued or not)
            from simgrad.runtime import abi, ll
            from simgrad.runtime.jit import get_jit

            text = ll.load("sim_grid", pfor_slot=abi.CTX_PFOR) + ll.load("sim_blocks", symbol="simgrad_sim_blocks")
            self._grid = _GRID_FN(get_jit().load(text, ["simgrad_sim_grid"])["simgrad_sim_grid"])
        if self.deferred:
            self._queue.append(("launch", fn, grid, block, ctx))
        else:
            self._grid(ctx, fn, block, grid)

    def synchronize(self) -> None:
        """Run the queued work in order (deferred mode; nothing to do otherwise)."""
        if not self._queue:
            return
        self.syncs += 1
        queue, self._queue = self._queue, []
        for op in queue:
            if op[0] == "launch":
                _, fn, grid, block, ctx = op
                self._grid(ctx, fn, block, grid)
            elif op[0] == "copy":
                _, dst, src = op
                ctypes.memmove(dst, src.ctypes.data, src.nbytes)
            elif op[0] == "free":
                self._blocks.pop(op[1], None)
            else:
                op[1].t = time.perf_counter()

    def event(self) -> HostEvent:
        if not self.deferred:
            return HostEvent(time.perf_counter())
        e = HostEvent()
        self._queue.append(("event", e))
        return e

    def elapsed_ms(self, start: HostEvent, end: HostEvent) -> float:
        if end.t is None or start.t is None:
            self.synchronize()
        assert start.t is not None and end.t is not None
        return (end.t - start.t) * 1e3


class CudaDriver(Device):
    """The CUDA driver API through cuda-python: the primary context of device `ordinal`, one stream (the
    default). Written against the documented API; exercised only on a machine with a GPU."""

    name = "CUDA"
    asynchronous = True

    def __init__(self, ordinal: int = 0, stack_bytes: int = 0) -> None:
        from cuda.bindings import driver as cu  # type: ignore[import-not-found]

        self.cu = cu
        self._check(cu.cuInit(0))
        self.device = self._check(cu.cuDeviceGet(ordinal))
        self.context = self._check(cu.cuDevicePrimaryCtxRetain(self.device))
        self._check(cu.cuCtxSetCurrent(self.context))
        if stack_bytes > 0:  # ti.init(cuda_stack_limit=...): a thread's stack, which recursive real functions use
            self._check(cu.cuCtxSetLimit(cu.CUlimit.CU_LIMIT_STACK_SIZE, int(stack_bytes)))
        major = self._check(cu.cuDeviceGetAttribute(
            cu.CUdevice_attribute.CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MAJOR, self.device))
        minor = self._check(cu.cuDeviceGetAttribute(
            cu.CUdevice_attribute.CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MINOR, self.device))
        self.compute_capability = (int(major), int(minor))
        self.sm_count = int(self._check(cu.cuDeviceGetAttribute(
            cu.CUdevice_attribute.CU_DEVICE_ATTRIBUTE_MULTIPROCESSOR_COUNT, self.device)))
        self.total_memory = int(self._check(self.cu.cuDeviceTotalMem(self.device)))
        self.modules: list[Any] = []
        self.shared: list[int] = []

    def _check(self, result):
        """cuda-python returns (CUresult, values...): raise a located error for a failure, else the values."""
        err, *vals = result if isinstance(result, tuple) else (result,)
        code = int(err)
        if code != 0:
            _, name = self.cu.cuGetErrorName(err)
            _, text = self.cu.cuGetErrorString(err)
            name = name.decode() if isinstance(name, bytes) else str(name)
            text = text.decode() if isinstance(text, bytes) else str(text)
            cls = DeviceMemoryError if code == 2 else DeviceError  # CUDA_ERROR_OUT_OF_MEMORY
            extra = " (a device-side assertion failed)" if code == 710 else ""  # CUDA_ERROR_ASSERT
            raise cls(f"CUDA error {name} ({code}): {text}{extra}", caller_loc())
        return vals[0] if len(vals) == 1 else (tuple(vals) if vals else None)

    def alloc(self, nbytes: int) -> int:
        return int(self._check(self.cu.cuMemAlloc(max(int(nbytes), 1))))

    def free(self, ptr: int) -> None:
        self._check(self.cu.cuMemFree(ptr))

    def alloc_shared(self, nbytes: int) -> np.ndarray:
        n = max(int(nbytes), 1)
        ptr = int(self._check(self.cu.cuMemAllocManaged(n, 1)))  # CU_MEM_ATTACH_GLOBAL: every stream, every device
        self._check(self.cu.cuMemsetD8(ptr, 0, n))
        self._check(self.cu.cuCtxSynchronize())
        self.shared.append(ptr)  # freed with the context (the program's memory lives as long as the process)
        return np.ctypeslib.as_array((ctypes.c_uint8 * n).from_address(ptr))[:nbytes]

    def reserve(self, nbytes: int) -> int:
        ptr = int(self._check(self.cu.cuMemAllocManaged(max(int(nbytes), 1), 1)))  # pages migrate on first touch
        self.shared.append(ptr)
        return ptr

    def to_device(self, dst: int, src: np.ndarray) -> None:
        src = np.ascontiguousarray(src)
        self._check(self.cu.cuMemcpyHtoD(dst, src.ctypes.data, src.nbytes))

    def to_host(self, dst: np.ndarray, src: int) -> None:
        self._check(self.cu.cuMemcpyDtoH(dst.ctypes.data, src, dst.nbytes))

    def upload(self, dst: int, src: np.ndarray) -> None:
        """cuMemcpyHtoDAsync on the default stream: from pageable memory the driver stages the bytes before it
        returns, without synchronizing (CUDA's "API synchronization behavior"), so `src` may change at once."""
        src = np.ascontiguousarray(src)
        self._check(self.cu.cuMemcpyHtoDAsync(dst, src.ctypes.data, src.nbytes, 0))
        self.pending = True

    def load_module(self, image: Any, symbols: list[str]) -> dict[str, Any]:
        data = image.encode() + b"\0" if isinstance(image, str) else image
        module = self._check(self.cu.cuModuleLoadData(data))
        self.modules.append(module)
        return {s: self._check(self.cu.cuModuleGetFunction(module, s.encode())) for s in symbols}

    def launch(self, fn: Any, grid: int, block: int, ctx: int) -> None:
        self.prepare_launch(fn, grid, block, ctx)()

    def prepare_launch(self, fn: Any, grid: int, block: int, ctx: int) -> Callable[[], object]:
        """cuLaunchKernel with its kernelParams built once: the kernel's one parameter, the context's device
        address (the driver copies the parameters when the launch is queued)."""
        arg = np.array([ctx], dtype=np.uint64)
        params = np.array([arg.ctypes.data], dtype=np.uint64)
        launch, check, pp = self.cu.cuLaunchKernel, self._check, params.ctypes.data

        def run(_keep=(arg, params)) -> None:
            check(launch(fn, grid, 1, 1, block, 1, 1, 0, 0, pp, 0))
            self.pending = True

        return run

    def prepare_upload(self, dst: int, src: np.ndarray) -> Callable[[], object]:
        copy, check, p, n = self.cu.cuMemcpyHtoDAsync, self._check, src.ctypes.data, src.nbytes

        def run(_keep=src) -> None:
            check(copy(dst, p, n, 0))
            self.pending = True

        return run

    def synchronize(self) -> None:
        """cuCtxSynchronize: also where a fault of a kernel that did not wait is reported (a DeviceError)."""
        self.pending = False
        self._check(self.cu.cuCtxSynchronize())

    def event(self) -> Any:
        e = self._check(self.cu.cuEventCreate(0))  # CU_EVENT_DEFAULT: timing enabled
        self._check(self.cu.cuEventRecord(e, 0))
        return e

    def elapsed_ms(self, start: Any, end: Any) -> float:
        self._check(self.cu.cuEventSynchronize(end))
        # cuda-bindings 12.8+ also has the _v2 form (same call, same result); older ones only the first
        elapsed = getattr(self.cu, "cuEventElapsedTime", None) or self.cu.cuEventElapsedTime_v2
        return float(self._check(elapsed(start, end)))

    def destroy_event(self, e: Any) -> None:
        self._check(self.cu.cuEventDestroy(e))


def saturating_grid(device: Device, block: int) -> int:
    """Blocks that fill the device (2048 resident threads per multiprocessor): the grid of every launch at most,
    its grid-stride loop covering the rest, so a thread index stays below `max_threads` (random states)."""
    sm = getattr(device, "sm_count", 1)
    return max(1, sm * max(1, 2048 // max(block, 1)))


def max_threads(device: Device) -> int:
    """The most threads a launch has (saturating_grid x block for any block size)."""
    return getattr(device, "sm_count", 1) * 2048
