"""Runs the unmodified DiffTaichi programs under simgrad and under taichi, side by side.

    python benchmarks/originals.py --difftaichi PATH [--only NAME ...] [--iters 5] [--json FILE] [--readme]

PATH is a checkout of taichi-dev/difftaichi; nothing of it is copied into this repository. Each
(framework, program) runs in a fresh child process inside its own temporary directory, which holds a copy
of DiffTaichi's examples/ folder (the programs read their images and robot configs from the working
directory) and generated stand-ins for files a program would download. The child

- makes `import taichi` resolve to simgrad (`sys.modules["taichi"] = simgrad`) or to the real taichi,
- wraps `ti.init` to pick the CPU and an empty offline cache in the temp dir (compile time is measured),
- wraps `ti.GUI` with `show_gui=False` (and `GUI.line` flattens its two points to floats: rigid_body.py
  passes (2, 1) arrays, which taichi 1.7.4's canvas rejects under numpy 2), turns cv2's window calls
  into no-ops, uses matplotlib's Agg backend,
- seeds `random` and `numpy.random` with 0 before running the program (the same draws for both
  frameworks; only diffmpm3d draws random numbers inside a kernel, `ti.randn()`, marked random below),
- gives taichi 1.7.4 `ti.clear_all_gradients = ti.ad.clear_all_gradients` (liquid.py calls the removed name),
- timestamps every stdout line.

The only edits to a program's text are in PROGRAMS below: iteration counts where the program has no
--iters option, and the ones listed with a reason (electric prints its loss only every 200 iterations;
water_renderer's VGG loss becomes its own L2 `compute_loss`). From the timestamped loss lines:
"first" is the time from the program's first line to its first loss line (compile included, framework
import excluded and reported separately); "s/iter" is the steady cost, (t[last] - t[1]) / (n - 2) over the
n loss lines. Losses of the two frameworks are compared over the first 3 iterations (relative difference).

Children need cv2 and imageio for some programs (`pip install simgrad[originals]`, or
`pip install --target DIR opencv-python-headless imageio` and `--pythonpath DIR`, which serves both
interpreters). taichi comes from --taichi-python or $TAICHI_PYTHON.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
README = os.path.join(ROOT, "examples", "README.md")
BEGIN, END = "<!-- originals:begin -->", "<!-- originals:end -->"
COMPARED = 3  # iterations whose losses are compared
TOLERANCE = 1e-4  # relative, for deterministic programs
# a framework name for simgrad with the Tape's captured backward pass off (lang/tape.py), to show what it buys
NO_CAPTURE = "simgrad-nocapture"


@dataclass
class Program:
    """One run of one DiffTaichi script. `argv` and patch replacements may contain {iters}."""

    name: str
    script: str
    argv: list[str] = field(default_factory=list)
    # (regex, replacement, why): each must match exactly once in the script's text
    patches: list[tuple[str, str, str]] = field(default_factory=list)
    slow: bool = False  # 3-D: taichi compiles for minutes; run last
    random: str = ""  # why the two frameworks' losses differ by design; then only "learns" is compared
    note: str = ""


ITERS = "iteration count"
PROGRAMS = [
    Program("mass_spring_simple", "mass_spring_simple.py",
            patches=[(r"for iter in range\(25\)", "for iter in range({iters})", ITERS)]),
    *[Program(f"mass_spring {r}", "mass_spring.py", [str(r), "train", "--iters", "{iters}"]) for r in range(4)],
    Program("mass_spring_interactive 0", "mass_spring_interactive.py", ["0", "--iters", "{iters}"]),
    Program("billiards", "billiards.py",
            patches=[(r"for iter in range\(200\)", "for iter in range({iters})", ITERS)]),
    *[Program(f"rigid_body {r}", "rigid_body.py", [str(r), "train"],
              patches=[(r"for iter in range\(20\)", "for iter in range({iters})", ITERS)]) for r in range(3)],
    Program("electric", "electric.py",
            patches=[(r"for iter in range\(200000\)", "for iter in range({iters})", ITERS),
                     (r"# (print\(iter, \"loss\", loss\[None\]\))", r"\1",
                      "uncomment the program's own per-iteration loss print (it prints a sum every 200)")]),
    Program("wave", "wave.py", ["--iters", "{iters}"]),
    Program("smoke_taichi", "smoke_taichi.py", ["--iters", "{iters}"]),
    Program("smoke_taichi_cpu", "smoke_taichi_cpu.py", ["--iters", "{iters}"]),
    Program("smoke_taichi_gpu", "smoke_taichi_gpu.py", ["--iters", "{iters}"], note="arch falls back to cpu"),
    Program("diffmpm_simple", "diffmpm_simple.py",
            patches=[(r"for i in range\(30\)", "for i in range({iters})", ITERS)]),
    Program("diffmpm", "diffmpm.py", ["--iters", "{iters}"]),
    Program("diffmpm_checkpointing", "diffmpm_checkpointing.py", ["--iters", "{iters}"]),
    Program("diffmpm_benchmark", "diffmpm_benchmark.py",
            patches=[(r"iters = 100000", "iters = 10", "kernel-timing loop count of benchmark()"),
                     (r"for i in range\(30\)", "for i in range({iters})", ITERS)]),
    Program("volume_renderer", "volume_renderer.py", ["--iters", "{iters}"],
            note="bunny_128.bin is a generated stand-in of the same shape"),
    Program("water_renderer (L2)", "water_renderer.py",
            patches=[(r"\n *from adversarial import vgg_grad, predict\n", "\n",
                      "L2 variant: no VGG (its weights cannot be downloaded here)"),
                     (r"(\n *forward\(\)\n *)vgg_predict\(\)\n", r"\1compute_loss(steps - 1)\n",
                      "L2 variant: the program's own compute_loss instead of the VGG loss"),
                     (r"print\('Iter', opt\)", "print('Iter', opt, ' Loss =', loss[None])",
                      "L2 variant: print the loss"),
                     (r"for opt in range\(10\)", "for opt in range({iters})", ITERS)]),
    Program("diffmpm3d", "diffmpm3d.py", ["--iters", "{iters}"], slow=True,
            random="weights drawn with ti.randn() in a kernel"),
    Program("liquid", "liquid.py", patches=[(r"for iter in range\(501\)", "for iter in range({iters})", ITERS)],
            slow=True, note="ti.clear_all_gradients shimmed for taichi"),
]

LOSS = re.compile(r"\b[Ll]oss\s*=?\s*([-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|nan|inf))")


# ---------------------------------------------------------------------------------------------- child
class _Stamped:
    """stdout replacement: every complete line goes out as '@@<seconds since t0> <line>'."""

    def __init__(self, stream):
        self.stream, self.buf, self.t0 = stream, "", time.perf_counter()

    def write(self, s):
        self.buf += s
        while "\n" in self.buf:
            line, self.buf = self.buf.split("\n", 1)
            self.stream.write(f"@@{time.perf_counter() - self.t0:.6f} {line}\n")
            self.stream.flush()
        return len(s)

    def flush(self):
        self.stream.flush()

    def close_line(self):
        if self.buf:
            self.write("\n")

    def isatty(self):
        return False


def _headless(ti, cache_dir, extra_init):
    """The GUI, arch and cache patches, applied to the framework module (not to the program's text)."""
    import numpy as np

    init = ti.init

    def cpu_init(*args, **kw):
        kw["arch"] = getattr(ti, os.environ.get("ORIGINALS_ARCH", "cpu"))  # --arch (cuda: the GPU side by side)
        kw.setdefault("offline_cache_file_path", cache_dir)
        kw.update(extra_init)
        return init(*args[1:], **kw) if args else init(**kw)

    ti.init = cpu_init
    gui_cls = ti.GUI

    class HeadlessGUI(gui_cls):
        def __init__(self, *args, **kw):
            if len(args) > 3:
                args = args[:3] + (False,) + args[4:]
            else:
                kw["show_gui"] = False
            super().__init__(*args, **kw)

        def line(self, begin, end, *args, **kw):
            # rigid_body.py passes (2, 1) column arrays; under numpy 2 taichi 1.7.4's canvas rejects them
            flat = [tuple(float(c) for c in np.asarray(p, dtype=np.float64).reshape(-1)) for p in (begin, end)]
            return super().line(*flat, *args, **kw)

    ti.GUI = HeadlessGUI
    if not hasattr(ti, "clear_all_gradients"):  # removed in taichi 1.x; liquid.py calls it
        ti.clear_all_gradients = ti.ad.clear_all_gradients
    try:
        import cv2
    except ImportError:
        return
    for name in ("imshow", "namedWindow", "destroyAllWindows", "destroyWindow", "moveWindow"):
        setattr(cv2, name, lambda *a, **k: None)
    cv2.waitKey = lambda *a, **k: -1


def child(framework, script, argv):
    import random
    import runpy

    out = _Stamped(sys.stdout)
    sys.stdout = out
    if framework == "taichi":
        import taichi as ti
    else:
        import simgrad as ti
        sys.modules["taichi"] = ti
        if framework == NO_CAPTURE:  # the before of the captured backward pass: every adjoint launched from Python
            import simgrad.lang.tape

            simgrad.lang.tape._backward_sequence = lambda entries: None
    print(f"@import {time.perf_counter() - out.t0:.6f}")
    extra = json.loads(os.environ.get("ORIGINALS_INIT", "{}")) if framework == "taichi" else {}
    _headless(ti, os.path.join(os.getcwd(), ".cache"), extra)
    import numpy as np

    random.seed(0)
    np.random.seed(0)
    sys.argv = [script, *argv]
    sys.path.insert(0, os.getcwd())
    print("@start")
    try:
        runpy.run_path(os.path.abspath(script), run_name="__main__")
    finally:
        out.close_line()
        sys.stdout.flush()


# --------------------------------------------------------------------------------------------- parent
def _standins(work):
    """Files a program would download: volume_renderer's 128^3 float32 density (bunny_128.bin). The
    stand-in is a bunny-like union of ellipsoids with the value the program's own torus uses (1/128)."""
    import numpy as np

    n = 128
    z, y, x = np.meshgrid(*(np.linspace(-0.5, 0.5, n, dtype=np.float32),) * 3, indexing="ij")
    blobs = [((0.0, -0.12, 0.0), (0.28, 0.2, 0.22)), ((0.16, 0.12, 0.0), (0.13, 0.13, 0.12)),
             ((0.2, 0.32, 0.05), (0.04, 0.12, 0.04)), ((0.12, 0.32, -0.05), (0.04, 0.12, 0.04))]
    inside = np.zeros((n, n, n), bool)
    for (cx, cy, cz), (rx, ry, rz) in blobs:
        inside |= ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 + ((z - cz) / rz) ** 2 < 1
    (inside.astype(np.float32) / n).tofile(os.path.join(work, "bunny_128.bin"))


def prepare(prog, difftaichi, iters):
    """Temp dir with DiffTaichi's examples/ and the patched script; returns (dir, argv)."""
    work = tempfile.mkdtemp(prefix="originals-")
    src = os.path.join(difftaichi, "examples")
    for f in os.listdir(src):
        if os.path.isfile(os.path.join(src, f)):
            shutil.copy(os.path.join(src, f), work)
    path = os.path.join(work, prog.script)
    with open(path) as fh:
        text = fh.read()
    for pattern, repl, why in prog.patches:
        text, n = re.subn(pattern, repl.replace("{iters}", str(iters)), text)
        if n != 1:
            raise RuntimeError(f"{prog.name}: patch {pattern!r} ({why}) matched {n} times")
    with open(path, "w") as fh:
        fh.write(text)
    if prog.script == "volume_renderer.py":
        _standins(work)
    return work, [a.replace("{iters}", str(iters)) for a in prog.argv]


def _error(stderr):
    """(first line of the final exception, the innermost frames in the program and in simgrad)."""
    lines = stderr.splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("Traceback (most recent call last)")]
    if not starts:
        tail = [line for line in lines if line.strip()]
        return (tail[-1] if tail else "no output"), None, None
    block = lines[starts[-1] + 1:]
    at = next((i for i, line in enumerate(block) if line and not line[0].isspace()), None)
    exc = "?" if at is None else block[at]
    rest = [line.strip() for line in block[at + 1:] if line.strip()] if at is not None else []
    if rest:  # simgrad's located errors: 'Error: File "x", line n:' / source / caret / message
        exc += " … " + rest[-1]
    frames = [line.strip() for line in block if line.strip().startswith("File ")]
    prog = next((f for f in reversed(frames) if f.startswith('File "') and "/" not in f.split('"')[1]), None)
    lib = next((f for f in reversed(frames) if "/simgrad/" in f or "/taichi/" in f), None)
    return exc, prog, lib


