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

from simgrad.runtime import fpenv, ll
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


#: SIMGRAD_POOL_STATS=1: the pool counts what it does in `@simgrad_pool_stats` (pool_stats()). Off, the IR
#: has none of the counting code (the only change: sg_run_chunks returns how many chunks it ran).
STAT_NAMES = (
    "launches",          # jobs published to the workers
    "direct",            # launches run on the calling thread alone (one thread, small range, pool busy)
    "chunks_caller",     # chunks run by the calling thread (tid 0) in published jobs
    "chunks_workers",    # chunks run by workers
    "caller_spun",       # the caller ran out of chunks with workers still inside and waited spinning
    "caller_slept",      # ... and the spin ran out: it slept on a futex (a worker inside was stalled)
    "caller_wait_ns",    # total time the caller waited for workers after its last chunk
    "caller_wait_max_ns",
    "worker_spin_hits",  # a worker saw the next job while spinning
    "worker_sleeps",     # a worker's spin ran out and it slept on a futex
    "wakes",             # publishes that had to wake sleeping workers (futex wake)
    "joins",             # workers that joined a job
    "late",              # workers that came after the job was closed (they ran nothing)
    "launch_ns",         # total time inside published launches
    "spare14", "spare15",
    # caller's share of a published job's chunks: < 1/4, < 1/2, < 3/4, < 1, all of them
    "share_q1", "share_q2", "share_q3", "share_q4", "share_all",
    # published launch durations: < 8 us, < 16, ..., < 4096 us, longer
    "t_lt8us", "t_lt16us", "t_lt32us", "t_lt64us", "t_lt128us", "t_lt256us", "t_lt512us", "t_lt1ms",
    "t_lt2ms", "t_lt4ms", "t_ge4ms",
)
N_STATS = 32


def _stats_enabled() -> bool:
    return os.environ.get("SIMGRAD_POOL_STATS", "0") not in ("", "0")


def _slot(name: str, index: str) -> str:
    """`%name` = the address of counter `index` (an i64 value or constant)."""
    return f"%{name} = getelementptr [{N_STATS} x i64], ptr @simgrad_pool_stats, i64 0, i64 {index}"


def _count(name: str, stat: str, value: str = "1", op: str = "add") -> str:
    return "\n  ".join([_slot(f"stp.{name}", str(STAT_NAMES.index(stat))),
                        f"%st.{name} = atomicrmw {op} ptr %stp.{name}, i64 {value} monotonic, align 8"])


def _stat_code() -> dict[str, str]:
    """What each `${st_*}` of threadpool.ll becomes with SIMGRAD_POOL_STATS (the names of the values it
    reads, %mine, %n, %chunk, %ran, are the .ll file's)."""
    q, b0 = STAT_NAMES.index("share_q1"), STAT_NAMES.index("t_lt8us")
    share = [  # the caller's share of the job's chunks, in quarters
        "%sh.c1 = sub i64 %chunk, 1", "%sh.n1 = add i64 %n, %sh.c1", "%sh.total = sdiv i64 %sh.n1, %chunk",
        "%sh.m4 = mul i64 %mine, 4", "%sh.q = sdiv i64 %sh.m4, %sh.total", "%sh.all = icmp sge i64 %mine, %sh.total",
        "%sh.b = select i1 %sh.all, i64 4, i64 %sh.q", f"%sh.k = add i64 %sh.b, {q}", _slot("sh.p", "%sh.k"),
        "%sh.r = atomicrmw add ptr %sh.p, i64 1 monotonic, align 8"]
    launch = [  # the launch, its time from %t0 on and its log2 duration bucket
        "%te = call i64 @sg_now()", "%dl = sub i64 %te, %t0", _count("launch", "launches"),
        _count("lns", "launch_ns", "%dl"), "%us = udiv i64 %dl, 1000", "%us1 = or i64 %us, 1",
        "%lz = call i64 @llvm.ctlz.i64(i64 %us1, i1 true)", "%lg = sub i64 63, %lz",  # floor(log2(us))
        "%lb0 = sub i64 %lg, 2", "%lneg = icmp slt i64 %lb0, 0", "%lb1 = select i1 %lneg, i64 0, i64 %lb0",
        "%lbig = icmp sgt i64 %lb1, 10", "%lb = select i1 %lbig, i64 10, i64 %lb1",
        f"%lk = add i64 %lb, {b0}", _slot("lp", "%lk"), "%lr = atomicrmw add ptr %lp, i64 1 monotonic, align 8"]
    # %tc (after the caller's last chunk) is read in `waited`, which `work` dominates
    waited = ["%tw = call i64 @sg_now()", "%dw = sub i64 %tw, %tc", _count("wns", "caller_wait_ns", "%dw"),
              _count("wmax", "caller_wait_max_ns", "%dw", "umax")]
    code = {
        "st_direct": _count("direct", "direct"), "st_t0": "%t0 = call i64 @sg_now()",
        "st_wakes": _count("wakes", "wakes"),
        "st_mine": "\n  ".join([_count("mine", "chunks_caller", "%mine"), *share, "%tc = call i64 @sg_now()"]),
        "st_spun": _count("spun", "caller_spun"), "st_slept": _count("slept", "caller_slept"),
        "st_waited": "\n  ".join(waited), "st_launch": "\n  ".join(launch),
        "st_hit": _count("hit", "worker_spin_hits"), "st_wsleep": _count("wsleep", "worker_sleeps"),
        "st_late": _count("late", "late"), "st_join": _count("join", "joins"),
        "st_wchunks": _count("wchunks", "chunks_workers", "%ran"),
    }
    return code


