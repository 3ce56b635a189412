; The allocator every kernel module that activates or frees sparse cells gets (codegen/sparse.py):
; @sg_sparse_alloc, @sg_sparse_free and their pool helpers. They call @sg_report (codegen/llvm.py) and
; @llvm.memset, declared by the kernel module. Parameters (substituted by runtime/ll/__init__.py `load`):
; CTX_SPARSE (runtime/abi.py), the pool table's row layout POOL_* and BATCH (runtime/sparse.py), and BATCHED
; (true on the CPU: a pool thread takes BATCH fresh blocks at a time into its slot of POOL_BATCHES; false on the
; GPU, whose threads are far more than the slots: each fresh block is one atomic add, and is zeroed when taken,
; as device pool memory is not zeroed in advance).

define internal ptr @sg_pool(ptr %ctx, i64 %pool) alwaysinline {
  %tp = getelementptr i64, ptr %ctx, i64 ${CTX_SPARSE}
  %table = load ptr, ptr %tp
  %off = mul i64 %pool, ${POOL_WORDS}
  %row = getelementptr i64, ptr %table, i64 %off
  ret ptr %row
}

define internal void @sg_pool_lock(ptr %row) {
entry:
  br label %try
try:
  %old = atomicrmw xchg ptr %row, i64 1 acquire
  %free = icmp eq i64 %old, 0
  br i1 %free, label %done, label %spin
spin:
  br label %try
done:
  ret void
}

define internal void @sg_pool_unlock(ptr %row) {
  store atomic i64 0, ptr %row release, align 8
  ret void
}

; the block behind *slot, allocating it (zeroed) when the slot is still null. Without freed blocks to reuse,
; a fresh block is bumped off the pool and installed by compare-and-swap, with no lock (the common case:
; many threads activating at once); a block that lost the race goes to the free list. Freed blocks are
; reused under the pool's lock. A pool that has run out reports error `code` and hands out the discard block.
define internal ptr @sg_sparse_alloc(ptr %ctx, i64 %pool, ptr %slot, i64 %code, i32 %tid) noinline {
entry:
  %row = call ptr @sg_pool(ptr %ctx, i64 %pool)
  %fp = getelementptr i64, ptr %row, i64 ${POOL_FREE}
  %free0 = load atomic ptr, ptr %fp monotonic, align 8
  %has_free0 = icmp ne ptr %free0, null
  %cp = getelementptr i64, ptr %row, i64 ${POOL_CAPACITY}
  %cap = load i64, ptr %cp
  br i1 %has_free0, label %locked, label %bump
bump:
  br i1 ${BATCHED}, label %batch, label %single
single:                    ; one shared atomic add per block
  %sp = getelementptr i64, ptr %row, i64 ${POOL_NEXT}
  %sr = atomicrmw add ptr %sp, i64 1 monotonic
  %sfull = icmp uge i64 %sr, %cap
  br i1 %sfull, label %exhausted, label %take_n
batch:                     ; this thread's batch of fresh blocks: one shared atomic add per BATCH blocks
  %tp = getelementptr i64, ptr %row, i64 ${POOL_BATCHES}
  %tbase = load ptr, ptr %tp
  %t64 = zext i32 %tid to i64
  %toff = mul i64 %t64, 8
  %mine = getelementptr i64, ptr %tbase, i64 %toff          ; [next, end] of this thread, a cache line apart
  %endp = getelementptr i64, ptr %mine, i64 1
  %bn = load i64, ptr %mine
  %be = load i64, ptr %endp
  %have_b = icmp ult i64 %bn, %be
  br i1 %have_b, label %from_batch, label %refill
from_batch:
  %bn1 = add i64 %bn, 1
  store i64 %bn1, ptr %mine
  br label %take_n
refill:
  %np = getelementptr i64, ptr %row, i64 ${POOL_NEXT}
  %r = atomicrmw add ptr %np, i64 ${BATCH} monotonic
  %full = icmp uge i64 %r, %cap
  br i1 %full, label %exhausted, label %refilled
refilled:
  %re0 = add i64 %r, ${BATCH}
  %over = icmp ugt i64 %re0, %cap
  %re = select i1 %over, i64 %cap, i64 %re0
  %r1 = add i64 %r, 1
  store i64 %r1, ptr %mine
  store i64 %re, ptr %endp
  br label %take_n
take_n:
  %n = phi i64 [ %bn, %from_batch ], [ %r, %refilled ], [ %sr, %single ]
  br label %fresh
fresh:
  %bp = getelementptr i64, ptr %row, i64 ${POOL_BASE}
  %base = load ptr, ptr %bp
  %szp = getelementptr i64, ptr %row, i64 ${POOL_BLOCK}
  %sz = load i64, ptr %szp
  %boff = mul i64 %n, %sz
  %blk = getelementptr i8, ptr %base, i64 %boff
  br i1 ${BATCHED}, label %install, label %zero
zero:                      ; device pool memory is not zeroed in advance (host mmap pages are)
  call void @llvm.memset.p0.i64(ptr %blk, i8 0, i64 %sz, i1 false)
  br label %install
install:
  store i64 0, ptr %blk  ; after a pool restart the first word may still hold a free-list link
  %cas = cmpxchg ptr %slot, ptr null, ptr %blk acq_rel monotonic
  %won = extractvalue { ptr, i1 } %cas, 1
  br i1 %won, label %done_fresh, label %lost
done_fresh:
  ret ptr %blk
lost:
  %other = extractvalue { ptr, i1 } %cas, 0
  call void @sg_pool_push(ptr %row, ptr %blk, i64 1)
  ret ptr %other
locked:
  call void @sg_pool_lock(ptr %row)
  %cur = load atomic ptr, ptr %slot acquire, align 8
  %have = icmp ne ptr %cur, null
  br i1 %have, label %unlock_cur, label %take
unlock_cur:
  call void @sg_pool_unlock(ptr %row)
  ret ptr %cur
take:
  %free = load ptr, ptr %fp
  %has_free = icmp ne ptr %free, null
  br i1 %has_free, label %reuse, label %unlock_bump
unlock_bump:
  call void @sg_pool_unlock(ptr %row)
  br label %bump
reuse:
  ; a lock-free bump elsewhere may install a block meanwhile: install by compare-and-swap here too. The
  ; block's first word (its free-list link) is cleared BEFORE the block is published: once installed, other
  ; threads add into its first cell at once, and a clear after the swap would wipe such an update
  %next = load ptr, ptr %free
  store i64 0, ptr %free
  %cas2 = cmpxchg ptr %slot, ptr null, ptr %free acq_rel monotonic
  %won2 = extractvalue { ptr, i1 } %cas2, 1
  br i1 %won2, label %popped, label %kept
popped:
  store ptr %next, ptr %fp
  %cnp2 = getelementptr i64, ptr %row, i64 ${POOL_FREECOUNT}
  %d1 = load i64, ptr %cnp2
  %d2 = sub i64 %d1, 1
  store i64 %d2, ptr %cnp2
  call void @sg_pool_unlock(ptr %row)
  ret ptr %free
kept:                      ; still on the list (the lock is held): its link back
  store ptr %next, ptr %free
  %other2 = extractvalue { ptr, i1 } %cas2, 0
  call void @sg_pool_unlock(ptr %row)
  ret ptr %other2
exhausted:
  call void @sg_report(ptr %ctx, i64 %code, i64 %cap)
  %dp = getelementptr i64, ptr %row, i64 ${POOL_DISCARD}
  %discard = load ptr, ptr %dp
  ret ptr %discard
}

