"""Run Taichi's own sparse-SNode example programs unmodified under simgrad and under taichi, side by side.

    python benchmarks/sparse_examples.py --taichi-git /path/to/taichi/.git [--tag v1.7.4] [--frames 20]
                                         [--taichi-python PATH]

The programs (python/taichi/examples/features/sparse/*.py, and the taichi_logo pattern one of them imports)
are read from a taichi clone's git history into a temporary folder; nothing of theirs is in this repository.
Each runs in a fresh process per framework with ti.GUI headless: its loop ends after --frames shown frames
(the last one is saved). Prints per program: both exit codes, whether stdout agrees, the largest pixel
difference of the last frame, and wall seconds for each.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

EXAMPLES = ["explicit_activation", "taichi_bitmasked", "taichi_dynamic", "taichi_sparse", "tutorial"]

RUNNER = r'''
import importlib.util, os, runpy, sys, types
framework, path, frames, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
if framework == "simgrad":
    import simgrad
    sys.modules["taichi"] = simgrad
    pkg = types.ModuleType("taichi.examples")
    pkg.__path__ = []
    sys.modules["taichi.examples"] = pkg
    spec = importlib.util.spec_from_file_location("taichi.examples.patterns",
                                                  os.path.join(os.path.dirname(path), "patterns.py"))
    mod = importlib.util.module_from_spec(spec)
    sys.modules["taichi.examples.patterns"] = mod
    spec.loader.exec_module(mod)
import taichi as ti


class HeadlessGUI(ti.GUI):
    shown = 0

    def __init__(self, *args, **kwargs):
        kwargs["show_gui"] = False
        super().__init__(*args, **kwargs)

    @property
    def running(self):
        return HeadlessGUI.shown < frames

    @running.setter
    def running(self, value):
        pass

    def show(self, file=None):
        HeadlessGUI.shown += 1
        last = HeadlessGUI.shown >= frames
        super().show(out if last else None)
        if last:
            raise SystemExit(0)


ti.GUI = HeadlessGUI
sys.argv = [path]
runpy.run_path(path, run_name="__main__")
'''


def _run(python: str, framework: str, runner: str, path: str, frames: int, out: str) -> tuple[int, str, float]:
    t = time.perf_counter()
    p = subprocess.run([python, runner, framework, path, str(frames), out], capture_output=True, text=True,
                       timeout=600)
    lines = [ln for ln in p.stdout.splitlines() if not ln.startswith("[Taichi]")]
    return p.returncode, "\n".join(lines), time.perf_counter() - t


def _pixel_diff(a: str, b: str) -> str:
    if not (os.path.exists(a) and os.path.exists(b)):
        return "-"
    import imageio.v3 as iio
    import numpy as np

    x, y = iio.imread(a).astype(int), iio.imread(b).astype(int)
    return "shape differs" if x.shape != y.shape else str(int(np.abs(x - y).max()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--taichi-git", required=True, help="the .git directory of a taichi clone")
    ap.add_argument("--tag", default="v1.7.4")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON", "/work/tivenv/bin/python"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        runner = os.path.join(tmp, "run.py")
        with open(runner, "w") as f:
            f.write(RUNNER)
        for name in ["patterns"] + EXAMPLES:
            where = "patterns.py" if name == "patterns" else f"features/sparse/{name}.py"
            src = subprocess.run(["git", f"--git-dir={args.taichi_git}", "show",
                                  f"{args.tag}:python/taichi/examples/{where}"],
                                 capture_output=True, text=True, check=True).stdout
            with open(os.path.join(tmp, f"{name}.py"), "w") as f:
                f.write(src)
        print("| program | exit (simgrad / taichi) | stdout agrees | last frame max pixel diff | seconds (simgrad / "
              "taichi) |")
        print("|---|---|---|---|---|")
        for name in EXAMPLES:
            path = os.path.join(tmp, f"{name}.py")
            frames = [os.path.join(tmp, f"{name}.{fw}.png") for fw in ("simgrad", "taichi")]
            rs, outs, ts = _run(sys.executable, "simgrad", runner, path, args.frames, frames[0])
            rt, outt, tt = _run(args.taichi_python, "taichi", runner, path, args.frames, frames[1])
            print(f"| {name} | {rs} / {rt} | {'yes' if outs == outt else 'NO'} | {_pixel_diff(*frames)} | "
                  f"{ts:.2f} / {tt:.2f} |", flush=True)


if __name__ == "__main__":
    main()
