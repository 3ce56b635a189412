"""A field has as many indices as distinct axes on its SNode path, in axis order, as taichi packs them:
`ti.root.dense(ti.k, 3).dense(ti.l, 4)` gives x[a, b] of shape (3, 4) (it had 4 indices before, which
stopped the unmodified electric, diffmpm and liquid programs). Struct-for, kernel access and Python scope
agree; the expected contents are numpy arithmetic on the indices (taichi 1.7.4 gives the same shapes and
contents for these layouts)."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti

LAYOUTS = [
    ("kl", lambda f: ti.root.dense(ti.k, 3).dense(ti.l, 4).place(f), (3, 4)),
    ("lj", lambda f: ti.root.dense(ti.l, 2).dense(ti.j, 5).place(f), (5, 2)),
    ("iji", lambda f: ti.root.dense(ti.i, 2).dense(ti.j, 3).dense(ti.i, 2).place(f), (4, 3)),
    ("ijl", lambda f: ti.root.dense(ti.ijl, (2, 3, 4)).place(f), (2, 3, 4)),
    ("ikl", lambda f: ti.root.dense(ti.ikl, (2, 3, 2)).place(f), (2, 3, 2)),
    ("jl_j", lambda f: ti.root.dense(ti.jl, (2, 3)).dense(ti.j, 2).place(f), (4, 3)),
]


@pytest.mark.parametrize("name, build, shape", LAYOUTS, ids=[x[0] for x in LAYOUTS])
def test_packed_axes_shape_struct_for_and_python_scope(name, build, shape):
    ti.init(arch=ti.cpu)
    f = ti.field(ti.i32)
    build(f)
    assert f.shape == shape

    if len(shape) == 2:
        @ti.kernel
        def fill():
            for p, q in f:
                f[p, q] = p * 100 + q
    else:
        @ti.kernel
        def fill():
            for p, q, r in f:
                f[p, q, r] = p * 100 + q * 10 + r

    fill()
    idx = np.indices(shape)
    want = idx[0] * 100 + idx[1] if len(shape) == 2 else idx[0] * 100 + idx[1] * 10 + idx[2]
    np.testing.assert_array_equal(f.to_numpy(), want)
    last = tuple(s - 1 for s in shape)
    assert f[last] == want[last]
    f[last] = -1
    assert f.to_numpy()[last] == -1


def test_vector_field_on_packed_axes():
    ti.init(arch=ti.cpu)
    e = ti.Vector.field(2, ti.f32)
    ti.root.dense(ti.k, 3).dense(ti.l, 2).place(e)

    @ti.kernel
    def fill():
        for a, b in e:
            e[a, b] = [a, b]

    fill()
    assert e.shape == (3, 2)
    np.testing.assert_array_equal(e.to_numpy()[2, 1], [2, 1])


def test_get_scalar_field_places_entries_separately_with_gradients():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    v = ti.Vector.field(2, ti.f64)
    m = ti.Matrix.field(2, 2, ti.f64)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    for c in range(2):
        ti.root.dense(ti.k, 3).dense(ti.l, 4).place(v.get_scalar_field(c))
        for d in range(2):
            ti.root.dense(ti.i, 4).place(m.get_scalar_field(c, d))
    ti.root.lazy_grad()
    assert v.shape == (3, 4) and m.shape == (4,)

    @ti.kernel
    def f():
        for a, b in v:
            v[a, b] = [a, b]
        for i in m:
            m[i] = [[i, 1], [2, i]]

    @ti.kernel
    def total():
        for a, b in v:
            loss[None] += v[a, b].dot(v[a, b]) * m[b][0, 0]

    f()
    with ti.ad.Tape(loss=loss):
        total()
    vs, ms = v.to_numpy(), m.to_numpy()
    np.testing.assert_array_equal(vs[2, 3], [2, 3])
    np.testing.assert_array_equal(ms[3], [[3, 1], [2, 3]])
    np.testing.assert_allclose(v.grad.to_numpy(), 2 * vs * ms[:, 0, 0][None, :, None])
    with pytest.raises(Exception, match="takes 2 integer index"):
        m.get_scalar_field(0)


def test_total_compilation_time_through_lang_impl():
    """smoke_taichi_gpu prints ti.lang.impl.get_runtime().prog.get_total_compilation_time()."""
    ti.init(arch=ti.cpu)
    before = ti.lang.impl.get_runtime().prog.get_total_compilation_time()
    x = ti.field(ti.f32, 4)

    @ti.kernel
    def k():
        for i in x:
            x[i] = 1

    k()
    after = ti.lang.impl.get_runtime().prog.get_total_compilation_time()
    assert after > before >= 0.0