; put a zeroed block on its pool's free list (%lost: 1 for a block that lost the race to install, counted)
define internal void @sg_pool_push(ptr %row, ptr %blk, i64 %lost) {
  call void @sg_pool_lock(ptr %row)
  %fp = getelementptr i64, ptr %row, i64 ${POOL_FREE}
  %free = load ptr, ptr %fp
  store ptr %free, ptr %blk
  store atomic ptr %blk, ptr %fp release, align 8
  %cnp = getelementptr i64, ptr %row, i64 ${POOL_FREECOUNT}
  %c1 = load i64, ptr %cnp
  %c2 = add i64 %c1, 1
  store i64 %c2, ptr %cnp
  %lsp = getelementptr i64, ptr %row, i64 ${POOL_LOST}
  %l1 = load i64, ptr %lsp
  %l2 = add i64 %l1, %lost
  store i64 %l2, ptr %lsp
  call void @sg_pool_unlock(ptr %row)
  ret void
}

; zero a block and give it back to its pool
define internal void @sg_sparse_free(ptr %ctx, i64 %pool, ptr %blk) noinline {
  %row = call ptr @sg_pool(ptr %ctx, i64 %pool)
  %szp = getelementptr i64, ptr %row, i64 ${POOL_BLOCK}
  %sz = load i64, ptr %szp
  call void @llvm.memset.p0.i64(ptr %blk, i8 0, i64 %sz, i1 false)
  call void @sg_pool_push(ptr %row, ptr %blk, i64 0)
  ret void
}

; --- dynamic lists: a chain of chunks ---
; A dynamic node's header (in its parent's cell) is {i32 length, i32 lock, ptr first chunk}; a chunk is a block
; of the node's pool: {ptr next chunk, then chunk_size cells}, as Taichi's. Chunks are allocated as writes reach
; them and stay until the list is deactivated.

