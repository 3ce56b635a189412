"""p2g launch times of DiffTaichi's diffmpm over many processes, with the thread pool's counters (issue 21).

diffmpm's s/iter was bimodal per process; p2g launches averaged ~70 us in some processes and ~160 us in
others. This runs `--procs` fresh processes one after another (never two at once); each builds
examples/diffmpm.py's simulation, runs one forward pass to compile and warm up, then times every p2g launch
of `--rounds` forward passes (the substeps as in training: clear_grid, p2g, grid_op, g2p). With `--stats`
(default) the pool counts what it does (SIMGRAD_POOL_STATS=1, runtime/threadpool.py STAT_NAMES): how many
chunks the calling thread ran alone, how often it waited or slept for a worker still inside the job, how
often workers slept and had to be woken. The counters cost two clock reads and a few atomics per launch;
`--no-stats` leaves them out of the pool's code.

    python benchmarks/pool_stalls.py [--procs 20] [--steps 256] [--rounds 4] [--threads N] [--no-stats]

Run it on a quiet machine: it prints one line per process and then the distribution of per-process means.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def child(steps: int, rounds: int, threads: int | None) -> None:
    sys.path.insert(0, os.path.join(HERE, "..", "examples"))
    import diffmpm

    import simgrad as ti
    from simgrad.runtime.threadpool import pool_stats, reset_pool_stats

    kw = {"cpu_max_num_threads": threads} if threads else {}
    ti.init(arch=ti.cpu, default_fp=diffmpm.real, **kw)
    sim = diffmpm.build(steps=steps)
    sim.reset()
    sim.forward()  # compiles and warms up
    reset_pool_stats()
    times = []
    clock = time.perf_counter
    for _ in range(rounds):
        sim.loss[None] = 0.0
        sim.compute_actuation()
        for s in range(steps - 1):
            sim.clear_grid()
            t = clock()
            sim.p2g(s)
            times.append(clock() - t)
            sim.grid_op()
            sim.g2p(s)
    us = sorted(t * 1e6 for t in times)
    out = {"pid": os.getpid(), "n": len(us), "mean_us": statistics.fmean(us), "median_us": us[len(us) // 2],
           "p90_us": us[int(len(us) * 0.9)], "p99_us": us[int(len(us) * 0.99)], "max_us": us[-1],
           "stats": pool_stats()}
    print("RESULT " + json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--procs", type=int, default=20)
    ap.add_argument("--steps", type=int, default=256)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--no-stats", action="store_true")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.steps, args.rounds, args.threads)
        return
    env = dict(os.environ, SIMGRAD_POOL_STATS="0" if args.no_stats else "1")
    cmd = [sys.executable, os.path.abspath(__file__), "--child", "--steps", str(args.steps), "--rounds",
           str(args.rounds)] + (["--threads", str(args.threads)] if args.threads else [])
    results = []
    for k in range(args.procs):
        out = subprocess.run(cmd, capture_output=True, text=True, env=env)
        line = [ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")]
        if out.returncode != 0 or not line:
            print(f"process {k}: failed (rc {out.returncode})\n{out.stderr[-2000:]}")
            continue
        r = json.loads(line[0][len("RESULT "):])
        results.append(r)
        st = r["stats"]
        launches = max(st["launches"], 1)
        print(f"{k:3d} mean {r['mean_us']:7.1f} us  median {r['median_us']:6.1f}  p90 {r['p90_us']:7.1f}  "
              f"p99 {r['p99_us']:8.1f}  max {r['max_us']:8.1f} | alone {st['share_all'] / launches:5.1%}  "
              f"caller slept {st['caller_slept']:5d}  waited {st['caller_wait_ns'] / launches / 1e3:6.1f} us/launch"
              f"  worker sleeps {st['worker_sleeps'] / launches:5.2f}/launch  wakes {st['wakes']:5d}  "
              f"late {st['late']:4d}")
    if not results:
        return
    means = sorted(r["mean_us"] for r in results)
    typical = statistics.median(r["median_us"] for r in results)
    slow = [m for m in means if m > 1.5 * typical]
    print(f"\nper-process p2g means (us, sorted): {' '.join(f'{m:.0f}' for m in means)}")
    print(f"median of medians {typical:.1f} us; {len(slow)} of {len(means)} processes have a mean above 1.5x it")


if __name__ == "__main__":
    main()
