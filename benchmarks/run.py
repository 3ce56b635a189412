"""Side-by-side benchmarks: every case in benchmarks/cases.py under simgrad and under taichi, in one run.

    python benchmarks/run.py [--case NAME ...] [--markdown]

Each (framework, case) runs in its own fresh process so compile times are cold and the two LLVMs never
share a process. taichi is an optional dev dependency: it is taken from this interpreter if importable,
else from $TAICHI_PYTHON (a python that has `taichi==1.7.4`). Ratios are simgrad / taichi.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
CASES = os.path.join(HERE, "cases.py")

# (label, case, metric, extra args, lower is better)
ROWS = [
    ("tiny kernel launch (us/call)", "launch", "launch_us", [], True),
    ("Python-scope x[None] access (us)", "pyscope", "pyscope_rw_us", [], True),
    ("saxpy 10M f32 (GB/s)", "saxpy", "saxpy_GBps", [], False),
    ("1M-particle P2G scatter (ms)", "scatter", "scatter_ms", [], True),
    ("cold compile diffmpm p2g (s)", "compile", "compile_p2g_s", [], True),
    ("cold compile p2g.grad (s)", "compile", "compile_p2g_grad_s", [], True),
    ("MPM p2g forward, 100k particles (ms)", "mpm_step", "p2g_fwd_ms", [], True),
    ("MPM p2g backward (ms)", "mpm_step", "p2g_bwd_ms", [], True),
    ("MPM p2g backward / forward", "mpm_step", "p2g_bwd_over_fwd", [], True),
    ("compute-bound kernel, 1 thread (ms)", "threads", "compute_ms", ["--threads", "1"], True),
    ("compute-bound kernel, 2 threads (ms)", "threads", "compute_ms", ["--threads", "2"], True),
]


def _env() -> dict:
    """Child environment: quiet taichi, and bytecode caching on as on a user's machine (this sandbox sets
    PYTHONDONTWRITEBYTECODE, which would charge every process for compiling our Python sources)."""
    env = dict(os.environ, TI_LOG_LEVEL="error")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def taichi_python() -> str | None:
    try:
        import taichi  # noqa: F401

        return sys.executable
    except ImportError:
        return os.environ.get("TAICHI_PYTHON")


def run_case(python: str, framework: str, case: str, extra: list[str]) -> dict:
    cmd = [python, CASES, "--framework", framework, "--case", case, *extra]
    env = _env()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"{framework}/{case} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")


def warm_start(python: str, framework: str) -> dict:
    """First-call times of the diffmpm p2g and its adjoint in a second process that finds the first one's
    disk cache."""
    with tempfile.TemporaryDirectory() as cache:
        run_case(python, framework, "compile", ["--cache", cache])
        return run_case(python, framework, "compile", ["--cache", cache])


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--case", action="append")
    p.add_argument("--markdown", action="store_true", help="print a table for RESULTS.md")
    args = p.parse_args()
    tpy = taichi_python()
    results: dict[tuple, dict] = {}
    rows = [r for r in ROWS if not args.case or r[1] in args.case]
    for _label, case, _metric, extra, _ in rows:
        for fw, py in (("simgrad", sys.executable), ("taichi", tpy)):
            key = (fw, case, tuple(extra))
            if py is None or key in results:
                continue
            try:
                results[key] = run_case(py, fw, case, extra)
            except Exception as e:  # a failing framework must not hide the other's numbers
                print(f"warning: {e}", file=sys.stderr)
                results[key] = {}
    table = []
    for label, case, metric, extra, _lower in rows:
        ours = results.get(("simgrad", case, tuple(extra)), {}).get(metric)
        theirs = results.get(("taichi", case, tuple(extra)), {}).get(metric)
        ratio = ours / theirs if ours is not None and theirs else None
        table.append((label, ours, theirs, ratio))
    if not args.case or "compile" in args.case:
        ours = warm_start(sys.executable, "simgrad")
        theirs = warm_start(tpy, "taichi") if tpy else {}
        for label, metric in (("warm start p2g, disk cache (s)", "compile_p2g_s"),
                              ("warm start p2g.grad, disk cache (s)", "compile_p2g_grad_s")):
            a, b = ours[metric], theirs.get(metric)
            table.append((label, a, b, a / b if b else None))
    one = results.get(("simgrad", "threads", ("--threads", "1")), {}).get("compute_ms")
    two = results.get(("simgrad", "threads", ("--threads", "2")), {}).get("compute_ms")
    t1 = results.get(("taichi", "threads", ("--threads", "1")), {}).get("compute_ms")
    t2 = results.get(("taichi", "threads", ("--threads", "2")), {}).get("compute_ms")
    if one and two:
        table.append(("speed-up 1 -> 2 threads", one / two, (t1 / t2) if t1 and t2 else None, None))

    def fmt(v):
        return "-" if v is None else f"{v:.3g}"

    header = "| case | simgrad | taichi | simgrad/taichi |\n|---|---|---|---|"
    lines = [f"| {label} | {fmt(a)} | {fmt(b)} | {fmt(r)} |" for label, a, b, r in table]
    print(f"{time.strftime('%Y-%m-%d')} on {platform.machine()} {os.cpu_count()} cores, "
          f"python {platform.python_version()}")
    print(header)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