def run_one(python, framework, prog, args, pythonpath):
    work, argv = prepare(prog, args.difftaichi, args.iters)
    env = dict(os.environ, MPLBACKEND="Agg", TI_LOG_LEVEL="error", TI_GUI_SHOW="0")
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as on a user's machine: our .py files are not recompiled
    env["ORIGINALS_INIT"] = json.dumps(args.taichi_init)
    env["ORIGINALS_ARCH"] = args.arch
    env["PYTHONPATH"] = os.pathsep.join(p for p in [args.simgrad_path if framework != "taichi" else "", *pythonpath,
                                                     os.environ.get("PYTHONPATH", "")] if p)
    cmd = [python, os.path.abspath(__file__), "--child", framework, prog.script, "--", *argv]
    if args.nice:
        cmd = ["nice", "-n", str(args.nice), *cmd]
    t = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=args.timeout)
        rc, stdout, stderr = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as e:
        rc, stdout, stderr = "timeout", _text(e.stdout), _text(e.stderr) + f"\nTimeout: over {args.timeout} s"
    wall = time.perf_counter() - t
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    res = {"rc": rc, "wall_s": wall, "losses": [], "times": [], "import_s": None}
    start = 0.0
    for line in stdout.splitlines():
        m = re.match(r"@@(\S+) (.*)", line)
        if not m:
            continue
        ts, text = float(m.group(1)), m.group(2)
        if text.startswith("@import "):
            res["import_s"] = float(text.split()[1])
        elif text == "@start":
            start = ts
        elif (lm := LOSS.search(text)):
            res["losses"].append(float(lm.group(1)))
            res["times"].append(ts - start)
    n = len(res["times"])
    res["first_s"] = res["times"][0] if n else None
    res["sec_per_iter"] = (res["times"][-1] - res["times"][1]) / (n - 2) if n >= 3 else None
    if rc != 0:
        stderr = stderr.replace(work + os.sep, "")  # the program's file by its own name
        res["error"], res["at_program"], res["at_library"] = _error(stderr)
        res["stderr_tail"] = stderr[-3000:]
    return res


