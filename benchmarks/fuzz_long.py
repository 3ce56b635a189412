"""The long run of the differential fuzzers (tests/fuzz/gen.py, tests/fuzz/shapes.py): N random programs,
half forward programs against the Python/numpy reference, half differentiable programs against finite
differences (and, for the shapes generator, forward mode against reverse mode).

    python benchmarks/fuzz_long.py --cases 10000 [--gen shapes|flat] [--start 0] [--batch 250] [--jobs 2]
                                   [--log results.jsonl]

Cases run in child processes, a batch each, so a crash (segfault, abort) is counted, not fatal: a batch
that dies is re-run one case per process to name the case. Prints the counts (cases, crashes, mismatches,
errors = valid programs that failed to compile or run) and every failing case's seed, kind and message;
--log appends each case's result as it comes (a long run stopped early keeps what it did).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor

HERE = os.path.dirname(os.path.abspath(__file__))
FUZZ = os.path.join(HERE, "..", "tests", "fuzz")

CHILD = r"""
import json, pathlib, sys, tempfile, traceback
sys.path.insert(0, sys.argv[1])
import gen
import shapes
RUN = {"fwd": [gen.run_forward], "grad": [gen.run_gradient], "sfwd": [shapes.run_forward],
       "sgrad": [shapes.run_gradient, shapes.run_forward_mode]}
for spec in sys.argv[2:]:
    kind, seed, size = spec.split(":")
    seed, size = int(seed), int(size)
    with tempfile.TemporaryDirectory() as d:
        try:
            for run in RUN[kind]:
                run(seed, size, pathlib.Path(d))
            status, msg = "ok", ""
        except gen.Inconclusive as e:
            status, msg = "inconclusive", str(e)[-300:]
        except AssertionError as e:
            status, msg = "mismatch", str(e)[-3000:]
        except Exception as e:
            status, msg = "error", (traceback.format_exc())[-3000:]
    print("CASE " + json.dumps({"spec": spec, "status": status, "msg": msg}), flush=True)
"""


def specs(start: int, cases: int, generator: str = "flat") -> list[str]:
    out = []
    for c in range(start, start + cases):
        kind = "fwd" if c % 2 == 0 else "grad"
        size = 1 + (c // 2) % (8 if kind == "fwd" else 5)
        if generator == "shapes":
            kind = "s" + kind
        out.append(f"{kind}:{c}:{size}")
    return out


def run_batch(batch: list[str]) -> list[dict]:
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.setdefault("SIMGRAD_VERIFY", "1")  # the IR verifier after every pass, as in the tests (LLVM's always runs)
    with tempfile.TemporaryDirectory() as cache:
        env["SIMGRAD_CACHE_DIR"] = cache
        proc = subprocess.run([sys.executable, "-c", CHILD, FUZZ, *batch], capture_output=True, text=True,
                              env=env, timeout=3600)
    done = [json.loads(line[5:]) for line in proc.stdout.splitlines() if line.startswith("CASE ")]
    if proc.returncode != 0:
        seen = {d["spec"] for d in done}
        rest = [s for s in batch if s not in seen]
        if len(batch) == 1:
            return done + [{"spec": batch[0], "status": "crash",
                            "msg": f"exit {proc.returncode}: {proc.stderr[-2000:]}"}]
        for s in rest:  # one per process, to name the case that crashed
            done += run_batch([s])
    return done


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=10000)
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--batch", type=int, default=250)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", help="write all results here")
    ap.add_argument("--gen", choices=("flat", "shapes"), default="shapes",
                    help="flat: gen.py's kernels; shapes: shapes.py's programs of real shapes")
    ap.add_argument("--log", help="append each case's result here as a JSON line")
    args = ap.parse_args()
    todo = specs(args.start, args.cases, args.gen)
    batches = [todo[k:k + args.batch] for k in range(0, len(todo), args.batch)]
    results: list[dict] = []
    with ThreadPoolExecutor(args.jobs) as ex:
        for k, res in enumerate(ex.map(run_batch, batches)):
            results += res
            if args.log:
                with open(args.log, "a") as fh:
                    fh.writelines(json.dumps(r) + "\n" for r in res)
            bad = [r for r in res if r["status"] not in ("ok", "inconclusive")]
            print(f"batch {k + 1}/{len(batches)}: {len(res)} cases, {len(bad)} failing", flush=True)
    counts = {s: sum(r["status"] == s for r in results) for s in ("ok", "inconclusive", "mismatch", "error", "crash")}
    print(json.dumps({"cases": len(results), **counts}))
    for r in results:
        if r["status"] not in ("ok", "inconclusive"):
            print(f"--- {r['spec']} {r['status']}\n{r['msg']}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh)


if __name__ == "__main__":
    main()
