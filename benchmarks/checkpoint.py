"""Memory and time of a long simulation's gradient: ti.ad.checkpoint (in-place state, a snapshot budget) against
the same simulation with every step's state stored (x[t, i], v[t, i], f[t, i]).

    python benchmarks/checkpoint.py [--particles 10000] [--steps 1000] [--budget 10] [--repeats 2]

Both advance a step with the same two kernels (forces, then velocities and positions). Each variant runs in
its own process; memory is the growth of peak resident memory over the process's
baseline after ti.init and the first (compiling) gradient, time the mean of the later gradients. The
gradients of the two are compared.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

CHILD = r'''
import json, resource, sys, time
import numpy as np
import simgrad as ti

variant, n, steps, budget, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
ti.init(arch=ti.cpu)
dt, k, damping = 1e-3, 50.0, 0.999
def rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
if variant == "checkpoint":
    x = ti.Vector.field(2, ti.f32, shape=n, needs_grad=True)
    v = ti.Vector.field(2, ti.f32, shape=n, needs_grad=True)
    f = ti.Vector.field(2, ti.f32, shape=n, needs_grad=True)
else:
    x = ti.Vector.field(2, ti.f32, shape=(steps + 1, n), needs_grad=True)
    v = ti.Vector.field(2, ti.f32, shape=(steps + 1, n), needs_grad=True)
    f = ti.Vector.field(2, ti.f32, shape=(steps, n), needs_grad=True)
x0 = ti.Vector.field(2, ti.f32, shape=n, needs_grad=True)
loss = ti.field(ti.f32, shape=(), needs_grad=True)

@ti.kernel
def start_ckpt():
    for i in range(n):
        x[i] = x0[i]
        v[i] = ti.Vector([0.0, 0.0])

@ti.kernel
def forces_ckpt():
    for i in range(n):
        j = (i + 1) % n
        l = (i + n - 1) % n
        f[i] = -k * (2 * x[i] - x[j] - x[l]) - ti.Vector([0.0, 1.0]) * ti.sin(x[i][0])

@ti.kernel
def advance_ckpt():
    for i in range(n):
        v[i] = v[i] * damping + dt * f[i]
        x[i] += dt * v[i]

@ti.kernel
def loss_ckpt():
    for i in range(n):
        loss[None] += x[i].norm_sqr()

@ti.kernel
def start_full():
    for i in range(n):
        x[0, i] = x0[i]
        v[0, i] = ti.Vector([0.0, 0.0])

@ti.kernel
def forces_full(t: ti.i32):
    for i in range(n):
        j = (i + 1) % n
        l = (i + n - 1) % n
        f[t, i] = -k * (2 * x[t, i] - x[t, j] - x[t, l]) - ti.Vector([0.0, 1.0]) * ti.sin(x[t, i][0])

@ti.kernel
def advance_full(t: ti.i32):
    for i in range(n):
        v[t + 1, i] = v[t, i] * damping + dt * f[t, i]
        x[t + 1, i] = x[t, i] + dt * v[t + 1, i]

@ti.kernel
def loss_full():
    for i in range(n):
        loss[None] += x[steps, i].norm_sqr()

def step(t):
    forces_ckpt()
    advance_ckpt()

x0.from_numpy(np.random.default_rng(0).random((n, 2)).astype(np.float32))

def gradient():
    with ti.ad.Tape(loss=loss):
        if variant == "checkpoint":
            start_ckpt()
            ti.ad.checkpoint(step, steps, state=[x, v], budget=budget)
            loss_ckpt()
        else:
            start_full()
            for t in range(steps):
                forces_full(t)
                advance_full(t)
            loss_full()
    return x0.grad.to_numpy()

g = gradient()  # compiles and touches the memory once
base_after_first = rss()
times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    g = gradient()
    times.append(time.perf_counter() - t0)
np.save(sys.argv[6], g)
print(json.dumps({"peak_rss": rss(), "rss_after_first": base_after_first, "seconds": sum(times) / len(times)}))
'''


def run(variant: str, args, tmp: str) -> dict:
    baseline = subprocess.run([sys.executable, "-c", "import resource, simgrad as ti; ti.init(arch=ti.cpu); "
                               "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)"],
                              capture_output=True, text=True, check=True)
    script = os.path.join(tmp, "child.py")  # kernels are compiled from source: a file, not -c
    with open(script, "w") as fh:
        fh.write(CHILD)
    out = subprocess.run([sys.executable, script, variant, str(args.particles), str(args.steps),
                          str(args.budget), str(args.repeats), os.path.join(tmp, variant + ".npy")],
                         capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(out.stderr[-3000:])
    res = json.loads(out.stdout.strip().splitlines()[-1])
    res["baseline"] = int(baseline.stdout.strip())
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--particles", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--budget", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        full = run("full", args, tmp)
        ckpt = run("checkpoint", args, tmp)
        gf = np.load(os.path.join(tmp, "full.npy"))
        gc = np.load(os.path.join(tmp, "checkpoint.npy"))
    mem_full = full["peak_rss"] - full["baseline"]
    mem_ckpt = ckpt["peak_rss"] - ckpt["baseline"]
    print(f"{args.particles} particles, {args.steps} steps, budget {args.budget} (f32, {os.cpu_count()} cores)")
    print("| variant | memory over baseline | s per gradient |\n|---|---|---|")
    print(f"| time-indexed (every step stored) | {mem_full / 2**20:.1f} MiB | {full['seconds']:.3f} |")
    print(f"| ti.ad.checkpoint(budget={args.budget}) | {mem_ckpt / 2**20:.1f} MiB | {ckpt['seconds']:.3f} |")
    print(f"memory ratio {mem_ckpt / max(mem_full, 1):.3f}, time ratio {ckpt['seconds'] / full['seconds']:.2f}, "
          f"gradients max rel diff {np.max(np.abs(gc - gf)) / np.max(np.abs(gf)):.1e}")


if __name__ == "__main__":
    main()
