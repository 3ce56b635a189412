"""Defects the fuzzers found that are not fixed yet, for the lead: each is a whole program that must run and
print what its comment says. Not collected by pytest (a known failure must not look like a pass); run

    .venv/bin/python tests/fuzz/reproducers.py

which runs each in a child process (a crash must not stop the others) and says which still fail. When one
is fixed, move it into the suite as a regression test of the area that fixed it and delete it here.
"""

from __future__ import annotations

import pathlib
import subprocess
import sys
import tempfile

# (none open: sfwd:750:8, LLVM's X86 instruction selection abort, is guarded since 2026-11-26;
# tests/runtime/test_isel_guard.py)
REPRODUCERS: dict[str, str] = {}


def main() -> None:
    failing = 0
    for name, src in REPRODUCERS.items():
        with tempfile.TemporaryDirectory() as d:  # kernels need a source file
            file = pathlib.Path(d) / "repro.py"
            file.write_text(src)
            p = subprocess.run([sys.executable, str(file)], capture_output=True, text=True, timeout=600)
        ok = p.returncode == 0
        failing += not ok
        print(f"{name}: {'runs (fixed?)' if ok else f'FAILS, exit {p.returncode}'}\n  {(p.stderr or p.stdout)[-400:]}")
    print(f"{failing} of {len(REPRODUCERS)} still fail")


if __name__ == "__main__":
    main()
