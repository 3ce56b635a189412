"""A native CPU thread pool: workers park in native code, so a parallel loop costs no GIL and no Python.

The pool is a small LLVM module (IR text below) compiled through the process JIT. Its globals hold the
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


def pool_ir(futex_nr: int, machine: str, stats: bool = False) -> str:
    """LLVM IR of the pool for one futex syscall number and machine (which picks the spin hint); `stats`
    adds the counters of SIMGRAD_POOL_STATS (each `{st(...)}` below is empty without it)."""

    def st(name: str, slot: int | str, value: str = "1", op: str = "add") -> str:
        if not stats:
            return ""
        k = STAT_NAMES.index(slot) if isinstance(slot, str) else slot
        slot_ptr = f"%stp.{name}"
        return (f"{slot_ptr} = getelementptr [{N_STATS} x i64], ptr @simgrad_pool_stats, i64 0, i64 {k}\n  "
                f"%st.{name} = atomicrmw {op} ptr {slot_ptr}, i64 {value} monotonic, align 8")

    def now(name: str) -> str:
        return f"%{name} = call i64 @sg_now()" if stats else ""

    if machine in ("x86_64", "amd64"):
        pause_decl, pause = "declare void @llvm.x86.sse2.pause()", "call void @llvm.x86.sse2.pause()"
    elif machine in ("aarch64", "arm64"):
        pause_decl, pause = "declare void @llvm.aarch64.hint(i32)", "call void @llvm.aarch64.hint(i32 1)"
    else:
        pause_decl, pause = "", ""
    a8, a4 = "align 8", "align 4"
    return f"""
@simgrad_cancel = global i32 0, align 64   ; set by SIGINT: tasks stop taking chunks, while loops exit
@sg_prev_sigint = internal global ptr null
@sg_task = internal global ptr null, align 64
@sg_closure = internal global ptr null
@sg_end = internal global i64 0
@sg_chunk = internal global i64 1
@sg_spin_ns = internal global i64 {DEFAULT_SPIN_NS}
@sg_nthreads = internal global i32 1
@sg_shutdown = internal global i32 0
@sg_busy = internal global i32 0
@sg_next = internal global i64 0, align 64
@sg_gen = internal global i32 0, align 64
@sg_sleepers = internal global i32 0
@sg_state = internal global i32 {_CLOSED}, align 64
@sg_caller_waiting = internal global i32 0
@simgrad_pool_stats = global [{N_STATS} x i64] zeroinitializer, align 64   ; SIMGRAD_POOL_STATS counters

declare i64 @syscall(i64, ...)
declare i32 @clock_gettime(i32, ptr)
declare i32 @sched_yield()
declare ptr @signal(i32, ptr)
declare i64 @llvm.ctlz.i64(i64, i1)
{pause_decl}

define internal i64 @sg_now() {{
  %ts = alloca {{ i64, i64 }}, align 8
  call i32 @clock_gettime(i32 1, ptr %ts)
  %s = load i64, ptr %ts, align 8
  %nsp = getelementptr {{ i64, i64 }}, ptr %ts, i32 0, i32 1
  %ns = load i64, ptr %nsp, align 8
  %s9 = mul i64 %s, 1000000000
  %t = add i64 %s9, %ns
  ret i64 %t
}}

define internal void @sg_futex(ptr %addr, i64 %op, i32 %val) {{
  %v = sext i32 %val to i64
  call i64 (i64, ...) @syscall(i64 {futex_nr}, ptr %addr, i64 %op, i64 %v, ptr null)
  ret void
}}

; Spin until ((*addr & mask) == val) == eq (acquire) or the spin budget runs out; returns the last value.
define internal i32 @sg_spin_until(ptr %addr, i32 %mask, i32 %val, i1 %eq) {{
entry:
  %budget = load atomic i64, ptr @sg_spin_ns monotonic, {a8}
  %t0 = call i64 @sg_now()
  %deadline = add i64 %t0, %budget
  br label %loop
loop:
  %cur = load atomic i32, ptr %addr acquire, {a4}
  %m = and i32 %cur, %mask
  %is = icmp eq i32 %m, %val
  %done = icmp eq i1 %is, %eq
  br i1 %done, label %out, label %more
more:
  {pause}
  {pause}
  {pause}
  {pause}
  %now = call i64 @sg_now()
  %late = icmp sgt i64 %now, %deadline
  br i1 %late, label %out, label %loop
out:
  ret i32 %cur
}}

