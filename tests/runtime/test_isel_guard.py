"""runtime/isel_guard.py: the loads that LLVM 22's X86 instruction selection merges too late (a SIGABRT)
are pointed at one pointer before emission; the rewrite keeps every address and finds only that shape."""

import os
import pathlib
import subprocess
import sys

import llvmlite.binding as llvm

from simgrad.runtime.isel_guard import merge_same_address_loads

HERE = pathlib.Path(__file__).parent
EMIT = """
import sys, llvmlite.binding as llvm
llvm.initialize_native_target(); llvm.initialize_native_asmprinter()
m = llvm.parse_assembly(sys.stdin.read()); m.verify()
llvm.Target.from_default_triple().create_target_machine(opt=3).emit_object(m)
print("emitted")
"""

BLOCK = """define i32 @f(ptr %root, i32 %v) {
entry:
  %a = and i32 %v, 3
  %cv = zext nneg i32 %a to i64
  %s1 = shl nuw nsw i64 %cv, 2
  %p1 = getelementptr inbounds nuw i8, ptr %root, i64 %s1
  %l1 = load i32, ptr %p1, align 4
  %s2 = shl nsw i32 %v, 2
  %b = and i32 %s2, 12
  %z = zext nneg i32 %b to i64
  %p2 = getelementptr inbounds nuw i8, ptr %root, i64 %z
  %l2 = load i32, ptr %p2, align 4
  %r = add i32 %l1, %l2
  ret i32 %r
}
"""


def _emit_in_child(text: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", EMIT], input=text, capture_output=True, text=True, timeout=120)


def test_the_reduced_crash_emits_once_guarded():
    """The backend's input of fuzz case sfwd:750:8 (87 lines): guarded, it emits; the guard changed exactly
    one load, to the pointer of an earlier load of the same block."""
    text = (HERE / "llvm_isel_memsdnode.ll").read_text()
    guarded = merge_same_address_loads(text)
    assert guarded is not None
    changed = [(a, b) for a, b in zip(text.split("\n"), guarded.split("\n")) if a != b]
    assert changed == [("  %g.136 = load i32, ptr %ptr.135, align 4", "  %g.136 = load i32, ptr %ptr.154, align 4")]
    p = _emit_in_child(guarded)
    assert p.returncode == 0 and "emitted" in p.stdout, p.stderr[-500:]


def test_both_spellings_of_one_offset_in_one_block_share_a_pointer():
    guarded = merge_same_address_loads(BLOCK)
    assert guarded is not None and "%l2 = load i32, ptr %p1, align 4" in guarded
    llvm.parse_assembly(guarded).verify()


def test_other_shapes_are_left_alone():
    """Another block, another mask, another base, a mask with low bits under the shift: not the same address
    (or not one the X86 matcher rewrites), so the text comes back as None."""
    other_block = BLOCK.replace("  %s2 = shl nsw", "  br label %next\nnext:\n  %s2 = shl nsw")
    assert merge_same_address_loads(other_block) is None
    assert merge_same_address_loads(BLOCK.replace("%b = and i32 %s2, 12", "%b = and i32 %s2, 28")) is None
    assert merge_same_address_loads(BLOCK.replace("ptr %root, i64 %z", "ptr %v2, i64 %z")
                                    .replace("(ptr %root, i32 %v)", "(ptr %root, i32 %v, ptr %v2)")) is None
    assert merge_same_address_loads(BLOCK.replace("%b = and i32 %s2, 12", "%b = and i32 %s2, 13")) is None


# fuzz case sfwd:750:8 reduced: every field is zero, so ndo is 0 // (...) = 0 everywhere
PROGRAM = """
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
"""


def test_the_reduced_program_runs(tmp_path):
    """The program whose -O3 code (with loop unrolling) crashed the backend, run in a child: it died with
    SIGABRT."""
    file = tmp_path / "repro.py"
    file.write_text(PROGRAM)
    env = dict(os.environ, SIMGRAD_CACHE_DIR=str(tmp_path / "cache"))  # compiled here, not found on disk
    p = subprocess.run([sys.executable, str(file)], capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 0, (p.returncode, p.stderr[-800:])
    assert p.stdout.split() == ["[0", "0", "0", "0", "0", "0]"]
