"""ti.graph: a compiled graph launches its recorded kernels in order with the ndarrays and scalars bound by
name (Taichi's graph/mpm88_graph.py and stable_fluid_graph.py examples), checked against the eager calls."""

import numpy as np
import pytest

import simgrad as ti


@ti.kernel
def scale(x: ti.types.ndarray(dtype=ti.math.vec2, ndim=1), s: ti.f32):
    for i in x:
        x[i] = x[i] * s + ti.Vector([1.0, 0.0])


@ti.kernel
def total(x: ti.types.ndarray(dtype=ti.math.vec2, ndim=1), out: ti.types.ndarray(ti.f32, ndim=0)):
    for i in x:
        out[None] += x[i][0] + 10.0 * x[i][1]


def _fresh():
    x = ti.Vector.ndarray(2, ti.f32, shape=4)
    x.from_numpy(np.arange(8, dtype=np.float32).reshape(4, 2))
    return x, ti.ndarray(ti.f32, shape=())


def test_graph_runs_the_recorded_launches_in_order():
    sym_x = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "x", dtype=ti.math.vec2, ndim=1)
    sym_s = ti.graph.Arg(ti.graph.ArgKind.SCALAR, "s", ti.f32)
    sym_out = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "out", ti.f32, ndim=0)
    builder = ti.graph.GraphBuilder()
    step = builder.create_sequential()
    step.dispatch(scale, sym_x, sym_s)
    step.dispatch(total, sym_x, sym_out)
    builder.dispatch(scale, sym_x, 0.5)  # a constant argument
    for _ in range(3):
        builder.append(step)
    graph = builder.compile()

    x, out = _fresh()
    graph.run({"x": x, "s": 2.0, "out": out})
    ex, eout = _fresh()
    scale(ex, 0.5)
    for _ in range(3):
        scale(ex, 2.0)
        total(ex, eout)
    np.testing.assert_array_equal(x.to_numpy(), ex.to_numpy())
    assert out[None] == eout[None] != 0


def test_graph_arguments_are_checked_where_run_is_called():
    sym_x = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "x", dtype=ti.math.vec2, ndim=1)
    builder = ti.graph.GraphBuilder()
    builder.dispatch(scale, sym_x, 1.0)
    graph = builder.compile()
    with pytest.raises(ti.SimgradError, match=r"no value for the arguments \['x'\]") as e:
        graph.run({})
    assert "test_graph.py" in str(e.value)
    with pytest.raises(ti.SimgradError, match=r"expected elements of shape \(2,\), got \(3,\)"):
        graph.run({"x": ti.Vector.ndarray(3, ti.f32, shape=4)})
    with pytest.raises(ti.SimgradError, match="expected 1 dimensions"):
        graph.run({"x": ti.Vector.ndarray(2, ti.f32, shape=(2, 2))})
    with pytest.raises(ti.SimgradNotSupportedError, match="textures"):
        ti.graph.Arg(ti.graph.ArgKind.TEXTURE, "tex", ndim=2)