def _keyval(s):
    key, _, value = s.partition("=")
    return key, json.loads(value.lower()) if value.lower() in ("true", "false") else json.loads(value)


def _text(b):
    return b.decode(errors="replace") if isinstance(b, bytes) else (b or "")


# ---------------------------------------------------------------------------------------------- table
def compare(s, t):
    """Max relative loss difference over the first COMPARED iterations both printed."""
    k = min(COMPARED, len(s["losses"]), len(t["losses"]))
    if k == 0:
        return None
    return max(abs(a - b) / max(abs(b), 1e-30) for a, b in zip(s["losses"][:k], t["losses"][:k]))


def _fmt(x, spec=".3g"):
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def _secs(r):
    return f"{r['first_s']:.3g} s" if r and r["first_s"] is not None else "-"


def _status(r):
    if r is None:
        return "not run"
    if r["rc"] == 0:
        return "ok"
    return f"fails: `{r.get('error', '?')[:240]}`".replace("|", "\\|")


def _learns(r):
    ls = r["losses"] if r else []
    return "-" if len(ls) < 2 else ("yes" if ls[-1] < ls[0] else "no")


def table(results):
    head = ("| program | iters | loss first → last (simgrad) | max rel. diff vs taichi (first 3) | learns (s / t) "
            "| simgrad s/iter | taichi s/iter | ratio | first iteration (simgrad / taichi) | simgrad | taichi |")
    rows = [head, "|" + "---|" * (head.count("|") - 1)]
    for prog in PROGRAMS:
        entry = results.get(prog.name)
        if not entry:
            continue
        s, t = entry.get("simgrad"), entry.get("taichi")
        diff = compare(s, t) if s and t else None
        ok = "" if diff is None else (" ✓" if diff <= TOLERANCE else " ✗")
        agreement = f"random ({prog.random})" if prog.random else f"{_fmt(diff, '.1e')}{ok}"
        sl = s["losses"] if s else []
        losses = f"{sl[0]:.5g} → {sl[-1]:.5g}" if sl else "-"
        ratio = (s["sec_per_iter"] / t["sec_per_iter"]) if s and t and s["sec_per_iter"] and t["sec_per_iter"] \
            else None
        name = prog.name + (f" ({prog.note})" if prog.note else "")
        rows.append(
            f"| {name} | {entry.get('iters', '-')} | {losses} | {agreement} "
            f"| {_learns(s)} / {_learns(t)} "
            f"| {_fmt(s and s['sec_per_iter'])} | {_fmt(t and t['sec_per_iter'])} | {_fmt(ratio, '.2f')} "
            f"| {_secs(s)} / {_secs(t)} | {_status(s)} | {_status(t)} |")
    return "\n".join(rows)


