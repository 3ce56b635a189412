"""A learning-rate sweep of diffmpm_simple's initial-velocity fit on Ray (simgrad.distributed, issue 26).

One optimisation per learning rate, all advancing together: every round is one `WorkerPool.map` of the
current initial velocities (each worker built the MPM program once, in its own process, with its thread pool
sized to its CPUs, and loaded the kernels the first worker compiled), then each velocity takes its gradient step
here. Writes every loss curve, the best one highlighted, to out/ray_lr_sweep/loss.png.

    python examples/ray_lr_sweep.py [--iters 10] [--lrs 2,5,10,20,40] [--steps 128] [--workers 0]

`ray.init()` starts a local Ray; with RAY_ADDRESS set the same script runs on that cluster.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

EXAMPLES = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, EXAMPLES)
from _common import out_dir, parse_args  # noqa: E402


def make_build(n_side: int = 20, n_grid: int = 32, steps: int = 128):
    """build() for the workers: the MPM program of diffmpm_simple; f(params) is its loss and d loss / d init_v."""

    def build():
        sys.path.insert(0, EXAMPLES)  # in the worker's process
        import diffmpm_simple

        import simgrad as ti

        sim = diffmpm_simple.build(n_side, n_grid, steps)
        sim.reset()

        def value_and_grad(params):
            sim.init_v[None] = [float(c) for c in params["init_v"]]
            with ti.ad.Tape(loss=sim.loss):
                sim.forward()
            return float(sim.loss[None]), {"init_v": sim.init_v.grad.to_numpy()}

        return value_and_grad

    return build


def sweep(pool, lrs, iters: int) -> list[list[float]]:
    """Gradient descent on init_v for every learning rate, one pool.map per round; the loss curves."""
    v = [np.zeros(2) for _ in lrs]
    curves: list[list[float]] = [[] for _ in lrs]
    for _ in range(iters):
        results = pool.map([{"init_v": vk} for vk in v], progress=False)
        for k, (loss, grads) in enumerate(results):
            curves[k].append(loss)
            v[k] = v[k] - lrs[k] * grads["init_v"]
    return curves


def plot(curves, lrs, path: str) -> int:
    """All curves, the best (lowest final loss) drawn bold; returns its index."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    best = int(np.argmin([c[-1] for c in curves]))
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for k, c in enumerate(curves):
        ax.plot(c, lw=2.5 if k == best else 1, alpha=1 if k == best else 0.5, label=f"lr {lrs[k]:g}")
    ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("distance to target")
    ax.set_title(f"diffmpm_simple on Ray: best lr {lrs[best]:g}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return best


def main():
    args = parse_args("Learning-rate sweep of an MPM velocity fit on Ray", iters=10, lrs="2,5,10,20,40",
                      steps=128, n_side=20, n_grid=32, workers=0)
    from simgrad.distributed import WorkerPool

    lrs = [float(s) for s in args.lrs.split(",")]
    out = out_dir(args.out, "ray_lr_sweep")
    t0 = time.time()
    with WorkerPool(make_build(args.n_side, args.n_grid, args.steps), args.workers or None) as pool:
        curves = sweep(pool, lrs, args.iters)
    best = plot(curves, lrs, os.path.join(out, "loss.png"))
    for k, c in enumerate(curves):
        print(f"lr {lrs[k]:6g}: loss {c[0]:.5f} -> {c[-1]:.5f}{'  (best)' if k == best else ''}")
    print(f"{time.time() - t0:.1f} s; plot: {os.path.join(out, 'loss.png')}")
    return curves, best


if __name__ == "__main__":
    main()
