"""Checks the oracle, not simgrad: runs shapes.py's forward programs under real Taichi and compares them with
the Python/numpy reference (the same comparison as the campaign), with every function a ti.real_func
(Taichi 1.7.4 refuses `return` inside a non-static if/for of a ti.func; simgrad accepts both). Needs
Taichi, so it is no part of the suite; run it with the interpreter that has Taichi:

    /work/tivenv/bin/python tests/fuzz/taichi_check.py [first_seed] [count]

A disagreement here is a reference that does not mean what Taichi means (or a Taichi defect): read it
before trusting a quiet campaign.
"""

from __future__ import annotations

import pathlib
import sys
import tempfile
import traceback

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import shapes  # noqa: E402


def main() -> None:
    import taichi as ti

    first = int(sys.argv[1]) if len(sys.argv) > 1 else 0
    count = int(sys.argv[2]) if len(sys.argv) > 2 else 20
    counts = {"agree": 0, "disagree": 0, "taichi error": 0}
    for seed in range(first, first + count):
        size = 1 + seed % 8
        text, ref = shapes.forward_case(seed, size, all_real=True)
        with tempfile.TemporaryDirectory() as d:
            try:
                got = shapes.simgrad_outputs(text, seed, pathlib.Path(d), f"ti_k{seed}", ti=ti)
            except Exception:
                counts["taichi error"] += 1
                print(f"--- seed {seed} size {size}: Taichi failed\n{traceback.format_exc()[-1500:]}")
                continue
            want = shapes.reference_outputs(ref, seed, pathlib.Path(d), f"ti_r{seed}")
        try:
            shapes.compare(got, want)
            counts["agree"] += 1
        except AssertionError as e:
            counts["disagree"] += 1
            print(f"--- seed {seed} size {size} layout {shapes.layout_of(seed)}: Taichi != reference\n{text}\n{e}")
    print(counts)


if __name__ == "__main__":
    main()