def pool_ir(futex_nr: int, machine: str, stats: bool = False) -> str:
    """LLVM IR of the pool for one futex syscall number and machine (which picks the spin hint); `stats`
    fills the `${st_*}` places of threadpool.ll with the SIMGRAD_POOL_STATS counters (else they are empty)."""
    if machine in ("x86_64", "amd64"):
        pause_decl, pause = "declare void @llvm.x86.sse2.pause()", "call void @llvm.x86.sse2.pause()"
    elif machine in ("aarch64", "arm64"):
        pause_decl, pause = "declare void @llvm.aarch64.hint(i32)", "call void @llvm.aarch64.hint(i32 1)"
    else:
        pause_decl, pause = "", ""
    a8, a4 = "align 8", "align 4"
    counters = {k: (v if stats else "") for k, v in _stat_code().items()}
    return ll.load("threadpool", futex_nr=futex_nr, pause_decl=pause_decl, pause=pause, a8=a8, a4=a4,
                   DEFAULT_SPIN_NS=DEFAULT_SPIN_NS, CHUNK_CAP=CHUNK_CAP, _CLOSED=_CLOSED, _JOINED=_JOINED,
                   _CLOSED_LAST=_CLOSED + 1, _INT_MAX=_INT_MAX, _FUTEX_WAIT=_FUTEX_WAIT, _FUTEX_WAKE=_FUTEX_WAKE,
                   N_STATS=N_STATS, **fpenv.pool_params(machine), **counters)


def pool_stats() -> dict:
    """The pool's counters since the last reset_pool_stats() (all zero unless SIMGRAD_POOL_STATS=1 was set
    when the pool was first used in this process)."""
    native = _get_native()
    return {k: int(native.stats[i]) for i, k in enumerate(STAT_NAMES) if not k.startswith("spare")}


def reset_pool_stats() -> None:
    native = _get_native()
    for i in range(N_STATS):
        native.stats[i] = 0


_PARALLEL_FOR_T = ctypes.CFUNCTYPE(
    None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64
)


class _Native:
    """ctypes handles on the pool module, which is linked into the process once."""

    def __init__(self) -> None:
        machine = platform.machine().lower()
        self.supported = machine in _FUTEX_NR
        self.stats_enabled = _stats_enabled()
        addrs = get_jit().load(pool_ir(_FUTEX_NR.get(machine, -1), machine, self.stats_enabled), _SYMBOLS)
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
        self.stats = (ctypes.c_int64 * N_STATS).from_address(get_jit().code.global_address("simgrad_pool_stats"))
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
