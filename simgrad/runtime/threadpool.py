"""A native CPU thread pool: workers park in native code, so a parallel loop costs no GIL and no Python.

The pool is a small LLVM module (runtime/ll/threadpool.ll) compiled through the process JIT. Its globals hold the
one current job, so there is exactly one pool per process. Compiled kernels call
`simgrad_parallel_for(task, closure, begin, end, grain)` through a function pointer
(`ThreadPool.parallel_for_address`); it runs `task(closure, lo, hi, tid)` over chunks of [begin, end),
tid 0 being the calling thread.

Workers spin briefly on a generation counter, then sleep on it with a futex. A worker *joins* a job
through a state word (closed bit + count of workers inside); once the caller has run out of chunks it
closes the job and waits only for the workers inside it. So a worker that is slow to wake never delays
the caller, yet no worker can still be inside a job when the next one is published.

A launch that finds the pool busy (another Python thread, or a parallel_for nested in a task) runs
inline on its calling thread with tid 0.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import platform
import threading

from simgrad.runtime import ll
from simgrad.runtime.jit import get_jit

#: futex(2) syscall numbers; on other machines the pool runs everything on the calling thread.
_FUTEX_NR = {"x86_64": 202, "amd64": 202, "aarch64": 98, "arm64": 98, "riscv64": 98}
_FUTEX_WAIT, _FUTEX_WAKE = 128, 129  # the _PRIVATE variants
#: job state word: bit 30 = closed (no more joiners), low bits = workers inside the job
_CLOSED, _JOINED = 1 << 30, (1 << 30) - 1
_INT_MAX = 2**31 - 1
#: most iterations one task call runs: between chunks the pool looks at the cancel flag (Ctrl-C); a
#: chunk this long costs far more than handing it out (one atomic add)
CHUNK_CAP = 1 << 18
#: how long workers (and the caller) spin before sleeping: long enough to stay hot across a training loop's
#: launches from Python (a Tape's bookkeeping between them included). Waking a sleeping worker took so long
#: on a 2-vCPU VM that with 50 us the caller ran most jobs alone: DiffTaichi's diffmpm took 0.94-1.27 s/iter in
#: about half the processes instead of 0.59 (p2g launches: mean 150-200 us, median 62); with 2 ms, 8 of 8 runs
#: took 0.58-0.60. Idle cost: 2 ms of spinning after the last launch.
DEFAULT_SPIN_NS = 2_000_000

_SYMBOLS = [
    "simgrad_parallel_for",
    "simgrad_worker_loop",
    "simgrad_pool_start",
    "simgrad_pool_shutdown",
    "simgrad_pool_reset",
    "simgrad_pool_set_spin_ns",
    "simgrad_install_sigint",
]


def pool_ir(futex_nr: int, machine: str) -> str:
    """LLVM IR of the pool for one futex syscall number and machine (which picks the spin hint)."""
    if machine in ("x86_64", "amd64"):
        pause_decl, pause = "declare void @llvm.x86.sse2.pause()", "call void @llvm.x86.sse2.pause()"
    elif machine in ("aarch64", "arm64"):
        pause_decl, pause = "declare void @llvm.aarch64.hint(i32)", "call void @llvm.aarch64.hint(i32 1)"
    else:
        pause_decl, pause = "", ""
    a8, a4 = "align 8", "align 4"
    return ll.load("threadpool", futex_nr=futex_nr, pause_decl=pause_decl, pause=pause, a8=a8, a4=a4,
                   DEFAULT_SPIN_NS=DEFAULT_SPIN_NS, CHUNK_CAP=CHUNK_CAP, _CLOSED=_CLOSED, _JOINED=_JOINED,
                   _CLOSED_LAST=_CLOSED + 1, _INT_MAX=_INT_MAX, _FUTEX_WAIT=_FUTEX_WAIT, _FUTEX_WAKE=_FUTEX_WAKE)

_PARALLEL_FOR_T = ctypes.CFUNCTYPE(
    None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64
)


class _Native:
    """ctypes handles on the pool module, which is linked into the process once."""

    def __init__(self) -> None:
        machine = platform.machine().lower()
        self.supported = machine in _FUTEX_NR
        addrs = get_jit().load(pool_ir(_FUTEX_NR.get(machine, -1), machine), _SYMBOLS)
        self.parallel_for_address = addrs["simgrad_parallel_for"]
        self.parallel_for = _PARALLEL_FOR_T(self.parallel_for_address)
        self.worker_loop = ctypes.CFUNCTYPE(None, ctypes.c_int32, ctypes.c_int32)(
            addrs["simgrad_worker_loop"]
        )
        self.start = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_int32)(addrs["simgrad_pool_start"])
        self.shutdown = ctypes.CFUNCTYPE(None)(addrs["simgrad_pool_shutdown"])
        self.reset = ctypes.CFUNCTYPE(None)(addrs["simgrad_pool_reset"])
        self.set_spin_ns = ctypes.CFUNCTYPE(None, ctypes.c_int64)(addrs["simgrad_pool_set_spin_ns"])
        self.install_sigint = ctypes.CFUNCTYPE(None)(addrs["simgrad_install_sigint"])
        #: the cancel flag every kernel reads (context slot CTX_CANCEL): 1 after Ctrl-C
        self.cancel_address = get_jit().code.global_address("simgrad_cancel")
        self._sigint_installed = False

    def watch_sigint(self) -> None:
        """Let Ctrl-C stop a running kernel: a native SIGINT handler sets the cancel flag and chains to
        Python's. Only while Python's own handler is the default one (a user's handler is left alone), and
        only from the main thread (where Python delivers signals)."""
        import signal

        if self._sigint_installed or threading.current_thread() is not threading.main_thread():
            return
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            return
        self.install_sigint()
        self._sigint_installed = True


_native: _Native | None = None
_active: ThreadPool | None = None
_lock = threading.RLock()


def _get_native() -> _Native:
    global _native
    with _lock:
        if _native is None:
            _native = _Native()
        return _native


class ThreadPool:
    """The process's pool; creating one shuts down the previous one (the native job state is global)."""

    def __init__(self, num_threads: int | None = None) -> None:
        global _active
        n = num_threads if num_threads is not None else (os.cpu_count() or 1)
        n = min(n, 4096)  # per-thread state (sparse pools' batches: runtime/sparse.py MAX_THREADS) has this room
        if n < 1:
            raise ValueError(f"num_threads must be >= 1, got {n}")
        native = _get_native()
        if not native.supported:
            n = 1
        with _lock:
            if _active is not None:
                _active.shutdown()
            self.num_threads = n
            self.parallel_for_address: int = native.parallel_for_address
            self.cancel_address: int = native.cancel_address
            native.watch_sigint()
            #: ctypes callable parallel_for(task_addr, closure_addr, begin, end, grain)
            self.parallel_for = native.parallel_for
            self._native = native
            self._threads: list[threading.Thread] = []
            self.closed = False
            gen = native.start(n)  # workers start from this generation, so none can miss the first job
            try:
                for tid in range(1, n):
                    t = threading.Thread(
                        target=native.worker_loop, args=(tid, gen), daemon=True, name=f"simgrad-worker-{tid}"
                    )
                    t.start()
                    self._threads.append(t)
            except BaseException:
                self.shutdown()
                raise
            _active = self

    def set_spin_ns(self, ns: int) -> None:
        """How long idle threads spin before sleeping in the kernel (trade latency against idle CPU)."""
        self._native.set_spin_ns(int(ns))

    def shutdown(self) -> None:
        """Stop and join the workers; later launches run on the calling thread until a new pool starts."""
        global _active
        with _lock:
            if self.closed:
                return
            self.closed = True
            self._native.shutdown()
            for t in self._threads:
                t.join()
            self._threads = []
            if _active is self:
                _active = None

    def __repr__(self) -> str:
        return f"ThreadPool(num_threads={self.num_threads}, closed={self.closed})"


def get_pool(num_threads: int | None = None) -> ThreadPool:
    """The process-wide pool, (re)created when absent or when another thread count is asked for."""
    with _lock:
        if _active is None or (num_threads is not None and _active.num_threads != num_threads):
            return ThreadPool(num_threads)
        return _active


def parallel_for(task_addr: int, closure_addr: int, begin: int, end: int, grain: int) -> None:
    """Run native task(closure, lo, hi, tid) over [begin, end) on the current pool (inline if none)."""
    _get_native().parallel_for(task_addr, closure_addr, begin, end, grain)


def _shutdown_at_exit() -> None:
    pool = _active
    if pool is not None:
        pool.shutdown()


def _after_fork_in_child() -> None:
    """Worker threads do not survive fork(): drop them so the child neither hangs nor joins ghosts."""
    global _active, _lock
    _lock = threading.RLock()
    if _native is not None:
        _native.reset()
    if _active is not None:
        _active.closed = True
        _active._threads = []
        _active = None


atexit.register(_shutdown_at_exit)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)
