"""8 independent optimisations in-process one after another versus through simgrad.distributed (issue 26).

The optimisations are examples/ray_lr_sweep.py's: diffmpm_simple's initial-velocity fit, one per learning rate,
`--iters` gradient steps each. In-process (a child process with a fresh kernel cache and `--threads` threads):
the program built once, the 8 optimisations run one after another. Distributed: a WorkerPool on a local Ray
(fresh cache too), every round one map of the 8 current params. Printed: wall time of each, LLVM compiles and
kernel-cache hits per process (the shared cache: the first worker compiles, the others compile nothing), the
per-task cost, and a paper estimate for a 64-core cluster from these measured costs.

    python benchmarks/ray_map.py [--iters 5] [--steps 128] [--n-side 20] [--n-grid 32] [--workers 0] [--threads 2]

Timings on a shared, loaded machine mean little; the compile counts do not depend on load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "examples"))

LRS = [2.0, 5.0, 10.0, 20.0, 40.0, 60.0, 80.0, 100.0]


def in_process(args) -> dict:
    """The child: 8 optimisations one after another in this process."""
    import numpy as np
    import ray_lr_sweep

    import simgrad as ti
    from simgrad.runtime.jit import get_jit

    t0 = time.perf_counter()
    ti.init(arch=ti.cpu, cpu_max_num_threads=args.threads)
    f = ray_lr_sweep.make_build(args.n_side, args.n_grid, args.steps)()
    task_times = []
    first = None
    for lr in LRS:
        v = np.zeros(2)
        for _ in range(args.iters):
            t = time.perf_counter()
            _, grads = f({"init_v": v})
            if first is None:
                first = time.perf_counter() - t0  # build + the first task: the compile
            else:
                task_times.append(time.perf_counter() - t)
            v = v - lr * grads["init_v"]
    stats = get_jit().stats
    return {"wall": time.perf_counter() - t0, "first": first, "task": sorted(task_times)[len(task_times) // 2],
            "compiled": stats["compiled"], "kernel_hits": stats["kernel_hits"],
            "compile_seconds": ti.lang.impl.get_runtime().prog.get_total_compilation_time()}


def distributed(args) -> dict:
    import ray
    import ray_lr_sweep

    from simgrad.distributed import WorkerPool

    t0 = time.perf_counter()
    if not ray.is_initialized():
        ray.init(include_dashboard=False, log_to_driver=False)
    t_ray = time.perf_counter() - t0
    cache = tempfile.mkdtemp(prefix="simgrad-ray-bench-")
    with WorkerPool(ray_lr_sweep.make_build(args.n_side, args.n_grid, args.steps), args.workers or None,
                    cache_dir=cache) as pool:
        rounds = []
        import numpy as np

        v = [np.zeros(2) for _ in LRS]
        for _ in range(args.iters):
            t = time.perf_counter()
            results = pool.map([{"init_v": vk} for vk in v], progress=False)
            rounds.append(time.perf_counter() - t)
            v = [vk - lr * g["init_v"] for vk, lr, (_, g) in zip(v, LRS, results)]
        stats = pool.stats()
    return {"wall": time.perf_counter() - t0, "ray_init": t_ray, "rounds": rounds, "workers": stats}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iters", type=int, default=5)
    p.add_argument("--steps", type=int, default=128)
    p.add_argument("--n-side", type=int, default=20)
    p.add_argument("--n-grid", type=int, default=32)
    p.add_argument("--workers", type=int, default=0)
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="threads of the in-process run")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(in_process(args)))
        return
    env = dict(os.environ, SIMGRAD_CACHE_DIR=tempfile.mkdtemp(prefix="simgrad-inproc-bench-"))
    out = subprocess.run([sys.executable, __file__, "--child", *sys.argv[1:]], env=env, check=True,
                         capture_output=True, text=True).stdout
    ip = json.loads(out.strip().splitlines()[-1])
    d = distributed(args)
    n_tasks = len(LRS) * args.iters
    print(f"{len(LRS)} optimisations x {args.iters} iterations = {n_tasks} value_and_grad tasks "
          f"(diffmpm_simple, {args.n_side}^2 particles, {args.n_grid}^2 grid, {args.steps} steps)")
    print(f"in-process ({args.threads} threads): {ip['wall']:.2f} s wall; first task incl. build+compile "
          f"{ip['first']:.2f} s; median task {ip['task'] * 1e3:.1f} ms; LLVM compiles {ip['compiled']}, "
          f"kernel-cache hits {ip['kernel_hits']}, compile time {ip['compile_seconds']:.2f} s")
    print(f"distributed ({len(d['workers'])} workers): {d['wall']:.2f} s wall incl. ray.init {d['ray_init']:.2f} s; "
          f"rounds {', '.join(f'{r:.2f}' for r in d['rounds'])} s")
    for k, w in enumerate(d["workers"]):
        print(f"  worker {k}: {w['threads']} thread(s), LLVM compiles {w['compiled']}, kernel-cache hits "
              f"{w['kernel_hits']}, instantiations {w['instantiations']}")
    steady = d["rounds"][1:] or d["rounds"]
    per_round = sum(steady) / len(steady)
    workers = len(d["workers"])
    task_1 = per_round / -(-len(LRS) // workers)  # one task's cost on a worker, overhead included
    print(f"per-task cost on a worker (steady rounds): {task_1 * 1e3:.1f} ms")
    # a cluster of 64 one-CPU workers: every round's 8 tasks run at once; start-up and the one compile as measured
    est = d["ray_init"] + d["rounds"][0] + (args.iters - 1) * task_1
    print(f"paper estimate, 64-core cluster, these 8 optimisations: ~{est:.1f} s (start-up + first round + "
          f"{args.iters - 1} rounds of one task each); 64 optimisations, one per core, would take about as long")


if __name__ == "__main__":
    main()
