"""A Ray Tune search over the learning rate and the number of simulation steps of diffmpm_simple's initial-
velocity fit (issue 26): each trial builds the MPM program in its own Ray worker process (simgrad.distributed's
rule: programs are built where they run, never pickled), runs its gradient-descent iterations and reports the
loss after each; Tune keeps the best configuration. Writes the loss curves of all trials, the best one bold, to
out/ray_tune_search/loss.png.

    pip install "ray[tune]"
    python examples/ray_tune_search.py [--iters 8] [--samples 6]

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


def trainable(config):
    """One trial: the program built in this process, `iters` gradient steps on init_v at config's rate."""
    sys.path.insert(0, EXAMPLES)
    import diffmpm_simple
    from ray import tune

    import simgrad as ti

    ti.init(arch=ti.cpu, cpu_max_num_threads=1)  # one CPU per trial (Tune's default resources)
    sim = diffmpm_simple.build(config["n_side"], config["n_grid"], int(config["steps"]))
    sim.reset()
    v = np.zeros(2)
    for _ in range(config["iters"]):
        sim.init_v[None] = [float(c) for c in v]
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        tune.report({"loss": float(sim.loss[None])})
        v = v - config["lr"] * sim.init_v.grad.to_numpy()


def main():
    args = parse_args("Ray Tune search of an MPM velocity fit's learning rate and step count", iters=8, samples=6,
                      n_side=16, n_grid=32, seed=0)
    try:
        import ray
        from ray import tune
    except ImportError as e:
        raise SystemExit(f"this example needs Ray Tune: pip install \"ray[tune]\" ({e})") from None
    out = out_dir(args.out, "ray_tune_search")
    ray.init(ignore_reinit_error=True, include_dashboard=False)
    if __name__ != "__main__":  # imported (a test): the trials get this module's code by value, not by name
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    space = {"lr": tune.loguniform(2.0, 60.0), "steps": tune.choice([64, 96, 128]), "iters": args.iters,
             "n_side": args.n_side, "n_grid": args.n_grid}
    t0 = time.time()
    tuner = tune.Tuner(trainable, param_space=space,
                       tune_config=tune.TuneConfig(metric="loss", mode="min", num_samples=args.samples,
                                                   search_alg=tune.search.BasicVariantGenerator(random_state=args.seed)),
                       run_config=tune.RunConfig(storage_path=os.path.abspath(os.path.join(out, "tune")),
                                                 verbose=0))
    results = tuner.fit()
    best = results.get_best_result()
    curves = [(r.config, r.metrics_dataframe["loss"].to_list()) for r in results if r.metrics_dataframe is not None]
    plot(curves, best.config, os.path.join(out, "loss.png"))
    for cfg, c in curves:
        mark = "  (best)" if cfg == best.config else ""
        print(f"lr {cfg['lr']:7.3f} steps {cfg['steps']:4d}: loss {c[0]:.5f} -> {c[-1]:.5f}{mark}")
    print(f"{time.time() - t0:.1f} s; best lr {best.config['lr']:.3f}, steps {best.config['steps']}; "
          f"plot: {os.path.join(out, 'loss.png')}")
    return curves, best.config


def plot(curves, best_config, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for cfg, c in curves:
        b = cfg == best_config
        ax.plot(c, lw=2.5 if b else 1, alpha=1 if b else 0.5, label=f"lr {cfg['lr']:.1f}, {cfg['steps']} steps")
    ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("distance to target")
    ax.set_title("diffmpm_simple under Ray Tune")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