; Runs chunks of the current job until none is left; returns how many it ran.
define internal i64 @sg_run_chunks(i32 %tid) {{
entry:
  %task = load atomic ptr, ptr @sg_task monotonic, {a8}
  %clo = load atomic ptr, ptr @sg_closure monotonic, {a8}
  %end = load atomic i64, ptr @sg_end monotonic, {a8}
  %chunk = load atomic i64, ptr @sg_chunk monotonic, {a8}
  br label %loop
loop:
  %ran = phi i64 [0, %entry], [%ran1, %body]
  %stop = load atomic i32, ptr @simgrad_cancel monotonic, {a4}
  %stopped = icmp ne i32 %stop, 0
  br i1 %stopped, label %done, label %take
take:
  %lo = atomicrmw add ptr @sg_next, i64 %chunk monotonic, {a8}
  %more = icmp slt i64 %lo, %end
  br i1 %more, label %body, label %done
body:
  %hi0 = add i64 %lo, %chunk
  %lt = icmp slt i64 %hi0, %end
  %hi = select i1 %lt, i64 %hi0, i64 %end
  call void %task(ptr %clo, i64 %lo, i64 %hi, i32 %tid)
  %ran1 = add i64 %ran, 1
  br label %loop
done:
  ret i64 %ran
}}

