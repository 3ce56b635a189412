"""passes/unswitch.py: a parallel loop that picks a vector component by a kernel argument (`rate[i][k] = ...`,
`rate[i][k - 1]`) runs as one copy per value the argument is compared with, plus the original for any other value.
Every value, those and others, gives numpy's result; the copies are ordinary top-level loops (one runs); gradients
through such an access match finite differences; the GPU and debug mode keep the one loop."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


def _parallel_loops(kernel, *args) -> int:
    return sum(1 for s in kernel.instance(args).ir.body.stmts if s.op is Op.RANGE_FOR and s.attrs.get("parallel"))


def _rk_program(n=1000):
    """snow_phaseField's pattern: a stage writes component k of a rate, the next reads component k - 1."""
    rate = ti.Vector.field(4, ti.f64, shape=n)
    x = ti.field(ti.f64, shape=n)
    y = ti.field(ti.f64, shape=n)

    @ti.kernel
    def stage(k: ti.i32):
        for i in x:
            rate[i][k] = x[i] * (k + 1) + 0.5
            y[i] = rate[i][k] * 2.0 + k

    @ti.kernel
    def read(k: ti.i32):
        for i in x:
            y[i] = rate[i][k - 1] - x[i]

    return rate, x, y, stage, read


def test_every_value_of_the_index_gives_numpys_result():
    ti.init(arch=ti.cpu)
    n = 1000
    rate, x, y, stage, read = _rk_program(n)
    xs = np.random.default_rng(0).standard_normal(n)
    x.from_numpy(xs)
    start = np.arange(4 * n, dtype=np.float64).reshape(n, 4)
    for k in (0, 1, 2, 3, 7, -1):  # the compared values, then others: no component (the original loop)
        rate.from_numpy(start)
        y.fill(0)
        stage(k)
        want = start.copy()
        if 0 <= k < 4:
            want[:, k] = xs * (k + 1) + 0.5
        np.testing.assert_array_equal(rate.to_numpy(), want)
        if 0 <= k < 4:
            np.testing.assert_array_equal(y.to_numpy(), want[:, k] * 2.0 + k)
    assert _parallel_loops(stage, 0) == 5  # four copies and the original
    for k in (1, 2, 3, 4):
        read(k)
        np.testing.assert_array_equal(y.to_numpy(), rate.to_numpy()[:, k - 1] - xs)
    assert _parallel_loops(read, 1) == 4  # a read selects among 4 loads by 3 comparisons: 3 copies, the original


def test_each_copy_has_one_store_per_access_and_no_component_compare():
    ti.init(arch=ti.cpu)
    rate, x, y, stage, read = _rk_program()
    ir = stage.instance((0,)).ir
    loops = [s for s in ir.body.stmts if s.op is Op.RANGE_FOR and s.attrs.get("parallel")]
    for copy in loops[:4]:  # the copies: the component is a constant, one store to rate and one to y
        stores = [s for s in walk(copy.blocks[0]) if s.op is Op.GLOBAL_STORE]
        assert len(stores) == 2, len(stores)
        assert not any(s.op is Op.SELECT for s in walk(copy.blocks[0]))


@pytest.mark.parametrize("k", [0, 2])
def test_gradients_through_a_picked_component_match_finite_differences(k):
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    n = 50
    v = ti.Vector.field(3, ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def energy(c: ti.i32):
        for i in v:
            loss[None] += ti.sin(v[i][c]) * v[i][(c + 1) % 3]

    vs = np.random.default_rng(1).standard_normal((n, 3))
    v.from_numpy(vs)
    with ti.ad.Tape(loss):
        energy(k)
    got = v.grad.to_numpy()
    h = 1e-6
    for i, j in [(0, k), (7, (k + 1) % 3), (9, (k + 2) % 3)]:
        def f(d):
            w = vs.copy()
            w[i, j] += d
            return float(np.sum(np.sin(w[:, k]) * w[:, (k + 1) % 3]))
        fd = (f(h) - f(-h)) / (2 * h)
        assert got[i, j] == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_debug_mode_keeps_one_loop_and_reports_an_out_of_range_component():
    ti.init(arch=ti.cpu, debug=True)
    rate, x, y, stage, read = _rk_program(10)
    stage(1)
    assert _parallel_loops(stage, 1) == 1
    with pytest.raises(Exception, match="out of range|index"):
        stage(7)
