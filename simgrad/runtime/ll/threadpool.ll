; simgrad's native thread pool (runtime/threadpool.py; that module's docstring says how it works).
; Parameters (substituted by runtime/ll/__init__.py `load`): futex_nr and the futex operations _FUTEX_WAIT /
; _FUTEX_WAKE, the machine's spin hint (pause, pause_decl: empty where there is none), the float mode's
; places (fp_decl, fp_publish, fp_adopt: runtime/fpenv.py pool_params), the job state word's
; bits (_CLOSED, _JOINED; _CLOSED_LAST = _CLOSED + 1), _INT_MAX, CHUNK_CAP, DEFAULT_SPIN_NS, and a4 / a8
; (the atomics' alignments); N_STATS and the st_... places, empty unless SIMGRAD_POOL_STATS=1 (then
; threadpool.py `_stat_code` fills them with counter updates of @simgrad_pool_stats).

@simgrad_cancel = global i32 0, align 64   ; set by SIGINT: tasks stop taking chunks, while loops exit
@sg_prev_sigint = internal global ptr null
@sg_task = internal global ptr null, align 64
@sg_closure = internal global ptr null
@sg_end = internal global i64 0
@sg_chunk = internal global i64 1
@sg_spin_ns = internal global i64 ${DEFAULT_SPIN_NS}
@sg_nthreads = internal global i32 1
@sg_shutdown = internal global i32 0
@sg_busy = internal global i32 0
@sg_next = internal global i64 0, align 64
@sg_gen = internal global i32 0, align 64
@sg_sleepers = internal global i32 0
@sg_state = internal global i32 ${_CLOSED}, align 64
@sg_caller_waiting = internal global i32 0
@sg_job_mxcsr = internal global i32 8064, align 4   ; the launching thread's float mode (runtime/fpenv.py)
@simgrad_pool_stats = global [${N_STATS} x i64] zeroinitializer, align 64   ; SIMGRAD_POOL_STATS counters

declare i64 @syscall(i64, ...)
declare i32 @clock_gettime(i32, ptr)
declare i32 @sched_yield()
declare ptr @signal(i32, ptr)
declare i64 @llvm.ctlz.i64(i64, i1)
${pause_decl}
${fp_decl}

define internal i64 @sg_now() {
  %ts = alloca { i64, i64 }, align 8
  call i32 @clock_gettime(i32 1, ptr %ts)
  %s = load i64, ptr %ts, align 8
  %nsp = getelementptr { i64, i64 }, ptr %ts, i32 0, i32 1
  %ns = load i64, ptr %nsp, align 8
  %s9 = mul i64 %s, 1000000000
  %t = add i64 %s9, %ns
  ret i64 %t
}

define internal void @sg_futex(ptr %addr, i64 %op, i32 %val) {
  %v = sext i32 %val to i64
  call i64 (i64, ...) @syscall(i64 ${futex_nr}, ptr %addr, i64 %op, i64 %v, ptr null)
  ret void
}

; Spin until ((*addr & mask) == val) == eq (acquire) or the spin budget runs out; returns the last value.
define internal i32 @sg_spin_until(ptr %addr, i32 %mask, i32 %val, i1 %eq) {
entry:
  %budget = load atomic i64, ptr @sg_spin_ns monotonic, ${a8}
  %t0 = call i64 @sg_now()
  %deadline = add i64 %t0, %budget
  br label %loop
loop:
  %cur = load atomic i32, ptr %addr acquire, ${a4}
  %m = and i32 %cur, %mask
  %is = icmp eq i32 %m, %val
  %done = icmp eq i1 %is, %eq
  br i1 %done, label %out, label %more
more:
  ${pause}
  ${pause}
  ${pause}
  ${pause}
  %now = call i64 @sg_now()
  %late = icmp sgt i64 %now, %deadline
  br i1 %late, label %out, label %loop
out:
  ret i32 %cur
}