define void @simgrad_parallel_for(ptr %task, ptr %clo, i64 %begin, i64 %end, i64 %grain) {{
entry:
  %n = sub i64 %end, %begin
  %nothing = icmp sle i64 %n, 0
  %cv = load atomic i32, ptr @simgrad_cancel monotonic, {a4}
  %cancelled = icmp ne i32 %cv, 0
  %empty = or i1 %nothing, %cancelled
  br i1 %empty, label %ret, label %check
check:
  %nt0 = load atomic i32, ptr @sg_nthreads monotonic, {a4}
  %single = icmp sle i32 %nt0, 1
  %small = icmp sle i64 %n, %grain
  %serial = or i1 %single, %small
  br i1 %serial, label %direct, label %lock
direct:                    ; on this thread, in chunks of at most CHUNK_CAP so Ctrl-C is seen
  {st("direct", "direct")}
  br label %dloop
dloop:
  %dlo = phi i64 [%begin, %direct], [%dhi, %dnext]
  %dhi0 = add i64 %dlo, {CHUNK_CAP}
  %dlt = icmp slt i64 %dhi0, %end
  %dhi = select i1 %dlt, i64 %dhi0, i64 %end
  call void %task(ptr %clo, i64 %dlo, i64 %dhi, i32 0)
  br i1 %dlt, label %dnext, label %ret
dnext:
  %dcv = load atomic i32, ptr @simgrad_cancel monotonic, {a4}
  %dstop = icmp ne i32 %dcv, 0
  br i1 %dstop, label %ret, label %dloop
lock:                      ; another launch in flight (other thread, or nested in a task): run inline
  %pair = cmpxchg ptr @sg_busy, i32 0, i32 1 acquire monotonic, {a4}
  %got = extractvalue {{ i32, i1 }} %pair, 1
  br i1 %got, label %locked, label %direct
locked:                    ; re-read under the lock: a shutdown may have happened meanwhile
  %nt = load atomic i32, ptr @sg_nthreads monotonic, {a4}
  %alone = icmp sle i32 %nt, 1
  br i1 %alone, label %unlock_direct, label %publish
unlock_direct:
  store atomic i32 0, ptr @sg_busy release, {a4}
  br label %direct
publish:
  {now("t0")}
  %nt64 = sext i32 %nt to i64
  %parts = mul i64 %nt64, 4
  %c0 = sdiv i64 %n, %parts
  %gpos = icmp sgt i64 %grain, 1
  %g1 = select i1 %gpos, i64 %grain, i64 1
  %cbig = icmp sgt i64 %c0, %g1
  %chunk0 = select i1 %cbig, i64 %c0, i64 %g1
  %ccap = icmp sgt i64 %chunk0, {CHUNK_CAP}
  %chunk = select i1 %ccap, i64 {CHUNK_CAP}, i64 %chunk0
  store atomic ptr %task, ptr @sg_task monotonic, {a8}
  store atomic ptr %clo, ptr @sg_closure monotonic, {a8}
  store atomic i64 %end, ptr @sg_end monotonic, {a8}
  store atomic i64 %chunk, ptr @sg_chunk monotonic, {a8}
  store atomic i64 %begin, ptr @sg_next monotonic, {a8}
  store atomic i32 0, ptr @sg_state release, {a4}       ; open, nobody joined
  atomicrmw add ptr @sg_gen, i32 1 seq_cst, {a4}
  %sl = load atomic i32, ptr @sg_sleepers seq_cst, {a4}
  %anysl = icmp ne i32 %sl, 0
  br i1 %anysl, label %wake, label %work
wake:
  call void @sg_futex(ptr @sg_gen, i64 {_FUTEX_WAKE}, i32 {_INT_MAX})
  {st("wakes", "wakes")}
  br label %work
work:
  %mine = call i64 @sg_run_chunks(i32 0)
  {st("mine", "chunks_caller", "%mine")}
  {_share_stats("%n", "%chunk", "%mine") if stats else ""}
  {now("tc")}
  %st = atomicrmw or ptr @sg_state, i32 {_CLOSED} seq_cst, {a4}   ; late wakers now skip this job
  %in0 = and i32 %st, {_JOINED}
  %none = icmp eq i32 %in0, 0
  br i1 %none, label %finish, label %spin
spin:
  {st("spun", "caller_spun")}
  %s1 = call i32 @sg_spin_until(ptr @sg_state, i32 {_JOINED}, i32 0, i1 true)
  %in1 = and i32 %s1, {_JOINED}
  %d1 = icmp eq i32 %in1, 0
  br i1 %d1, label %waited, label %sleep
sleep:
  {st("slept", "caller_slept")}
  store atomic i32 1, ptr @sg_caller_waiting seq_cst, {a4}
  br label %sleep_loop
sleep_loop:
  %s2 = load atomic i32, ptr @sg_state seq_cst, {a4}
  %in2 = and i32 %s2, {_JOINED}
  %d2 = icmp eq i32 %in2, 0
  br i1 %d2, label %woke, label %do_wait
do_wait:
  call void @sg_futex(ptr @sg_state, i64 {_FUTEX_WAIT}, i32 %s2)
  br label %sleep_loop
woke:
  store atomic i32 0, ptr @sg_caller_waiting monotonic, {a4}
  br label %waited
waited:
  {_wait_stats(st) if stats else ""}
  br label %finish
finish:
  {_launch_stats(st) if stats else ""}
  store atomic i32 0, ptr @sg_busy release, {a4}
  br label %ret
ret:
  ret void
}}

