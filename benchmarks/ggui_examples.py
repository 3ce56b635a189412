"""Run Taichi's own GGUI examples unmodified under simgrad, headless, for a few frames each.

    python benchmarks/ggui_examples.py --taichi-git /path/to/taichi/.git [--tag v1.7.4] [--frames 5] [--out DIR]

The examples are read from a taichi checkout's git history (nothing of theirs is in this repository) into a
temporary folder. Each runs in a fresh process where ``import taichi`` (and ``taichi.math``) is simgrad, with
``SIMGRAD_UI_MAX_FRAMES`` ending its ``while window.running`` loop and, with ``--out``, ``SIMGRAD_UI_FRAMES``
recording its frames and a GIF. Prints one line per example: ok / the error's last line, and seconds.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

EXAMPLES = ["mpm3d_ggui", "fem128_ggui", "mass_spring_3d_ggui", "mpm128_ggui", "stable_fluid_ggui",
            "fractal3d_ggui", "mass_spring_game_ggui"]

RUNNER = r'''
import runpy, sys
import simgrad
sys.modules["taichi"] = simgrad
sys.modules["taichi.math"] = simgrad.math
path = sys.argv[1]
sys.argv = [path]
runpy.run_path(path, run_name="__main__")
'''


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--taichi-git", required=True, help="the .git directory of a taichi clone")
    ap.add_argument("--tag", default="v1.7.4")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--out", default=None, help="record each example's frames under OUT/<example>")
    ap.add_argument("--only", nargs="*", default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        runner = os.path.join(tmp, "run.py")
        with open(runner, "w") as f:
            f.write(RUNNER)
        for name in args.only or EXAMPLES:
            src = subprocess.run(["git", f"--git-dir={args.taichi_git}", "show",
                                  f"{args.tag}:python/taichi/examples/ggui_examples/{name}.py"],
                                 capture_output=True, text=True, check=True).stdout
            path = os.path.join(tmp, f"{name}.py")
            with open(path, "w") as f:
                f.write(src)
            env = dict(os.environ, SIMGRAD_UI_MAX_FRAMES=str(args.frames))
            env.pop("DISPLAY", None)
            env.pop("WAYLAND_DISPLAY", None)
            if args.out:
                env["SIMGRAD_UI_FRAMES"] = os.path.join(os.path.abspath(args.out), name)
            t0 = time.time()
            proc = subprocess.run([sys.executable, runner, path], cwd=tmp, env=env, capture_output=True, text=True)
            seconds = time.time() - t0
            err = (proc.stderr.strip().splitlines() or ["?"])[-1]
            status = "ok" if proc.returncode == 0 else f"FAILED: {err}"
            print(f"{name:24s} {status}  ({seconds:.1f} s for {args.frames} frames incl. compile)", flush=True)


if __name__ == "__main__":
    main()