; Runs chunks of the current job until none is left; returns how many it ran.
define internal i64 @sg_run_chunks(i32 %tid) {
entry:
  %task = load atomic ptr, ptr @sg_task monotonic, ${a8}
  %clo = load atomic ptr, ptr @sg_closure monotonic, ${a8}
  %end = load atomic i64, ptr @sg_end monotonic, ${a8}
  %chunk = load atomic i64, ptr @sg_chunk monotonic, ${a8}
  br label %loop
loop:
  %ran = phi i64 [0, %entry], [%ran1, %body]
  %stop = load atomic i32, ptr @simgrad_cancel monotonic, ${a4}
  %stopped = icmp ne i32 %stop, 0
  br i1 %stopped, label %done, label %take
take:
  %lo = atomicrmw add ptr @sg_next, i64 %chunk monotonic, ${a8}
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
}

define void @simgrad_parallel_for(ptr %task, ptr %clo, i64 %begin, i64 %end, i64 %grain) {
entry:
  %n = sub i64 %end, %begin
  %nothing = icmp sle i64 %n, 0
  %cv = load atomic i32, ptr @simgrad_cancel monotonic, ${a4}
  %cancelled = icmp ne i32 %cv, 0
  %empty = or i1 %nothing, %cancelled
  br i1 %empty, label %ret, label %check
check:
  %nt0 = load atomic i32, ptr @sg_nthreads monotonic, ${a4}
  %single = icmp sle i32 %nt0, 1
  %small = icmp sle i64 %n, %grain
  %serial = or i1 %single, %small
  br i1 %serial, label %direct, label %lock
direct:                    ; on this thread, in chunks of at most CHUNK_CAP so Ctrl-C is seen
  ${st_direct}
  br label %dloop
dloop:
  %dlo = phi i64 [%begin, %direct], [%dhi, %dnext]
  %dhi0 = add i64 %dlo, ${CHUNK_CAP}
  %dlt = icmp slt i64 %dhi0, %end
  %dhi = select i1 %dlt, i64 %dhi0, i64 %end
  call void %task(ptr %clo, i64 %dlo, i64 %dhi, i32 0)
  br i1 %dlt, label %dnext, label %ret
dnext:
  %dcv = load atomic i32, ptr @simgrad_cancel monotonic, ${a4}
  %dstop = icmp ne i32 %dcv, 0
  br i1 %dstop, label %ret, label %dloop
lock:                      ; another launch in flight (other thread, or nested in a task): run inline
  %pair = cmpxchg ptr @sg_busy, i32 0, i32 1 acquire monotonic, ${a4}
  %got = extractvalue { i32, i1 } %pair, 1
  br i1 %got, label %locked, label %direct
locked:                    ; re-read under the lock: a shutdown may have happened meanwhile
  %nt = load atomic i32, ptr @sg_nthreads monotonic, ${a4}
  %alone = icmp sle i32 %nt, 1
  br i1 %alone, label %unlock_direct, label %publish
unlock_direct:
  store atomic i32 0, ptr @sg_busy release, ${a4}
  br label %direct
publish:
  ${st_t0}
  %nt64 = sext i32 %nt to i64
  %parts = mul i64 %nt64, 4
  %c0 = sdiv i64 %n, %parts
  %gpos = icmp sgt i64 %grain, 1
  %g1 = select i1 %gpos, i64 %grain, i64 1
  %cbig = icmp sgt i64 %c0, %g1
  %chunk0 = select i1 %cbig, i64 %c0, i64 %g1
  %ccap = icmp sgt i64 %chunk0, ${CHUNK_CAP}
  %chunk = select i1 %ccap, i64 ${CHUNK_CAP}, i64 %chunk0
  ${fp_publish}
  store atomic ptr %task, ptr @sg_task monotonic, ${a8}
  store atomic ptr %clo, ptr @sg_closure monotonic, ${a8}
  store atomic i64 %end, ptr @sg_end monotonic, ${a8}
  store atomic i64 %chunk, ptr @sg_chunk monotonic, ${a8}
  store atomic i64 %begin, ptr @sg_next monotonic, ${a8}
  store atomic i32 0, ptr @sg_state release, ${a4}       ; open, nobody joined
  atomicrmw add ptr @sg_gen, i32 1 seq_cst, ${a4}
  ; claim the sleepers: each wake is for those counted now; a worker woken but not yet running is not counted
  ; again, so the next launch does not wake it a second time (a futile syscall per launch under load)
  %sl = atomicrmw xchg ptr @sg_sleepers, i32 0 seq_cst, ${a4}
  %anysl = icmp ne i32 %sl, 0
  br i1 %anysl, label %wake, label %work
wake:
  call void @sg_futex(ptr @sg_gen, i64 ${_FUTEX_WAKE}, i32 ${_INT_MAX})
  ${st_wakes}
  br label %work
work:
  %mine = call i64 @sg_run_chunks(i32 0)
  ${st_mine}
  %st = atomicrmw or ptr @sg_state, i32 ${_CLOSED} seq_cst, ${a4}   ; late wakers now skip this job
  %in0 = and i32 %st, ${_JOINED}
  %none = icmp eq i32 %in0, 0
  br i1 %none, label %finish, label %spin
spin:
  ${st_spun}
  %s1 = call i32 @sg_spin_until(ptr @sg_state, i32 ${_JOINED}, i32 0, i1 true)
  %in1 = and i32 %s1, ${_JOINED}
  %d1 = icmp eq i32 %in1, 0
  br i1 %d1, label %waited, label %sleep
sleep:
  ${st_slept}
  store atomic i32 1, ptr @sg_caller_waiting seq_cst, ${a4}
  br label %sleep_loop
sleep_loop:
  %s2 = load atomic i32, ptr @sg_state seq_cst, ${a4}
  %in2 = and i32 %s2, ${_JOINED}
  %d2 = icmp eq i32 %in2, 0
  br i1 %d2, label %woke, label %do_wait
do_wait:
  call void @sg_futex(ptr @sg_state, i64 ${_FUTEX_WAIT}, i32 %s2)
  br label %sleep_loop
woke:
  store atomic i32 0, ptr @sg_caller_waiting monotonic, ${a4}
  br label %waited
waited:                    ; the caller waited for workers still inside after its last chunk
  ${st_waited}
  br label %finish
finish:
  ${st_launch}
  store atomic i32 0, ptr @sg_busy release, ${a4}
  br label %ret
ret:
  ret void
}

