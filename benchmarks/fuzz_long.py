"""The long run of the differential fuzzer (tests/fuzz/gen.py): N random kernels, half forward programs
against the numpy reference, half differentiable programs against finite differences.

    python benchmarks/fuzz_long.py --cases 10000 [--start 0] [--batch 250] [--jobs 2]

Cases run in child processes, a batch each, so a crash (segfault, abort) is counted, not fatal: a batch
that dies is re-run one case per process to name the case. Prints the counts (cases, crashes, mismatches,
errors = valid programs that failed to compile or run) and every failing case's seed, kind and message.
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
for spec in sys.argv[2:]:
    kind, seed, size = spec.split(":")
    seed, size = int(seed), int(size)
    with tempfile.TemporaryDirectory() as d:
        try:
            (gen.run_forward if kind == "fwd" else gen.run_gradient)(seed, size, pathlib.Path(d))
            status, msg = "ok", ""
        except gen.Inconclusive as e:
            status, msg = "inconclusive", str(e)[-300:]
        except AssertionError as e:
            status, msg = "mismatch", str(e)[-3000:]
        except Exception as e:
            status, msg = "error", (traceback.format_exc())[-3000:]
    print("CASE " + json.dumps({"spec": spec, "status": status, "msg": msg}), flush=True)
"""


def specs(start: int, cases: int) -> list[str]:
    out = []
    for c in range(start, start + cases):
        kind = "fwd" if c % 2 == 0 else "grad"
        size = 1 + (c // 2) % (8 if kind == "fwd" else 5)
        out.append(f"{kind}:{c}:{size}")
    return out


def run_batch(batch: list[str]) -> list[dict]:
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
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
    args = ap.parse_args()
    todo = specs(args.start, args.cases)
    batches = [todo[k:k + args.batch] for k in range(0, len(todo), args.batch)]
    results: list[dict] = []
    with ThreadPoolExecutor(args.jobs) as ex:
        for k, res in enumerate(ex.map(run_batch, batches)):
            results += res
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
