"""Seconds per optimisation iteration of each example, under simgrad and under taichi, in one run.

    python benchmarks/examples.py [--only NAME ...] [--iters N]

Each (framework, example) runs in a fresh process: `train(iters=1)` with an empty offline cache gives the
first-iteration time (compile included); then, in the same process (cache warm), the difference between
`train(iters=N+1)` and `train(iters=1)` divided by N gives the steady seconds per iteration (each train()
builds new fields and kernels, whose instantiation both frameworks pay again; the difference cancels it
and any setup work). Under taichi the example's `import simgrad as ti` is served by `taichi`
(the examples use only the Taichi API). taichi comes from this interpreter or $TAICHI_PYTHON.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLES = os.path.join(HERE, "..", "examples")

# example -> keyword arguments of train() for the benchmark (defaults = the example's full size)
DEFAULT = ["mass_spring_simple", "diffmpm_simple", "mass_spring", "electric", "billiards", "rigid_body", "wave",
           "smoke", "diffmpm", "volume_renderer", "water_renderer", "potential_forces", "diffmpm3d", "liquid"]

RUNNER = r"""
import json, os, sys, time
fw, name, iters, cache = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
if fw == "taichi":
    import taichi
    sys.modules["simgrad"] = taichi
sys.path.insert(0, {examples!r})
import simgrad as ti
ti.init(arch=ti.cpu, offline_cache=True, offline_cache_file_path=cache)
mod = __import__(name)
t = time.perf_counter()
losses1, _ = mod.train(1, None)
first = time.perf_counter() - t
t = time.perf_counter()
mod.train(1, None)
one = time.perf_counter() - t
t = time.perf_counter()
losses, sec = mod.train(iters + 1, None)
more = time.perf_counter() - t
print("RESULT " + json.dumps({{"first_s": first, "sec_per_iter": (more - one) / iters, "example_sec": sec,
                               "first_loss": float(losses[0]), "last_loss": float(losses[-1])}}))
"""


def _env() -> dict:
    """Child environment: quiet taichi, and bytecode caching on as on a user's machine (this sandbox sets
    PYTHONDONTWRITEBYTECODE, which would charge every process for compiling our Python sources)."""
    env = dict(os.environ, TI_LOG_LEVEL="error")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def taichi_python():
    try:
        import taichi  # noqa: F401

        return sys.executable
    except ImportError:
        return os.environ.get("TAICHI_PYTHON")


def run(python, fw, name, iters):
    with tempfile.TemporaryDirectory() as cache:
        code = RUNNER.format(examples=os.path.abspath(EXAMPLES))
        proc = subprocess.run([python, "-c", code, fw, name, str(iters), cache], capture_output=True, text=True,
                              timeout=3600, env=_env())
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    print(f"warning: {fw}/{name} failed: {proc.stderr[-800:]}", file=sys.stderr)
    return None


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--only", action="append")
    p.add_argument("--iters", type=int, default=3)
    args = p.parse_args()
    tpy = taichi_python()
    print("| example | simgrad s/iter | taichi s/iter | ratio | simgrad first iter (s) | taichi first iter (s) |")
    print("|---|---|---|---|---|---|")
    for name in args.only or DEFAULT:
        if not os.path.exists(os.path.join(EXAMPLES, name + ".py")):
            continue
        ours = run(sys.executable, "simgrad", name, args.iters)
        theirs = run(tpy, "taichi", name, args.iters) if tpy else None

        def f(r, k):
            return f"{r[k]:.3g}" if r else "-"

        ratio = f"{ours['sec_per_iter'] / theirs['sec_per_iter']:.2f}" if ours and theirs else "-"
        print(f"| {name} | {f(ours, 'sec_per_iter')} | {f(theirs, 'sec_per_iter')} | {ratio} | "
              f"{f(ours, 'first_s')} | {f(theirs, 'first_s')} |", flush=True)


if __name__ == "__main__":
    main()