define void @simgrad_worker_loop(i32 %tid, i32 %seen0) {
entry:
  br label %wait
wait:
  %seen = phi i32 [ %seen0, %entry ], [ %g, %next_job ]
  %g0 = call i32 @sg_spin_until(ptr @sg_gen, i32 -1, i32 %seen, i1 false)
  %new0 = icmp ne i32 %g0, %seen
  br i1 %new0, label %spin_hit, label %sleep
spin_hit:
  ${st_hit}
  br label %got
sleep:
  ${st_wsleep}
  atomicrmw add ptr @sg_sleepers, i32 1 seq_cst, ${a4}
  br label %sleep_loop
sleep_loop:
  %g1 = load atomic i32, ptr @sg_gen seq_cst, ${a4}
  %new1 = icmp ne i32 %g1, %seen
  br i1 %new1, label %woke, label %do_wait
do_wait:
  call void @sg_futex(ptr @sg_gen, i64 ${_FUTEX_WAIT}, i32 %seen)
  br label %sleep_loop
woke:                      ; the launch that woke us took our count (a stale count after a wake without a
  br label %got            ; sleep only costs the next launch one futile wake)
got:
  %g = phi i32 [ %g0, %spin_hit ], [ %g1, %woke ]
  %sd = load atomic i32, ptr @sg_shutdown acquire, ${a4}
  %stop = icmp ne i32 %sd, 0
  br i1 %stop, label %exit, label %try_join
try_join:                  ; join the current job unless the caller already closed it
  %st = load atomic i32, ptr @sg_state monotonic, ${a4}
  br label %join_loop
join_loop:
  %s = phi i32 [ %st, %try_join ], [ %s_cur, %join_retry ]
  %closed = icmp uge i32 %s, ${_CLOSED}
  br i1 %closed, label %late, label %join_cas
late:                      ; the caller had closed the job already
  ${st_late}
  br label %next_job
join_cas:
  %s1 = add i32 %s, 1
  %pair = cmpxchg ptr @sg_state, i32 %s, i32 %s1 acquire monotonic, ${a4}
  %ok = extractvalue { i32, i1 } %pair, 1
  br i1 %ok, label %job, label %join_retry
join_retry:
  %s_cur = extractvalue { i32, i1 } %pair, 0
  br label %join_loop
job:
  ${st_join}
  ${fp_adopt}
  %ran = call i64 @sg_run_chunks(i32 %tid)
  ${st_wchunks}
  %old = atomicrmw sub ptr @sg_state, i32 1 seq_cst, ${a4}
  %last = icmp eq i32 %old, ${_CLOSED_LAST}       ; closed, and we were the last one inside
  br i1 %last, label %check_caller, label %next_job
check_caller:
  %cw = load atomic i32, ptr @sg_caller_waiting seq_cst, ${a4}
  %cwait = icmp ne i32 %cw, 0
  br i1 %cwait, label %wake_caller, label %next_job
wake_caller:
  call void @sg_futex(ptr @sg_state, i64 ${_FUTEX_WAKE}, i32 1)
  br label %next_job
next_job:
  br label %wait
exit:
  ret void
}

