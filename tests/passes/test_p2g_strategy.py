"""The strategies of an MLS-MPM particle-to-grid kernel and its adjoint (the examples' speed depends on
them): the scatter into the grid goes to per-thread copies or paired compare-and-swaps, the particle
state is owned. Golden: tests/passes/golden/p2g_strategies.txt."""

from collections import Counter

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


def _p2g(n_particles=64, n_grid=16, steps=3):
    dt, dx, inv_dx = 1e-4, 1.0 / n_grid, float(n_grid)
    x = ti.Vector.field(2, ti.f32, shape=(steps, n_particles), needs_grad=True, name="x")
    v = ti.Vector.field(2, ti.f32, shape=(steps, n_particles), needs_grad=True, name="v")
    C = ti.Matrix.field(2, 2, ti.f32, shape=(steps, n_particles), needs_grad=True, name="C")
    F = ti.Matrix.field(2, 2, ti.f32, shape=(steps, n_particles), needs_grad=True, name="F")
    grid_v = ti.Vector.field(2, ti.f32, shape=(n_grid, n_grid), needs_grad=True, name="grid_v")
    grid_m = ti.field(ti.f32, shape=(n_grid, n_grid), needs_grad=True, name="grid_m")

    @ti.kernel
    def p2g(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_F = (ti.Matrix.diag(dim=2, val=1) + dt * C[f, p]) @ F[f, p]
            F[f + 1, p] = new_F
            affine = 10.0 * (new_F - ti.Matrix.diag(2, 1.0)) + C[f, p]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    offset = ti.Vector([i, j])
                    dpos = (ti.cast(offset, ti.f32) - fx) * dx
                    weight = w[i][0] * w[j][1]
                    grid_v[base + offset] += weight * (v[f, p] + affine @ dpos)
                    grid_m[base + offset] += weight

    rng = np.random.default_rng(0)
    x.from_numpy((rng.random((steps, n_particles, 2)) * 0.5 + 0.25).astype(np.float32))
    F.from_numpy(np.broadcast_to(np.eye(2, dtype=np.float32), (steps, n_particles, 2, 2)).copy())
    return p2g


def _summary(ir) -> tuple[str, Counter]:
    lines, forms = [], Counter()
    for s in walk(ir.body):
        if s.op is Op.RANGE_FOR and "strategy" in s.attrs:
            lines.append(f"loop: {s.attrs['strategy'].ir_name()}")
        if s.op is Op.ATOMIC and s.operands[0].op is Op.GLOBAL_PTR:
            name = s.operands[0].attrs["target"].name
            forms[(name, s.attrs["strategy"])] += 1
    lines += [f"{name}: {form} x{n}" for (name, form), n in sorted(forms.items())]
    return "\n".join(lines) + "\n", forms


def test_p2g_and_its_adjoint_keep_their_strategies(golden):
    p2g = _p2g()
    p2g(0)
    p2g.grad(0)
    fwd, fwd_forms = _summary(p2g.instance((0,)).ir)
    bwd, bwd_forms = _summary(p2g._instance_for((0,), "grad").ir)
    assert fwd_forms == Counter({("grid_v[0]", "private|pair"): 9, ("grid_v[1]", "private|pair"): 9,
                                 ("grid_m", "private|atomic"): 9})
    assert {form for (_name, form) in bwd_forms} == {"plain"}  # each particle gradient is owned by its p
    golden.check("p2g_strategies.txt", f"forward:\n{fwd}adjoint:\n{bwd}")


def test_debug_mode_sums_into_a_field_element_atomically():
    """ti.init(debug=True): `x[n % 8] += 1` in a parallel loop was a per-thread sum whose final add re-addressed
    x[n % 8] after the loop, with the bounds-checked offset computed inside it (LLVM's verifier fired); in debug
    mode a field element is updated atomically, a local is still summed per thread."""
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.f32, shape=8)
    t = ti.field(ti.f32, shape=())

    @ti.kernel
    def run(n: ti.i32) -> ti.f32:
        s = 0.0
        for _ in range(1000):
            x[n % 8] += 1.0
            x[2] += 2.0  # a constant index is checked in the loop too
            t[None] += 1.0  # a 0-D field has no index: still summed per thread
            s += 0.5
        return s

    assert run(13) == 500.0 and t[None] == 1000.0
    np.testing.assert_array_equal(x.to_numpy(), [0, 0, 2000, 0, 0, 1000, 0, 0])
    forms = [s.attrs["strategy"] for s in walk(run.instance((13,)).ir.body) if s.op is Op.ATOMIC]
    assert forms[2:] == ["reduce", "reduce"] and "reduce" not in forms[0] + forms[1]
    x_bad = ti.field(ti.f32, shape=4)

    @ti.kernel
    def bad(n: ti.i32):
        for _ in range(10):
            x_bad[n] += 1.0

    with pytest.raises(Exception, match="index 7 is out of bounds"):  # still checked, in the loop
        bad(7)
