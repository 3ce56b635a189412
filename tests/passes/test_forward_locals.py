"""Forwarding of locals stored several times (passes/promote.py `_forward_last`) and branches on constants
(passes/simplify.py `_fold_branches`). diffmpm3d's grid_op zeroes `v_out` at the floor and then tests
`lin = v_out.dot(normal) < 0`: with the zeros forwarded that branch folds away, and the adjoint no longer keeps
its values and decision on the tape (its loop then vectorises: 2.6 -> 1.4 ms at 64^3, one thread).
Values against plain Python / numpy, gradients against central differences in f64, at 1 and 2 threads."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.testing import check_grads

N = 8
BOUND = 3
COEFF = 1.5


def _grid_op():
    m_in = ti.field(ti.f64, shape=(N, N, N), needs_grad=True)
    v_in = ti.Vector.field(3, ti.f64, shape=(N, N, N), needs_grad=True)
    v_out = ti.Vector.field(3, ti.f64, shape=(N, N, N), needs_grad=True)

    @ti.kernel
    def grid_op():
        for i, j, k in m_in:
            inv_m = 1 / (m_in[i, j, k] + 1e-10)
            v = inv_m * v_in[i, j, k]
            v[1] -= 0.02
            if i < BOUND and v[0] < 0:
                v[0] = 0
                v[1] = 0
                v[2] = 0
            if j < BOUND and v[1] < 0:
                v[0] = 0
                v[1] = 0
                v[2] = 0
                normal = ti.Vector([0.0, 1.0, 0.0])
                lsq = (normal**2).sum()
                if lsq > 0.5:
                    lin = v.dot(normal)
                    if lin < 0:
                        vit = v - lin * normal
                        lit = vit.norm() + 1e-10
                        if lit + COEFF * lin <= 0:
                            v[0] = 0
                            v[1] = 0
                            v[2] = 0
                        else:
                            v = (1 + COEFF * lin / lit) * vit
            if j > N - BOUND and v[1] > 0:
                v = ti.Vector([0.0, 0.0, 0.0])
            v_out[i, j, k] = v

    return grid_op, m_in, v_in, v_out


def _reference(m, vin):
    out = (1 / (m + 1e-10))[..., None] * vin
    out[..., 1] -= 0.02
    i, j = np.indices((N, N, N))[:2]
    out[(i < BOUND) & (out[..., 0] < 0)] = 0
    out[(j < BOUND) & (out[..., 1] < 0)] = 0
    out[(j > N - BOUND) & (out[..., 1] > 0)] = 0
    return out


def _nested_ifs(body) -> list:
    return [s for s in walk(body) if s.op is Op.IF and any(x.op is Op.IF for b in s.blocks for x in walk(b))]


@pytest.mark.parametrize("threads", [1, 2])
def test_grid_op_friction_branch_folds_and_its_adjoint_keeps_no_tape(threads):
    ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=threads, offline_cache=False)
    grid_op, m_in, v_in, v_out = _grid_op()
    rng = np.random.default_rng(0)
    m = rng.random((N, N, N)) + 0.5
    vin = rng.standard_normal((N, N, N, 3))
    m_in.from_numpy(m)
    v_in.from_numpy(vin)
    grid_op()
    np.testing.assert_allclose(v_out.to_numpy(), _reference(m, vin), rtol=1e-14, atol=1e-15)
    forward = grid_op._instance_for((), "").ir
    assert not _nested_ifs(forward.body), "the friction branch (lsq > 0.5, lin < 0, lit <= 0) is gone"
    check_grads(grid_op, [m_in, v_in], [v_out])
    adjoint = grid_op._instance_for((), "grad").ir
    assert not any(s.op is Op.TAPE_PUSH for s in walk(adjoint.body))


@pytest.mark.parametrize("threads", [1, 2])
def test_forwarding_respects_branches_loops_and_updates(threads):
    """Each place where a local's last value is not the one stored before: a store in a branch, in a loop
    (seen again at the loop's head), a `+=`, a break out of a while."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False)
    n = 64
    x = ti.field(ti.i32, shape=n)
    out = ti.field(ti.i32, shape=(n, 6))

    @ti.kernel
    def k():
        for i in x:
            a = x[i]
            b = 7
            if a % 3 == 0:
                b = a * 2
            out[i, 0] = b  # the branch's store or the one before
            c = 1
            for t in range(4):
                out[i, 1] += c  # c seen at the head: 1, then the loop's own stores
                c = c * 2 + t
            out[i, 2] = c
            d = a
            d += 5
            out[i, 3] = d  # after an update
            e = 0
            while True:
                e = e + 3
                if e > a % 10:
                    break
                e = e + 1
            out[i, 4] = e  # the store before the break
            f = 2
            if 1 > 0:  # a constant condition: the branch is the enclosing block
                f = 9
            out[i, 5] = f

    xs = np.arange(n, dtype=np.int32) * 7 - 100
    x.from_numpy(xs)
    k()
    expect = np.zeros((n, 6), np.int32)
    for i, a in enumerate(xs.tolist()):
        b = a * 2 if a % 3 == 0 else 7
        c, s = 1, 0
        for t in range(4):
            s += c
            c = c * 2 + t
        e = 0
        while True:
            e += 3
            if e > a % 10:
                break
            e += 1
        expect[i] = [b, s, c, a + 5, e, 9]
    np.testing.assert_array_equal(out.to_numpy(), expect)


def test_forwarding_turned_off_keeps_the_friction_branch(monkeypatch):
    """What the test above relies on: without the forwarding the branch stays and the adjoint tapes it."""
    import simgrad.passes.promote as promote

    monkeypatch.setattr(promote, "_forward_last", lambda *a: None)
    ti.init(arch=ti.cpu, default_fp=ti.f64, offline_cache=False)
    grid_op = _grid_op()[0]
    assert _nested_ifs(grid_op._instance_for((), "").ir.body)
    assert any(s.op is Op.TAPE_PUSH for s in walk(grid_op._instance_for((), "grad").ir.body))
