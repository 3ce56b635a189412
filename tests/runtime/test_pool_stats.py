"""The pool's counters (SIMGRAD_POOL_STATS=1, runtime/threadpool.py STAT_NAMES): consistent counts in a
child process that sets the variable, and none of the counting code in the pool's IR without it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from simgrad.runtime.threadpool import pool_ir, pool_stats

SCRIPT = textwrap.dedent("""
    import json
    import simgrad as ti
    from simgrad.runtime.threadpool import pool_stats, reset_pool_stats

    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    x = ti.field(ti.f32, 1 << 16)

    @ti.kernel
    def k():
        for i in x:
            x[i] += 1.0

    @ti.kernel
    def small():
        for i in range(3):
            x[i] += 1.0

    k()
    reset_pool_stats()
    for _ in range(50):
        k()
        small()
    print(json.dumps(pool_stats()))
""")


def _stats_of(script_text: str, tmp_path) -> dict:
    """The pool's counters printed by `script_text`, run in a child with SIMGRAD_POOL_STATS=1."""
    script = tmp_path / "stats.py"
    script.write_text(script_text)
    env = dict(os.environ, SIMGRAD_POOL_STATS="1", SIMGRAD_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_counters_add_up(tmp_path):
    st = _stats_of(SCRIPT, tmp_path)
    assert st["launches"] == 50 and st["direct"] == 50  # the 3-iteration loop runs on the caller
    # 2 threads: 8 chunks of 8192 per launch, each run once, by the caller or a worker
    assert st["chunks_caller"] + st["chunks_workers"] == 50 * 8
    shares = sum(st[k] for k in ("share_q1", "share_q2", "share_q3", "share_q4", "share_all"))
    assert shares == 50
    assert sum(v for k, v in st.items() if k.startswith("t_")) == 50
    assert st["caller_slept"] <= st["caller_spun"] and st["caller_wait_max_ns"] <= st["caller_wait_ns"]
    assert st["launch_ns"] > 0


def test_no_counting_code_without_the_variable():
    off, on = pool_ir(202, "x86_64", False), pool_ir(202, "x86_64", True)
    assert "%st." not in off and "@sg_now()" in off  # sg_now only where the spin needs it
    assert off.count("call i64 @sg_now()") < on.count("call i64 @sg_now()")
    if os.environ.get("SIMGRAD_POOL_STATS", "0") in ("", "0"):
        assert set(pool_stats().values()) == {0}


ONE_CPU = textwrap.dedent("""
    import json, os
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # the pool's worker cannot run while we do
    import simgrad as ti
    from simgrad.runtime.threadpool import pool_stats, reset_pool_stats

    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    x = ti.field(ti.f32, 1 << 16)

    @ti.kernel
    def k():
        for i in x:
            x[i] += 1.0

    k()
    reset_pool_stats()
    for _ in range(200):
        k()
    print(json.dumps(pool_stats()))
""")


def test_a_woken_worker_is_not_woken_again_before_it_runs(tmp_path):
    """Every futex wake is for a worker that went to sleep: one woken but not yet scheduled (here it shares the
    caller's only CPU) is not counted asleep by the next launch. Before, each of the 200 launches woke it again
    (under load: ~5,000 futile wake syscalls in a diffmpm run; benchmarks/pool_stalls.py)."""
    st = _stats_of(ONE_CPU, tmp_path)
    assert st["launches"] == 200
    assert st["wakes"] <= st["worker_sleeps"] + 1, st
