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

# sfwd:750:8 of the long run (benchmarks/fuzz_long.py --gen shapes), reduced by deleting statements and
# replacing selects/ternaries by a branch. LLVM 22.1 (llvmlite 0.50.0, a build with assertions) aborts in
# X86 instruction selection: "llvm::cast<MemSDNode>(SDNode*) ... Assertion `isa<To>(Val)' failed", the
# process dies with SIGABRT. The IR simgrad emits is valid (module.verify() passes, SIMGRAD_VERIFY=1
# passes); the optimised module crashes the backend only with loop unrolling on (runtime/jit.py's
# pipeline: speed 3 + unrolling crashes, speed 3 without unrolling or vectorisation emits fine; speed
# 3 + vectorisation without unrolling is fine too). Any cpu (host znver5 or generic).
# tests/fuzz/llvm_isel_memsdnode.ll is the backend's input reduced to 87 lines (no simgrad needed).
# Expected: prints the ndarray `ndo` (6 integers) and exits 0.
LLVM_ISEL_MEMSDNODE = '''
import simgrad as ti
ti.init(arch=ti.cpu, default_fp=ti.f64)
ai = ti.field(ti.i32, 4)
af = ti.field(ti.f64, 4)


@ti.func
def f0(u, v) -> ti.f64:
    r = u
    s = v
    for k1 in range(3):
        r = ti.select(k1 == ai[r % 4], ai[u % 4], ai[k1 % 4])
        if af[k1 % 4] < ti.select(-0.365 < (af[k1 % 4] if -0.956 >= v else af[u % 4]), ai[(k1 + u) % 4], k1) - \\
                ti.select(ai[k1 % 4] < ai[(k1 + k1) % 4], af[(k1 + u) % 4], af[k1 % 4]):
            r = k1 % (7 % 5 + 6) * ti.max(ai[(k1 + r) % 4], ti.select(ai[k1 % 4] <= ai[r % 4], ai[r % 4], ai[u % 4]))
        if (k1 + r) % 3 == 0:
            return s
    return 0.0


@ti.kernel
def main(nd: ti.types.ndarray(dtype=ti.i32, ndim=1), ndo: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    for t in range(4):
        a0 = ai[(t + 0) % 4]
        a1 = ai[(t + 1) % 4]
        a2 = ai[(t + 2) % 4]
        x0 = af[(t + 0) % 4]
        x1 = af[(t + 1) % 4]
        h = a1
        ndo[2 + t] = x1 * 100.0 // (ti.select(f0(a0 % (a2 % 5 + 6), x0) >= af[(a1 + a0) % 4], nd[a0 % 4],
                                              h >> 18) % 7 + 8)


nd, ndo = ti.ndarray(ti.i32, 4), ti.ndarray(ti.i32, 6)
main(nd, ndo)
print(ndo.to_numpy())
'''

REPRODUCERS = {"llvm_isel_memsdnode (sfwd:750:8)": LLVM_ISEL_MEMSDNODE}


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
