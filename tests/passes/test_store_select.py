"""passes/store_select.py: `if c: x[p] = v` after a store to x[p] in the same block is one store of a select.
Values equal numpy's; the rewrite is not made without an earlier store to that very element in that block, with
a side that reads memory or does more than one store, or for a sparse element; a Tape does not take the
re-read for an in-place update."""

import numpy as np

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


def _ifs(kernel, *args) -> int:
    return sum(1 for s in walk(kernel.instance(args).ir.body) if s.op is Op.IF)


def test_boundary_conditions_become_selects():
    ti.init(arch=ti.cpu)
    n = 16
    m = ti.field(ti.f32, shape=(n, n))
    v = ti.Vector.field(2, ti.f32, shape=(n, n))
    g = ti.Vector.field(2, ti.f32, shape=())

    @ti.kernel
    def grid():
        for i, j in m:
            if m[i, j] > 0:
                v[i, j] = v[i, j] / m[i, j] + g[None]
                if i < 3 and v[i, j][0] < 0:
                    v[i, j][0] = 0
                if i > n - 3 and v[i, j][0] > 0:
                    v[i, j][0] = 0
                if j < 3 and v[i, j][1] < 0:
                    v[i, j][1] = 0
                if j > n - 3:
                    pass
                else:
                    v[i, j][1] = v[i, j][1] * 0.5  # the else side

    rng = np.random.default_rng(0)
    ms = rng.uniform(-1, 1, (n, n)).astype(np.float32)
    vs = rng.uniform(-1, 1, (n, n, 2)).astype(np.float32)
    m.from_numpy(ms)
    v.from_numpy(vs)
    g[None] = [0.25, -0.5]
    grid()
    assert _ifs(grid) == 1  # only `if m[i, j] > 0` is left
    w = vs / ms[..., None] + np.array([0.25, -0.5], np.float32)
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    w[..., 0] = np.where((ii < 3) & (w[..., 0] < 0), 0, w[..., 0])
    w[..., 0] = np.where((ii > n - 3) & (w[..., 0] > 0), 0, w[..., 0])
    w[..., 1] = np.where((jj < 3) & (w[..., 1] < 0), 0, w[..., 1])
    w[..., 1] = np.where(jj > n - 3, w[..., 1], w[..., 1] * np.float32(0.5))
    np.testing.assert_allclose(v.to_numpy(), np.where((ms > 0)[..., None], w, vs), rtol=1e-6)


def test_not_rewritten_without_the_same_element_stored_before_in_the_block():
    ti.init(arch=ti.cpu)
    n = 12
    x, y, z, w, u = (ti.field(ti.f32, shape=n + 1) for _ in range(5))

    def body(i, x, y, z, w, u):
        if i % 2 == 0:  # no earlier store
            y[i] = 1.0
        x[i + 1] = 2.0
        if i % 3 == 0:  # an earlier store, but to x[i + 1]
            x[i] = 3.0
        z[i] = 0.5
        if i % 4 == 0:  # the side reads memory
            z[i] = x[i]
        w[i] = 0.25
        if i == 1:  # two stores on the side
            w[i] = 6.0
            y[i] = 6.0
        if i > 2:
            u[i] = 1.0
        if i > 4:  # the earlier store is in a nested block
            u[i] = 7.0

    kernel_body = ti.func(body)

    @ti.kernel
    def k():
        ti.loop_config(serialize=True)
        for i in range(n):
            kernel_body(i, x, y, z, w, u)

    k()
    assert _ifs(k) == 6
    ref = [np.zeros(n + 1, np.float32) for _ in range(5)]
    for i in range(n):
        body(i, *ref)
    for f, r in zip((x, y, z, w, u), ref):
        np.testing.assert_array_equal(f.to_numpy(), r)


def test_sparse_elements_keep_their_branch():
    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32)
    ti.root.pointer(ti.i, 4).dense(ti.i, 4).place(x)

    @ti.kernel
    def k():
        for i in range(16):
            x[i] = 1.0
            if i % 2 == 0:
                x[i] = 2.0

    k()
    np.testing.assert_array_equal(x.to_numpy(), np.where(np.arange(16) % 2 == 0, 2.0, 1.0))
    assert _ifs(k) == 1


def test_rewritten_kernel_is_not_taken_for_in_place():
    ti.init(arch=ti.cpu)
    n = 8
    x = ti.field(ti.f32, shape=n, needs_grad=True)
    y = ti.field(ti.f32, shape=n, needs_grad=True)

    @ti.kernel
    def k():
        for i in x:
            t = x[i] * 3.0
            y[i] = x[i] * 2.0
            if i % 2 == 0:
                y[i] = t

    k()
    assert _ifs(k) == 0
    assert not k.instance(()).in_place
    np.testing.assert_array_equal(y.to_numpy(), np.zeros(n))