define void @simgrad_worker_loop(i32 %tid, i32 %seen0) {{
entry:
  br label %wait
wait:
  %seen = phi i32 [ %seen0, %entry ], [ %g, %next_job ]
  %g0 = call i32 @sg_spin_until(ptr @sg_gen, i32 -1, i32 %seen, i1 false)
  %new0 = icmp ne i32 %g0, %seen
  br i1 %new0, label %spin_hit, label %sleep
spin_hit:
  {st("hit", "worker_spin_hits")}
  br label %got
sleep:
  {st("wsleep", "worker_sleeps")}
  atomicrmw add ptr @sg_sleepers, i32 1 seq_cst, {a4}
  br label %sleep_loop
sleep_loop:
  %g1 = load atomic i32, ptr @sg_gen seq_cst, {a4}
  %new1 = icmp ne i32 %g1, %seen
  br i1 %new1, label %woke, label %do_wait
do_wait:
  call void @sg_futex(ptr @sg_gen, i64 {_FUTEX_WAIT}, i32 %seen)
  br label %sleep_loop
woke:
  atomicrmw sub ptr @sg_sleepers, i32 1 seq_cst, {a4}
  br label %got
got:
  %g = phi i32 [ %g0, %spin_hit ], [ %g1, %woke ]
  %sd = load atomic i32, ptr @sg_shutdown acquire, {a4}
  %stop = icmp ne i32 %sd, 0
  br i1 %stop, label %exit, label %try_join
try_join:                  ; join the current job unless the caller already closed it
  %st = load atomic i32, ptr @sg_state monotonic, {a4}
  br label %join_loop
join_loop:
  %s = phi i32 [ %st, %try_join ], [ %s_cur, %join_retry ]
  %closed = icmp uge i32 %s, {_CLOSED}
  br i1 %closed, label %late, label %join_cas
late:
  {st("late", "late")}
  br label %next_job
join_cas:
  %s1 = add i32 %s, 1
  %pair = cmpxchg ptr @sg_state, i32 %s, i32 %s1 acquire monotonic, {a4}
  %ok = extractvalue {{ i32, i1 }} %pair, 1
  br i1 %ok, label %job, label %join_retry
join_retry:
  %s_cur = extractvalue {{ i32, i1 }} %pair, 0
  br label %join_loop
job:
  {st("join", "joins")}
  %ran = call i64 @sg_run_chunks(i32 %tid)
  {st("wchunks", "chunks_workers", "%ran")}
  %old = atomicrmw sub ptr @sg_state, i32 1 seq_cst, {a4}
  %last = icmp eq i32 %old, {_CLOSED + 1}          ; closed, and we were the last one inside
  br i1 %last, label %check_caller, label %next_job
check_caller:
  %cw = load atomic i32, ptr @sg_caller_waiting seq_cst, {a4}
  %cwait = icmp ne i32 %cw, 0
  br i1 %cwait, label %wake_caller, label %next_job
wake_caller:
  call void @sg_futex(ptr @sg_state, i64 {_FUTEX_WAKE}, i32 1)
  br label %next_job
next_job:
  br label %wait
exit:
  ret void
}}

; Arms the pool for n threads and returns the generation the new workers start from.
define i32 @simgrad_pool_start(i32 %n) {{
  store atomic i32 0, ptr @sg_shutdown seq_cst, {a4}
  store atomic i32 %n, ptr @sg_nthreads seq_cst, {a4}
  %g = load atomic i32, ptr @sg_gen seq_cst, {a4}
  ret i32 %g
}}

define void @simgrad_pool_shutdown() {{
entry:
  br label %lock
lock:                      ; wait out a launch in flight so no worker leaves in the middle of a job
  %pair = cmpxchg ptr @sg_busy, i32 0, i32 1 acquire monotonic, {a4}
  %got = extractvalue {{ i32, i1 }} %pair, 1
  br i1 %got, label %locked, label %yield
yield:
  call i32 @sched_yield()
  br label %lock
locked:
  store atomic i32 1, ptr @sg_nthreads seq_cst, {a4}
  store atomic i32 1, ptr @sg_shutdown seq_cst, {a4}
  atomicrmw add ptr @sg_gen, i32 1 seq_cst, {a4}
  call void @sg_futex(ptr @sg_gen, i64 {_FUTEX_WAKE}, i32 {_INT_MAX})
  store atomic i32 0, ptr @sg_busy release, {a4}
  ret void
}}

; After fork() the workers are gone: forget them and run everything inline.
define void @simgrad_pool_reset() {{
  store atomic i32 1, ptr @sg_nthreads seq_cst, {a4}
  store atomic i32 {_CLOSED}, ptr @sg_state seq_cst, {a4}
  store atomic i32 0, ptr @sg_sleepers seq_cst, {a4}
  store atomic i32 0, ptr @sg_caller_waiting seq_cst, {a4}
  store atomic i32 0, ptr @sg_busy seq_cst, {a4}
  ret void
}}

