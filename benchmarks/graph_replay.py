"""Per-kernel cost of a ti.graph replay, side by side with taichi (issue 25 item 3).

    python benchmarks/graph_replay.py [--taichi-python PY] [--sizes 1 100 1000] [--runs 200]

A graph of K dispatches of one tiny kernel (`x[0] += s` on a one-element-used ndarray, one thread) is
compiled and run R times with the same arguments; simgrad replays the captured launch sequence in one native
call (lang/graph.py, runtime/launch.py Sequence), so the per-kernel figure at large K is the native step
cost and at K=1 the Python cost of `run` itself. The same K*R launches made eagerly from Python are timed too.
Each framework runs in its own child process; the final value of x[0] is checked against the launch count.
"""


import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def child(framework: str, k: int, runs: int) -> dict:
    if framework == "taichi":
        import taichi as ti
    else:
        import simgrad as ti
    ti.init(arch=ti.cpu, cpu_max_num_threads=1)

    @ti.kernel
    def bump(x: ti.types.ndarray(ndim=1), s: ti.f32):
        x[0] += s

    sym_x = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "x", ti.f32, ndim=1)
    sym_s = ti.graph.Arg(ti.graph.ArgKind.SCALAR, "s", ti.f32)
    gb = ti.graph.GraphBuilder()
    for _ in range(k):
        gb.dispatch(bump, sym_x, sym_s)
    graph = gb.compile()
    x = ti.ndarray(ti.f32, shape=4)
    graph.run({"x": x, "s": 1.0})  # compiles, and captures in simgrad
    ti.sync()
    t = time.perf_counter()
    for _ in range(runs):
        graph.run({"x": x, "s": 1.0})
    ti.sync()
    replayed = (time.perf_counter() - t) / (k * runs)
    t = time.perf_counter()
    for _ in range(runs):
        for _ in range(k):
            bump(x, 1.0)
    ti.sync()
    eager = (time.perf_counter() - t) / (k * runs)
    expected = float((2 * runs + 1) * k)  # exact in f32 for the sizes used
    return {"graph_us": replayed * 1e6, "eager_us": eager * 1e6, "ok": float(x.to_numpy()[0]) == expected}


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON"))
    ap.add_argument("--sizes", type=int, nargs="*", default=[1, 100, 1000])
    ap.add_argument("--runs", type=int, default=200)
    args = ap.parse_args()
    pythons = {"simgrad": sys.executable}
    if args.taichi_python:
        pythons["taichi"] = args.taichi_python
    env = dict(os.environ, TI_LOG_LEVEL="error", PYTHONPATH=os.pathsep.join(
        p for p in [ROOT, os.environ.get("PYTHONPATH", "")] if p))
    print("| K kernels per graph | runs | " + " | ".join(f"{fw} replay us/kernel | {fw} eager us/kernel"
                                                      for fw in pythons) + " |")
    print("|---|---|" + "---|---|" * len(pythons))
    for k in args.sizes:
        runs = max(5, args.runs * 100 // max(k, 100)) if k > 100 else args.runs * 25 if k == 1 else args.runs
        cells = []
        for fw, py in pythons.items():
            out = subprocess.run([py, os.path.abspath(__file__), "--child", fw, str(k), str(runs)], env=env,
                                 capture_output=True, text=True, check=True).stdout
            r = json.loads(out.strip().splitlines()[-1])
            bad = "" if r["ok"] else " (WRONG x)"
            cells += [f"{r['graph_us']:.3f}{bad}", f"{r['eager_us']:.2f}"]
        print(f"| {k} | {runs} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
