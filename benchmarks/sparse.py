"""Sparse SNodes: simgrad against Taichi on a 4096^2 field ti.root.pointer(ti.ij, 512).dense(ti.ij, 8).

    python benchmarks/sparse.py [--framework both|simgrad|taichi] [--active 0.05] [--cells 100000] [--repeats 5]
                                [--taichi-python PATH] [--json FILE]

A fixed-seed RNG picks 5% of the 512^2 pointer blocks (and, for (c), 100k random cells). Operations, each timed
(ms, best of --repeats after --warmup untimed runs that also compile), with an untimed setup before every run:

  (a) fill:       from nothing active, a kernel writes every cell of the chosen blocks (activates them)
  (b) struct-for: x[i, j] += 1 over the active cells (the chosen blocks)
  (c) activate:   from the chosen blocks active, a kernel writes 100k random cells (activates their blocks)
  (d) deactivate_all: pointer.deactivate_all() after (a) and (c)

Each framework runs in its own process (simgrad with this interpreter or --simgrad-python, Taichi with
--taichi-python, default $TAICHI_PYTHON or /work/tivenv/bin/python). Both report the number of active cells and a
checksum after each step, which must agree. A framework that fails is reported with the end of its error output.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

CHILD = r"""
import json, sys, time
import numpy as np

framework, n, bs, frac, n_cells, repeats, warmup, seed = (sys.argv[1], int(sys.argv[2]), int(sys.argv[3]),
    float(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6]), int(sys.argv[7]), int(sys.argv[8]))
if framework == "taichi":
    import taichi as ti
else:
    import simgrad as ti
ti.init(arch=ti.cpu)

nb = n // bs
x = ti.field(ti.f32)
blk = ti.root.pointer(ti.ij, nb)
blk.dense(ti.ij, bs).place(x)