; Arms the pool for n threads and returns the generation the new workers start from.
define i32 @simgrad_pool_start(i32 %n) {
  store atomic i32 0, ptr @sg_shutdown seq_cst, ${a4}
  store atomic i32 %n, ptr @sg_nthreads seq_cst, ${a4}
  %g = load atomic i32, ptr @sg_gen seq_cst, ${a4}
  ret i32 %g
}

define void @simgrad_pool_shutdown() {
entry:
  br label %lock
lock:                      ; wait out a launch in flight so no worker leaves in the middle of a job
  %pair = cmpxchg ptr @sg_busy, i32 0, i32 1 acquire monotonic, ${a4}
  %got = extractvalue { i32, i1 } %pair, 1
  br i1 %got, label %locked, label %yield
yield:
  call i32 @sched_yield()
  br label %lock
locked:
  store atomic i32 1, ptr @sg_nthreads seq_cst, ${a4}
  store atomic i32 1, ptr @sg_shutdown seq_cst, ${a4}
  atomicrmw add ptr @sg_gen, i32 1 seq_cst, ${a4}
  call void @sg_futex(ptr @sg_gen, i64 ${_FUTEX_WAKE}, i32 ${_INT_MAX})
  store atomic i32 0, ptr @sg_busy release, ${a4}
  ret void
}

; After fork() the workers are gone: forget them and run everything inline.
define void @simgrad_pool_reset() {
  store atomic i32 1, ptr @sg_nthreads seq_cst, ${a4}
  store atomic i32 ${_CLOSED}, ptr @sg_state seq_cst, ${a4}
  store atomic i32 0, ptr @sg_sleepers seq_cst, ${a4}
  store atomic i32 0, ptr @sg_caller_waiting seq_cst, ${a4}
  store atomic i32 0, ptr @sg_busy seq_cst, ${a4}
  ret void
}

; SIGINT: mark the running kernel cancelled, then chain to the handler that was installed (Python's,
; which makes the interpreter raise KeyboardInterrupt once the kernel has returned).
define internal void @sg_on_sigint(i32 %sig) {
  store atomic i32 1, ptr @simgrad_cancel seq_cst, ${a4}
  %prev = load ptr, ptr @sg_prev_sigint
  %pi = ptrtoint ptr %prev to i64
  %real = icmp ugt i64 %pi, 1               ; not SIG_DFL (0) or SIG_IGN (1)
  br i1 %real, label %chain, label %out
chain:
  call void %prev(i32 %sig)
  br label %out
out:
  ret void
}

define void @simgrad_install_sigint() {
  %old = call ptr @signal(i32 2, ptr @sg_on_sigint)
  %mine = icmp eq ptr %old, @sg_on_sigint
  br i1 %mine, label %out, label %keep
keep:
  store ptr %old, ptr @sg_prev_sigint
  br label %out
out:
  ret void
}

define void @simgrad_pool_set_spin_ns(i64 %ns) {
  store atomic i64 %ns, ptr @sg_spin_ns monotonic, ${a8}
  ret void
}