def write_readme(results, when):
    with open(README) as fh:
        text = fh.read()
    block = f"{BEGIN}\n_Measured {when}._\n\n{table(results)}\n{END}"
    if BEGIN in text:
        text = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    with open(README, "w") as fh:
        fh.write(text)


# ----------------------------------------------------------------------------------------------- main
def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        framework, script = sys.argv[2], sys.argv[3]
        child(framework, script, sys.argv[5:])
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--difftaichi", required=True, help="checkout of taichi-dev/difftaichi")
    ap.add_argument("--only", nargs="*", help="program names (as in the table), e.g. billiards 'mass_spring 2'")
    ap.add_argument("--skip-slow", action="store_true", help="leave out the 3-D programs")
    ap.add_argument("--frameworks", default="simgrad,taichi",
                    help=f"comma-separated: simgrad, taichi, {NO_CAPTURE} (simgrad, the Tape's backward from Python)")
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--arch", default="cpu", choices=["cpu", "cuda"],
                    help="the arch every program's ti.init gets, in both frameworks (cuda: on a GPU machine, with "
                         "SIMGRAD_CUDA_RUNTIME=1 for simgrad's runtime)")
    ap.add_argument("--simgrad-python", default=sys.executable)
    ap.add_argument("--simgrad-path", default=ROOT, help="directory holding the simgrad package to test")
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON", sys.executable))
    ap.add_argument("--pythonpath", action="append", default=[], help="extra path for both children (cv2...)")
    ap.add_argument("--taichi-init", type=_keyval, action="append", default=[],
                    help="extra ti.init argument for taichi, e.g. fast_math=False (taichi's default is True)")
    ap.add_argument("--timeout", type=float, default=1800)
    ap.add_argument("--nice", type=int, default=0)
    ap.add_argument("--keep", action="store_true", help="keep the temp dirs")
    ap.add_argument("--json", help="results file; merged with what it already holds")
    ap.add_argument("--readme", action="store_true", help="write the table into examples/README.md")
    ap.add_argument("--table-only", action="store_true", help="run nothing: the table from --json")
    args = ap.parse_args()
    args.taichi_init = dict(args.taichi_init)
    results = {}
    if args.json and os.path.exists(args.json):
        with open(args.json) as fh:
            results = json.load(fh)
    progs = [p for p in PROGRAMS if (not args.only or p.name in args.only) and not args.table_only]
    if args.skip_slow:
        progs = [p for p in progs if not p.slow]
    progs.sort(key=lambda p: p.slow)
    pythons = {"simgrad": args.simgrad_python, NO_CAPTURE: args.simgrad_python, "taichi": args.taichi_python}
    for prog in progs:
        entry = results.setdefault(prog.name, {})
        entry["iters"] = args.iters
        for fw in args.frameworks.split(","):
            r = run_one(pythons[fw], fw, prog, args, args.pythonpath)
            entry[fw] = r
            print(f"{prog.name:28s} {fw:8s} rc={r['rc']} first={_fmt(r['first_s'])} s/iter="
                  f"{_fmt(r['sec_per_iter'])} losses={[float(f'{x:.6g}') for x in r['losses']]}"
                  + (f"\n    {r['error']}\n    {r['at_program']}\n    {r['at_library']}" if r["rc"] else ""),
                  flush=True)
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(results, fh, indent=1)
    print(table(results))
    if args.readme:
        write_readme(results, time.strftime("%Y-%m-%d %H:%M"))


if __name__ == "__main__":
    main()