; SIGINT: mark the running kernel cancelled, then chain to the handler that was installed (Python's,
; which makes the interpreter raise KeyboardInterrupt once the kernel has returned).
define internal void @sg_on_sigint(i32 %sig) {{
  store atomic i32 1, ptr @simgrad_cancel seq_cst, {a4}
  %prev = load ptr, ptr @sg_prev_sigint
  %pi = ptrtoint ptr %prev to i64
  %real = icmp ugt i64 %pi, 1               ; not SIG_DFL (0) or SIG_IGN (1)
  br i1 %real, label %chain, label %out
chain:
  call void %prev(i32 %sig)
  br label %out
out:
  ret void
}}

define void @simgrad_install_sigint() {{
  %old = call ptr @signal(i32 2, ptr @sg_on_sigint)
  %mine = icmp eq ptr %old, @sg_on_sigint
  br i1 %mine, label %out, label %keep
keep:
  store ptr %old, ptr @sg_prev_sigint
  br label %out
out:
  ret void
}}

define void @simgrad_pool_set_spin_ns(i64 %ns) {{
  store atomic i64 %ns, ptr @sg_spin_ns monotonic, {a8}
  ret void
}}
"""


def _slot(name: str, index: str) -> str:
    """`%name` = the address of counter `index` (an i64 value or constant)."""
    return f"%{name} = getelementptr [{N_STATS} x i64], ptr @simgrad_pool_stats, i64 0, i64 {index}"


def _share_stats(n: str, chunk: str, mine: str) -> str:
    """Count the caller's share of the job's chunks in quarters (slots share_q1..share_all)."""
    q = STAT_NAMES.index("share_q1")
    return "\n  ".join([
        f"%sh.c1 = sub i64 {chunk}, 1", f"%sh.n1 = add i64 {n}, %sh.c1", f"%sh.total = sdiv i64 %sh.n1, {chunk}",
        f"%sh.m4 = mul i64 {mine}, 4", "%sh.q = sdiv i64 %sh.m4, %sh.total",
        f"%sh.all = icmp sge i64 {mine}, %sh.total", "%sh.b = select i1 %sh.all, i64 4, i64 %sh.q",
        f"%sh.k = add i64 %sh.b, {q}", _slot("sh.p", "%sh.k"),
        "%sh.r = atomicrmw add ptr %sh.p, i64 1 monotonic, align 8"])


def _wait_stats(st) -> str:
    """The caller's wait for the workers still inside after its last chunk (from %tc on)."""
    return "\n  ".join(["%tw = call i64 @sg_now()", "%dw = sub i64 %tw, %tc",
                        st("wns", "caller_wait_ns", "%dw"), st("wmax", "caller_wait_max_ns", "%dw", "umax")])


def _launch_stats(st) -> str:
    """Count a published launch, its time (from %t0 on) and its log2 duration bucket."""
    b0 = STAT_NAMES.index("t_lt8us")
    return "\n  ".join([
        "%te = call i64 @sg_now()", "%dl = sub i64 %te, %t0", st("launch", "launches"),
        st("lns", "launch_ns", "%dl"), "%us = udiv i64 %dl, 1000", "%us1 = or i64 %us, 1",
        "%lz = call i64 @llvm.ctlz.i64(i64 %us1, i1 true)", "%lg = sub i64 63, %lz",  # floor(log2(us))
        "%lb0 = sub i64 %lg, 2", "%lneg = icmp slt i64 %lb0, 0", "%lb1 = select i1 %lneg, i64 0, i64 %lb0",
        "%lbig = icmp sgt i64 %lb1, 10", "%lb = select i1 %lbig, i64 10, i64 %lb1",
        f"%lk = add i64 %lb, {b0}", _slot("lp", "%lk"), "%lr = atomicrmw add ptr %lp, i64 1 monotonic, align 8"])


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
