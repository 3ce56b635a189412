"""LLVM emission: the op table, the target split, and the text of small kernels (golden,
tests/codegen/golden; rewrite with `pytest tests/codegen --update-golden` and review the diff)."""

import subprocess
import sys

import numpy as np
from irkit import atomic_add, new_kernel, parallel_for, ptr, store

import simgrad as ti
from simgrad import dtypes as dt
from simgrad.codegen.cpu import CpuCodegen
from simgrad.codegen.llvm import LOWERING
from simgrad.ir.ops import Op
from simgrad.passes.manager import run_pipeline
from simgrad.runtime.jit import get_jit


def test_every_op_has_a_lowering():
    assert set(LOWERING) == set(Op)


def test_shared_codegen_and_analyses_import_no_cpu_code():
    """A second target (NVPTX) reuses codegen/llvm.py and the strategy pass without the CPU target."""
    code = ("import sys; import simgrad.codegen.llvm, simgrad.passes.parallel_strategy; "
            "bad = [m for m in ('simgrad.codegen.cpu', 'simgrad.codegen.privatize', 'simgrad.runtime.threadpool') "
            "if m in sys.modules]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def _llvm(k, debug=False) -> str:
    run_pipeline(k, debug=debug)
    text = CpuCodegen(k, "sg_kernel", debug=debug).generate()
    get_jit().object_for(text)  # valid LLVM IR that compiles
    return text


def test_fill_kernel_text(golden):
    """y[i] = x * i over a parallel loop: one task; y[i] is addressed affinely in the loop index."""
    y = ti.field(ti.f32, shape=16, name="y")
    k, b = new_kernel("fill")
    x = b.emit(Op.ARG, dt.f32, (), {"slot": 0})
    loop = parallel_for(b, 16)
    with b.inside(loop.blocks[0]):
        store(b, ptr(b, y, loop), b.binary(Op.MUL, x, b.cast(loop, dt.f32)))
    text = _llvm(k)
    assert "define internal void @sg_kernel_task1(ptr %clo, i64 %lo, i64 %hi, i32 %tid)" in text
    assert "atomicrmw" not in text and "udiv" not in text
    golden.check("fill.ll", text)


def _scatter_kernel():
    """grid_v[i % 8] += (1, 2); grid_m[i % 8] += 1; total[None] += 1 over 64 iterations."""
    grid_v = ti.Vector.field(2, ti.f32, shape=8, name="grid_v")
    grid_m = ti.field(ti.f32, shape=8, name="grid_m")
    total = ti.field(ti.f32, shape=(), name="total")
    k, b = new_kernel("scatter")
    one, two = b.const(1.0, dt.f32), b.const(2.0, dt.f32)
    loop = parallel_for(b, 64)
    with b.inside(loop.blocks[0]):
        cell = b.binary(Op.MOD, loop, b.const(8, dt.i32))
        atomic_add(b, ptr(b, grid_v.comps[0], cell), one)
        atomic_add(b, ptr(b, grid_v.comps[1], cell), two)
        atomic_add(b, ptr(b, grid_m, cell), one)
        atomic_add(b, ptr(b, total), one)
    return k, (grid_v, grid_m, total)


def test_scatter_kernel_text_has_every_strategy(golden):
    k, _fields = _scatter_kernel()
    text = _llvm(k)
    task = text.split("define internal void @sg_kernel_task1(")[1].split("\n}\n")[0]
    private = text.split("define internal void @sg_kernel_task1_private(")[1].split("\n}\n")[0]
    assert "cmpxchg ptr" in task and task.count("atomicrmw") == 2  # the pair; grid_m; total's chunk sum
    assert "cmpxchg" not in private and private.count("atomicrmw") == 1  # copies: plain adds; total
    assert "alloca float" in task  # total's per-thread partial sum
    golden.check("scatter.ll", text)


def test_scatter_kernel_debug_text_pairs_nothing():
    k, _fields = _scatter_kernel()
    text = _llvm(k, debug=True)
    assert "cmpxchg ptr %" not in text.split("define internal void @sg_report")[0]


def test_scatter_kernel_runs():
    """The emitted kernel, launched: every strategy adds the right amounts."""
    grid_v = ti.Vector.field(2, ti.f32, shape=8)
    grid_m = ti.field(ti.f32, shape=8)
    total = ti.field(ti.f32, shape=())

    @ti.kernel
    def scatter():
        for i in range(64):
            grid_v[i % 8] += ti.Vector([1.0, 2.0])
            grid_m[i % 8] += 1.0
            total[None] += 1.0

    scatter()
    np.testing.assert_array_equal(grid_v.to_numpy(), np.tile([8.0, 16.0], (8, 1)))
    np.testing.assert_array_equal(grid_m.to_numpy(), np.full(8, 8.0))
    assert total[None] == 64.0
