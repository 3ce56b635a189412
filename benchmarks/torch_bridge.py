"""Overhead of the torch bridge: one `@simgrad.torch.function` call (forward, and forward + backward) against a
direct kernel launch on the same tensors, and against Taichi 1.7.4's recommended manual pattern (fields, a
hand-written torch.autograd.Function copying in and out with from_torch/to_torch).

    python benchmarks/torch_bridge.py [--sizes 1000 1000000] [--repeats 200]
                                      [--taichi-python /work/tivenv/bin/python] [--json OUT]

The model is y = sin(x) * w elementwise, loss = y.sum(). Variants (microseconds per call, median of
`repeats`):
- simgrad kernel: `k(x, w, y)` on the tensors (zero copy); kernel + grad: then `k.grad` with pairs;
- simgrad bridged: `f(x, w)` under torch.no_grad (the plain call) and `f(x, w).sum().backward()`;
- taichi manual: x/w fields from_torch, kernel, y.to_torch (forward), then y.grad.from_torch, kernel.grad,
  x.grad/w.grad.to_torch (backward) inside a torch.autograd.Function, as Taichi's docs show.
Each framework runs in its own process (taichi's in its own interpreter). Timings are for the machine the
script runs on; on a shared machine they are indicative only.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

CHILD = r'''
import json, sys, time
import numpy as np
import torch
framework, sizes, repeats = sys.argv[1], [int(s) for s in sys.argv[2].split(",")], int(sys.argv[3])
torch.set_num_threads(int(sys.argv[4]))
if framework == "taichi":
    import taichi as ti
else:
    import simgrad as ti
ti.init(arch=ti.cpu)

def median_us(fn):
    fn()
    fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts) * 1e6)

out = {}
for n in sizes:
    x = torch.rand(n, requires_grad=True)
    w = torch.rand(n, requires_grad=True)
    row = {}
    if framework == "simgrad":
        @ti.kernel
        def k(x: ti.types.ndarray(), w: ti.types.ndarray(), y: ti.types.ndarray()):
            for i in x:
                y[i] = ti.sin(x[i]) * w[i]

        xd, wd, y = x.detach(), w.detach(), torch.zeros(n)
        row["simgrad kernel"] = median_us(lambda: k(xd, wd, y))
        gx, gw, gy = torch.zeros(n), torch.zeros(n), torch.ones(n)
        pairs = (ti.ad.with_grad(xd, gx), ti.ad.with_grad(wd, gw), ti.ad.with_grad(y, gy))
        row["simgrad kernel + grad"] = median_us(lambda: (k(xd, wd, y), k.grad(*pairs)))

        @ti.torch.function
        def f(x, w):
            y = torch.empty_like(x)
            k(x, w, y)
            return y

        def bridged():
            with torch.no_grad():
                f(x, w)

        row["simgrad bridged forward"] = median_us(bridged)

        def bridged_backward():
            x.grad = w.grad = None
            f(x, w).sum().backward()

        row["simgrad bridged forward + backward"] = median_us(bridged_backward)
        check = (torch.cos(x) * w).detach()
        assert torch.allclose(x.grad, check, rtol=1e-5, atol=1e-6)
    else:
        xf = ti.field(ti.f32, shape=n, needs_grad=True)
        wf = ti.field(ti.f32, shape=n, needs_grad=True)
        yf = ti.field(ti.f32, shape=n, needs_grad=True)

        @ti.kernel
        def k():
            for i in xf:
                yf[i] = ti.sin(xf[i]) * wf[i]

        class Manual(torch.autograd.Function):
            @staticmethod
            def forward(ctx, x, w):
                xf.from_torch(x)
                wf.from_torch(w)
                k()
                return yf.to_torch()

            @staticmethod
            def backward(ctx, g):
                xf.grad.fill(0)
                wf.grad.fill(0)
                yf.grad.from_torch(g.contiguous())
                k.grad()
                return xf.grad.to_torch(), wf.grad.to_torch()

        row["taichi kernel (fields)"] = median_us(lambda: (k(), ti.sync()))

        def manual():
            with torch.no_grad():
                Manual.apply(x, w)

        row["taichi manual forward"] = median_us(manual)

        def manual_backward():
            x.grad = w.grad = None
            Manual.apply(x, w).sum().backward()

        row["taichi manual forward + backward"] = median_us(manual_backward)
        check = (torch.cos(x) * w).detach()
        assert torch.allclose(x.grad, check, rtol=1e-5, atol=1e-6)
    out[n] = row
print(json.dumps(out))
'''


def run(python: str, framework: str, sizes: list[int], repeats: int, torch_threads: int) -> dict:
    env = dict(os.environ)
    if framework == "simgrad":
        env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                             env.get("PYTHONPATH", "")])
    with tempfile.TemporaryDirectory() as tmp:  # kernels need a source file (both frameworks parse it)
        script = os.path.join(tmp, "torch_bridge_child.py")
        with open(script, "w") as fh:
            fh.write(CHILD)
        proc = subprocess.run([python, script, framework, ",".join(map(str, sizes)), str(repeats),
                               str(torch_threads)], capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        return {"error": proc.stderr[-1500:]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="*", default=[1000, 1000000])
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON"))
    ap.add_argument("--torch-threads", type=int, default=1,
                    help="torch's intra-op threads (1: torch's own ops do not compete with the kernels' pool; on a "
                         "loaded 2-core machine torch.zeros(100000) took 12 ms with its default threads, 0.02 ms "
                         "with one)")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    results = {"simgrad": run(sys.executable, "simgrad", args.sizes, args.repeats, args.torch_threads)}
    if args.taichi_python:
        results["taichi"] = run(args.taichi_python, "taichi", args.sizes, args.repeats,
                                 args.torch_threads)
    print("| variant | " + " | ".join(f"n = {n} (us)" for n in args.sizes) + " |")
    print("|---|" + "---|" * len(args.sizes))
    for framework, res in results.items():
        if "error" in res:
            print(f"{framework} failed:\n{res['error']}")
            continue
        for name in res[str(args.sizes[0])]:
            print(f"| {name} | " + " | ".join(f"{res[str(n)][name]:.1f}" for n in args.sizes) + " |")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
