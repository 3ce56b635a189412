"""Native thread pool: every index exactly once, tids in range, no deadlock, restartable."""

import ctypes
import threading

import numpy as np
import pytest

from simgrad.runtime import threadpool
from simgrad.runtime.jit import get_jit
from simgrad.runtime.threadpool import ThreadPool, get_pool

# task(closure, lo, hi, tid): closure = {i64* out, i32* tids, i64* calls};
# out[i] += 1 (non-atomic), tids[i] = tid, *calls += 1 (atomic)
TASKS_IR = """
define void @count_task(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
entry:
  %out = load ptr, ptr %clo, align 8
  %tp = getelementptr ptr, ptr %clo, i64 1
  %tids = load ptr, ptr %tp, align 8
  %cp = getelementptr ptr, ptr %clo, i64 2
  %calls = load ptr, ptr %cp, align 8
  atomicrmw add ptr %calls, i64 1 seq_cst, align 8
  %e = icmp slt i64 %lo, %hi
  br i1 %e, label %loop, label %done
loop:
  %i = phi i64 [ %lo, %entry ], [ %i1, %loop ]
  %p = getelementptr i64, ptr %out, i64 %i
  %v = load i64, ptr %p, align 8
  %v1 = add i64 %v, 1
  store i64 %v1, ptr %p, align 8
  %q = getelementptr i32, ptr %tids, i64 %i
  store i32 %tid, ptr %q, align 4
  %i1 = add i64 %i, 1
  %c = icmp slt i64 %i1, %hi
  br i1 %c, label %loop, label %done
done:
  ret void
}

define void @nop_task(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {
  ret void
}
"""

GRAIN = 64


@pytest.fixture(scope="module")
def tasks():
    addrs = get_jit().load(TASKS_IR, ["count_task", "nop_task"])
    yield addrs
    pool = threadpool._active
    if pool is not None:
        pool.shutdown()


class Counter:
    """Arrays plus the closure struct that points at them."""

    def __init__(self, n):
        self.out = np.zeros(n, dtype=np.int64)
        self.tids = np.full(n, -1, dtype=np.int32)
        self.calls = np.zeros(1, dtype=np.int64)
        ptrs = (self.out.ctypes.data, self.tids.ctypes.data, self.calls.ctypes.data)
        self.closure = (ctypes.c_void_p * 3)(*ptrs)
        self.addr = ctypes.addressof(self.closure)


def run(pool, tasks, c, begin, end, grain=GRAIN):
    pool.parallel_for(tasks["count_task"], c.addr, begin, end, grain)


@pytest.mark.parametrize("nthreads", [1, 2, 4])
@pytest.mark.parametrize(
    "begin,end",
    [(0, 0), (5, 3), (0, 1), (0, GRAIN), (0, GRAIN + 1), (0, 10**6), (7, 12345), (3, 3 + 4 * GRAIN + 1)],
)
def test_each_index_once(tasks, nthreads, begin, end):
    pool = get_pool(nthreads)
    assert pool.num_threads == nthreads
    c = Counter(max(end, begin) + 5)
    run(pool, tasks, c, begin, end)
    expected = np.zeros_like(c.out)
    expected[begin:end] = 1
    np.testing.assert_array_equal(c.out, expected)
    touched = c.tids[begin:end]
    assert ((touched >= 0) & (touched < nthreads)).all()
    assert (c.tids[:begin] == -1).all() and (c.tids[max(end, begin) :] == -1).all()
    n = max(end - begin, 0)
    assert (n == 0) == (c.calls[0] == 0)
    assert c.calls[0] <= -(-n // GRAIN)  # grain is the smallest chunk
    if n <= GRAIN:
        assert (touched == 0).all() and c.calls[0] <= 1  # small loops stay on the calling thread


@pytest.mark.parametrize("spin_ns", [threadpool.DEFAULT_SPIN_NS, 0])
def test_workers_take_part(tasks, spin_ns):
    """With spin 0 the worker is asleep at every launch, so this also checks that launches wake it."""
    pool = get_pool(2)
    pool.set_spin_ns(spin_ns)
    try:
        c = Counter(10**6)
        seen = set()  # over several launches: the OS may leave one thread off-CPU for a whole launch
        for k in range(1, 51):
            run(pool, tasks, c, 0, 10**6)
            assert (c.out == k).all()
            seen |= {int(t) for t in np.unique(c.tids)}
            if len(seen) > 1:
                break
        assert seen == {0, 1}  # the caller (tid 0) works too
    finally:
        pool.set_spin_ns(threadpool.DEFAULT_SPIN_NS)


@pytest.mark.parametrize("spin_ns", [threadpool.DEFAULT_SPIN_NS, 0])
@pytest.mark.parametrize("nthreads", [2, 4])
def test_back_to_back(tasks, nthreads, spin_ns):
    pool = get_pool(nthreads)
    pool.set_spin_ns(spin_ns)  # 0: every wait goes through the futex sleep path
    try:
        c = Counter(1000)
        launches = 3000
        for k in range(launches):
            run(pool, tasks, c, 0, 1000 - (k % 7), grain=8)
        expected = np.full(1000, launches, dtype=np.int64)
        for k in range(7):
            expected[1000 - k :] -= len(range(k, launches, 7))
        np.testing.assert_array_equal(c.out, expected)

        # big ranges: workers join, and the caller must wait for them before returning
        big = Counter(200_000)
        for k in range(1, 41):
            run(pool, tasks, big, 0, 200_000, grain=1000)
            assert big.out[0] == k and big.out[-1] == k and (big.out == k).all()
    finally:
        pool.set_spin_ns(threadpool.DEFAULT_SPIN_NS)


def test_concurrent_callers(tasks):
    """Launches from several Python threads at once: one uses the pool, the others run inline."""
    pool = get_pool(2)
    counters = [Counter(5000) for _ in range(3)]

    def hammer(c):
        for _ in range(300):
            run(pool, tasks, c, 0, 5000, grain=16)

    threads = [threading.Thread(target=hammer, args=(c,)) for c in counters]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for c in counters:
        assert (c.out == 300).all()


def test_shutdown_and_recreate(tasks):
    p2 = get_pool(2)
    assert get_pool() is p2 and get_pool(2) is p2
    p3 = get_pool(3)
    assert p2.closed and not p3.closed and p3.num_threads == 3
    assert get_pool() is p3
    c = Counter(10**5)
    run(p3, tasks, c, 0, 10**5)
    assert (c.out == 1).all() and c.tids.max() < 3

    p3.shutdown()
    p3.shutdown()  # idempotent
    assert threadpool._active is None
    c = Counter(10**5)
    threadpool.parallel_for(tasks["count_task"], c.addr, 0, 10**5, GRAIN)  # no pool: runs inline
    assert (c.out == 1).all() and (c.tids == 0).all()

    p = ThreadPool(2)
    assert p.parallel_for_address == p2.parallel_for_address
    c = Counter(10**5)
    threadpool.parallel_for(tasks["count_task"], c.addr, 0, 10**5, GRAIN)
    assert (c.out == 1).all() and c.tids.max() <= 1


def test_bad_thread_count():
    with pytest.raises(ValueError):
        ThreadPool(0)