rng = np.random.default_rng(seed)
n_blocks = int(round(frac * nb * nb))
chosen = rng.choice(nb * nb, size=n_blocks, replace=False)
blocks = ti.field(ti.i32, shape=(n_blocks, 2))
blocks.from_numpy(np.stack([chosen // nb, chosen % nb], axis=1).astype(np.int32))
cells = ti.field(ti.i32, shape=(n_cells, 2))
cells.from_numpy(rng.integers(0, n, size=(n_cells, 2)).astype(np.int32))
stats = ti.field(ti.f64, shape=2)


@ti.kernel
def fill_blocks():
    for k, di, dj in ti.ndrange(n_blocks, bs, bs):
        x[blocks[k, 0] * bs + di, blocks[k, 1] * bs + dj] = 1.0


@ti.kernel
def add_one():
    for i, j in x:
        x[i, j] += 1.0


@ti.kernel
def activate_cells():
    for k in range(n_cells):
        x[cells[k, 0], cells[k, 1]] = 2.0


@ti.kernel
def measure():
    stats[0] = 0.0
    stats[1] = 0.0
    for i, j in x:
        stats[0] += 1.0
        stats[1] += x[i, j]


def deactivate_all():
    blk.deactivate_all()


def check():
    measure()
    ti.sync()
    return [int(stats[0]), float(stats[1])]


def timed(setup, op):
    best = float("inf")
    for r in range(warmup + repeats):
        setup()
        ti.sync()
        t0 = time.perf_counter()
        op()
        ti.sync()
        dt = time.perf_counter() - t0
        if r >= warmup:
            best = min(best, dt)
    return best * 1e3


def nothing():
    pass


def chosen_active():
    deactivate_all()
    fill_blocks()


def chosen_and_cells_active():
    chosen_active()
    activate_cells()


res = {"framework": framework, "ms": {}, "check": {}}
res["ms"]["fill"] = timed(deactivate_all, fill_blocks)
res["check"]["fill"] = check()
res["ms"]["struct_for"] = timed(nothing, add_one)
chosen_active()
add_one()
res["check"]["struct_for"] = check()
res["ms"]["activate"] = timed(chosen_active, activate_cells)
res["check"]["activate"] = check()
res["ms"]["deactivate_all"] = timed(chosen_and_cells_active, deactivate_all)
res["check"]["deactivate_all"] = check()
print(json.dumps(res))
"""

OPS = [
    ("fill", "(a) fill the chosen blocks (kernel)"),
    ("struct_for", "(b) struct-for x[i, j] += 1"),
    ("activate", "(c) activate random cells (kernel)"),
    ("deactivate_all", "(d) deactivate_all"),
]


def run(framework: str, python: str, args, script: str) -> dict:
    cmd = [
        python,
        script,
        framework,
        str(args.n),
        str(args.block),
        str(args.active),
        str(args.cells),
        str(args.repeats),
        str(args.warmup),
        str(args.seed),
    ]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    except FileNotFoundError as e:
        return {"framework": framework, "error": str(e)}
    except subprocess.TimeoutExpired:
        return {"framework": framework, "error": f"timed out after {args.timeout} s"}
    if out.returncode:
        return {"framework": framework, "error": (out.stderr or out.stdout)[-2000:]}
    try:
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        return {"framework": framework, "error": "no result line in its output:\n" + out.stdout[-2000:]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--framework", choices=["both", "simgrad", "taichi"], default="both")
    ap.add_argument("--n", type=int, default=4096, help="field side (default 4096)")
    ap.add_argument("--block", type=int, default=8, help="dense block side under the pointer (default 8)")
    ap.add_argument("--active", type=float, default=0.05, help="fraction of pointer blocks chosen (default 0.05)")
    ap.add_argument("--cells", type=int, default=100000, help="random cells activated in (c) (default 100000)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per framework process")
    ap.add_argument("--simgrad-python", default=sys.executable)
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON", "/work/tivenv/bin/python"))
    ap.add_argument("--json", metavar="FILE", help="also save the results as JSON")
    args = ap.parse_args()
    frameworks = ["simgrad", "taichi"] if args.framework == "both" else [args.framework]
    pythons = {"simgrad": args.simgrad_python, "taichi": args.taichi_python}

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        script = os.path.join(tmp, "sparse_child.py")  # kernels are compiled from source: a file, not -c
        with open(script, "w") as fh:
            fh.write(CHILD)
        for fw in frameworks:
            results[fw] = run(fw, pythons[fw], args, script)

    nb = args.n // args.block
    print(
        f"{args.n}^2 f32 field, pointer({nb}^2).dense({args.block}^2), {args.active:.0%} of blocks "
        f"({int(round(args.active * nb * nb))}), {args.cells} random cells; ms, best of {args.repeats} after "
        f"{args.warmup} warm-up ({os.cpu_count()} cores)"
    )
    for fw, res in results.items():
        if "error" in res:
            print(f"\n{fw} FAILED:\n{res['error'].rstrip()}\n")
    ok = [fw for fw in frameworks if "error" not in results[fw]]
    header = "| operation | " + " | ".join(f"{fw} ms" for fw in frameworks)
    if ok == ["simgrad", "taichi"]:
        header += " | simgrad/taichi"
    print(header + " |")
    print("|---" * (header.count("|")) + "|")
    for key, label in OPS:
        row = f"| {label} | "
        row += " | ".join(f"{results[fw]['ms'][key]:.3f}" if fw in ok else "failed" for fw in frameworks)
        if ok == ["simgrad", "taichi"]:
            row += f" | {results['simgrad']['ms'][key] / results['taichi']['ms'][key]:.2f}"
        print(row + " |")
    if ok == ["simgrad", "taichi"]:
        for key, _ in OPS:
            a, b = results["simgrad"]["check"][key], results["taichi"]["check"][key]
            if a[0] != b[0] or abs(a[1] - b[1]) > 1e-6 * max(1.0, abs(b[1])):
                print(f"MISMATCH after {key}: simgrad (active cells, sum) {a}, taichi {b}")
    for fw in ok:
        print(f"{fw} checks (active cells, sum): " + ", ".join(f"{k} {v}" for k, v in results[fw]["check"].items()))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "results": results}, fh, indent=1)
    if len(ok) < len(frameworks):
        sys.exit(1)


if __name__ == "__main__":
    main()
