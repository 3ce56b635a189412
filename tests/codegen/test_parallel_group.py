"""A parallel loop's task marks its field loads and stores with an access group that the loop's
`llvm.loop.parallel_accesses` names (codegen/llvm.py parallel_group): iterations share no element but through
atomics, so LLVM needs no run-time overlap checks. Without it a G2P-style loop (reads of a grid at indices
computed from particle positions, stores to the particles) was not vectorised ("cannot identify array
bounds"): diffmpm3d's g2p 2.6 -> 1.6 ms. Only a loop whose iterations store to no element another reads or
stores gets it (LoopStrategy.independent; tests/lang/test_dependent_iterations.py); its updates (plain ones too),
the tape and locals stay outside the group, so a loop with any of them is left to LLVM's own analysis."""

import re

import numpy as np
import pytest

import simgrad as ti
import simgrad.codegen.llvm as llvm
from simgrad.runtime.jit import get_jit

NP = 1000
NG = 16


def _g2p():
    x = ti.Vector.field(3, ti.f32, shape=NP)
    v = ti.Vector.field(3, ti.f32, shape=NP)
    grid = ti.Vector.field(3, ti.f32, shape=(NG, NG, NG))

    @ti.kernel
    def g2p():
        for p in x:
            base = ti.cast(x[p] * NG - 0.5, ti.i32)
            fx = x[p] * NG - ti.cast(base, ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.Vector([0.0, 0.0, 0.0])
            for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
                new_v += w[i][0] * w[j][1] * w[k][2] * grid[base[0] + i, base[1] + j, base[2] + k]
            v[p] = new_v

    return g2p, x, v, grid


def _reference(xs, gs):
    base = (xs * np.float32(NG) - np.float32(0.5)).astype(np.int32)
    fx = xs * np.float32(NG) - base.astype(np.float32)
    w = [np.float32(0.5) * (np.float32(1.5) - fx) ** 2, np.float32(0.75) - (fx - 1) ** 2,
         np.float32(0.5) * (fx - np.float32(0.5)) ** 2]
    out = np.zeros_like(xs, dtype=np.float64)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                wt = w[i][:, 0] * w[j][:, 1] * w[k][:, 2]
                out += wt[:, None] * gs[base[:, 0] + i, base[:, 1] + j, base[:, 2] + k]
    return out


def _task(kernel) -> str:
    opt = str(get_jit()._optimized(kernel._instance_for((), "").llvm_text, 0))
    return opt.split("define internal void @sg_kernel_task1(")[1].split("\n}")[0]


def test_gather_loop_vectorises(monkeypatch):
    ti.init(arch=ti.cpu, offline_cache=False)
    task = _task(_g2p()[0])
    assert re.search(r"<(4|8|16) x float>.*masked\.gather|masked\.gather", task), "the grid reads are gathers"
    monkeypatch.setattr(llvm.KernelCodegen, "parallel_group", lambda self, f: None)
    ti.init(arch=ti.cpu, offline_cache=False)
    assert "masked.gather" not in _task(_g2p()[0])  # what the group fixes: LLVM left the loop scalar


@pytest.mark.parametrize("threads", [1, 2])
def test_gather_loop_values(threads):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False)
    g2p, x, v, grid = _g2p()
    rng = np.random.default_rng(0)
    xs = (rng.random((NP, 3)) * 0.8 + 0.1).astype(np.float32)
    gs = rng.standard_normal((NG, NG, NG, 3)).astype(np.float32)
    x.from_numpy(xs)
    grid.from_numpy(gs)
    g2p()
    np.testing.assert_allclose(v.to_numpy(), _reference(xs, gs), rtol=2e-5, atol=2e-5)


@pytest.mark.parametrize("threads", [1, 2])
def test_colliding_updates_stay_exact(threads):
    """Many iterations add into few cells (plain adds on one thread, copies or atomics on two) beside a
    store and a load of the iteration's own elements: the updates are not in the group."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False)
    n, cells = 4096, 7
    idx = ti.field(ti.i32, shape=n)
    val = ti.field(ti.f64, shape=n)
    out = ti.field(ti.f64, shape=n)
    acc = ti.field(ti.f64, shape=cells)

    @ti.kernel
    def scatter():
        for i in idx:
            out[i] = val[i] * 2
            acc[idx[i]] += val[i]

    rng = np.random.default_rng(1)
    ids = rng.integers(0, cells, n).astype(np.int32)
    vals = rng.integers(-50, 50, n).astype(np.float64)  # integers: any order of the sums is exact
    idx.from_numpy(ids)
    val.from_numpy(vals)
    scatter()
    expect = np.zeros(cells)
    np.add.at(expect, ids, vals)
    np.testing.assert_array_equal(acc.to_numpy(), expect)
    np.testing.assert_array_equal(out.to_numpy(), vals * 2)
    # iterations share acc's elements: the loop is not independent (parallel_strategy.py), LLVM keeps its analysis
    assert "llvm.loop.parallel_accesses" not in scatter._instance_for((), "").llvm_text


@pytest.mark.parametrize("threads", [1, 2])
def test_owned_updates_stay_outside_the_group(threads):
    """An independent loop with an update of its own element: the loop has the group, the update's load and
    store (a plain read-modify-write) do not carry it."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False)
    n = 512
    val = ti.field(ti.f32, shape=n)
    out = ti.field(ti.f32, shape=n)

    @ti.kernel
    def own():
        for i in val:
            out[i] += val[i] * 2

    vals = np.arange(n, dtype=np.float32)
    val.from_numpy(vals)
    out.from_numpy(vals)
    own()
    np.testing.assert_array_equal(out.to_numpy(), vals * 3)
    text = own._instance_for((), "").llvm_text
    assert "llvm.loop.parallel_accesses" in text
    grouped = [line for line in text.splitlines() if "access.group" in line]
    assert len(grouped) == 1 and "load" in grouped[0]  # val[i] only
