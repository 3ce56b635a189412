"""benchmarks/ggui_frame.py at toy size: every case renders and is reported (no timing is checked), and the
saved frames show the particles, the mesh and the 2-D primitives."""

import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")


def test_ggui_frame_benchmark_runs_every_case(tmp_path):
    out = subprocess.run(
        [sys.executable, os.path.join(ROOT, "benchmarks", "ggui_frame.py"), "--frames", "1", "--res", "96", "72",
         "--particles", "2000", "--triangles", "800", "--circles", "500", "--triangles2d", "50", "--lines", "50",
         "--save", str(tmp_path / "frame")],
        capture_output=True, text=True, check=True, env=dict(os.environ, DISPLAY=""),
    ).stdout
    results = json.loads(out.strip().splitlines()[-1])
    cases_2d = ("circles", "triangles2d", "lines", "all2d")
    timed_2d = {f"{c} {path}" for c in cases_2d for path in ("kernels", "numpy")}
    assert set(results) == {"particles", "mesh", "both"} | timed_2d
    assert all(r["median_ms"] > 0 for r in results.values())
    from PIL import Image

    def pixels(case):
        with Image.open(tmp_path / f"frame_{case}.png") as im:
            return np.asarray(im.convert("RGB"))

    white = np.array([255, 255, 255])
    drawn = {case: (pixels(case) != white).any(-1).sum() for case in ("particles", "mesh", "both") + cases_2d}
    assert all(drawn[c] > 20 for c in cases_2d) and drawn["all2d"] >= drawn["circles"]
    assert drawn["particles"] > 100 and drawn["mesh"] > 100
    assert drawn["both"] >= max(drawn["particles"], drawn["mesh"])