; the chunk *slot points to; a write finding it null allocates it under the list's lock (one chunk per slot,
; however many threads reach it at once). Threads waiting for the lock poll the slot, and go on as soon as the
; chunk is there, without taking the lock in turn. Null: a read of a chunk not allocated, or a pool that ran out
; (reported by @sg_sparse_alloc).
define internal ptr @sg_dyn_link(ptr %ctx, i64 %pool, ptr %hdr, ptr %slot, i1 %write, i64 %code, i32 %tid) {
entry:
  %v = load atomic ptr, ptr %slot acquire, align 8
  %have = icmp ne ptr %v, null
  br i1 %have, label %done, label %absent
absent:
  %lp = getelementptr i8, ptr %hdr, i64 4
  br i1 %write, label %try, label %done
try:
  %v1 = load atomic ptr, ptr %slot acquire, align 8
  %have1 = icmp ne ptr %v1, null
  br i1 %have1, label %done, label %free
free:
  %held = load atomic i32, ptr %lp monotonic, align 4
  %busy = icmp ne i32 %held, 0
  br i1 %busy, label %try, label %grab
grab:
  %old = atomicrmw xchg ptr %lp, i32 1 acquire
  %got = icmp eq i32 %old, 0
  br i1 %got, label %locked, label %try
locked:
  %v2 = load atomic ptr, ptr %slot acquire, align 8
  %have2 = icmp ne ptr %v2, null
  br i1 %have2, label %unlock, label %alloc
alloc:
  %blk = call ptr @sg_sparse_alloc(ptr %ctx, i64 %pool, ptr %slot, i64 %code, i32 %tid)
  br label %unlock
unlock:
  store atomic i32 0, ptr %lp release, align 4
  %v3 = load atomic ptr, ptr %slot acquire, align 8
  br label %done
done:
  %r = phi ptr [ %v, %entry ], [ null, %absent ], [ %v1, %try ], [ %v3, %unlock ]
  ret ptr %r
}

; the chunk number %k of the list at %hdr: the zero block for a read where it is not allocated, the discard block
; for a write whose pool ran out. %cur is the calling function's cursor {hdr, first chunk, k, chunk} for this
; pool: a walk starts from the chunk found last when it is of the same list (same header and first chunk, so a
; list emptied and refilled meanwhile is walked afresh) and not past %k; a loop running along a list then follows
; one link per chunk, not k per element. %f0 is the list's first chunk as the caller loaded it (acquire for a
; write; a plain load for a read, which LLVM may then hoist out of a loop reading the list).
define internal ptr @sg_dyn_chunk(ptr %ctx, i64 %pool, ptr %hdr, ptr %f0, i64 %k, i1 %write, i64 %code, i32 %tid,
                                  ptr %cur) alwaysinline {
entry:
  %first = getelementptr i8, ptr %hdr, i64 8
  %ch = load ptr, ptr %cur
  %cfp = getelementptr i64, ptr %cur, i64 1
  %cf = load ptr, ptr %cfp
  %ckp = getelementptr i64, ptr %cur, i64 2
  %ck = load i64, ptr %ckp
  %cpp = getelementptr i64, ptr %cur, i64 3
  %cp = load ptr, ptr %cpp
  %same_h = icmp eq ptr %ch, %hdr
  %same_f = icmp eq ptr %cf, %f0
  %behind = icmp ule i64 %ck, %k
  %u1 = and i1 %same_h, %same_f
  %use = and i1 %u1, %behind
  br i1 %use, label %walk, label %head
head:
  %p0 = call ptr @sg_dyn_link(ptr %ctx, i64 %pool, ptr %hdr, ptr %first, i1 %write, i64 %code, i32 %tid)
  %null0 = icmp eq ptr %p0, null
  br i1 %null0, label %absent, label %walk
walk:
  %fc = phi ptr [ %f0, %entry ], [ %p0, %head ], [ %fc, %step ]
  %j = phi i64 [ %ck, %entry ], [ 0, %head ], [ %j1, %step ]
  %p = phi ptr [ %cp, %entry ], [ %p0, %head ], [ %q, %step ]
  %more = icmp ult i64 %j, %k
  br i1 %more, label %hop, label %found
hop:
  %q = call ptr @sg_dyn_link(ptr %ctx, i64 %pool, ptr %hdr, ptr %p, i1 %write, i64 %code, i32 %tid)
  %nq = icmp eq ptr %q, null
  br i1 %nq, label %absent, label %step
step:
  %j1 = add i64 %j, 1
  br label %walk
found:
  store ptr %hdr, ptr %cur
  store ptr %fc, ptr %cfp
  store i64 %k, ptr %ckp
  store ptr %p, ptr %cpp
  ret ptr %p
absent:
  %row = call ptr @sg_pool(ptr %ctx, i64 %pool)
  %word = select i1 %write, i64 ${POOL_DISCARD}, i64 ${POOL_ZERO}
  %sp = getelementptr i64, ptr %row, i64 %word
  %side = load ptr, ptr %sp
  ret ptr %side
}

; empty the list at %hdr: its length to 0, its chunks zeroed and back to the pool
define internal void @sg_dyn_clear(ptr %ctx, i64 %pool, ptr %hdr) noinline {
entry:
  %first = getelementptr i8, ptr %hdr, i64 8
  %c0 = atomicrmw xchg ptr %first, ptr null acq_rel
  store atomic i32 0, ptr %hdr monotonic, align 4
  br label %loop
loop:
  %c = phi ptr [ %c0, %entry ], [ %next, %free ]
  %more = icmp ne ptr %c, null
  br i1 %more, label %free, label %done
free:
  %next = load ptr, ptr %c
  call void @sg_sparse_free(ptr %ctx, i64 %pool, ptr %c)
  br label %loop
done:
  ret void
}
