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


def _graph():
    sym_x = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "x", dtype=ti.math.vec2, ndim=1)
    sym_s = ti.graph.Arg(ti.graph.ArgKind.SCALAR, "s", ti.f32)
    sym_out = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "out", ti.f32, ndim=0)
    builder = ti.graph.GraphBuilder()
    builder.dispatch(scale, sym_x, 0.5)
    builder.dispatch(scale, sym_x, sym_s)  # one kernel instance at two steps with other arguments
    builder.dispatch(total, sym_x, sym_out)
    return builder.compile()


def _eager(x, s, out, runs):
    for _ in range(runs):
        scale(x, 0.5)
        scale(x, s)
        total(x, out)


def test_later_runs_with_the_same_values_replay_in_one_native_call(monkeypatch):
    """The second run on replays the captured sequence: no kernel is called from Python, and every result
    equals the eager calls'; a new scalar or another ndarray launches from Python and captures again."""
    from simgrad.runtime import launch

    graph = _graph()
    x, out = _fresh()
    graph.run({"x": x, "s": 2.0, "out": out})  # launches from Python, then captures
    replays = []
    real = launch.Sequence.run
    monkeypatch.setattr(launch.Sequence, "run", lambda self: (replays.append(1), real(self)))
    calls = []
    kernel_call = type(scale).__call__
    monkeypatch.setattr(type(scale), "__call__", lambda self, *a, **k: (calls.append(1), kernel_call(self, *a, **k))[1])
    for _ in range(3):
        graph.run({"x": x, "s": 2.0, "out": out})
    assert len(replays) == 3 and not calls  # no kernel called from Python
    monkeypatch.setattr(type(scale), "__call__", kernel_call)
    ex, eout = _fresh()
    _eager(ex, 2.0, eout, 4)
    np.testing.assert_array_equal(x.to_numpy(), ex.to_numpy())
    assert out[None] == eout[None]
    graph.run({"x": x, "s": 3.0, "out": out})  # another scalar: from Python (and captured anew)
    _eager(ex, 3.0, eout, 1)
    assert len(replays) == 3
    graph.run({"x": x, "s": 3.0, "out": out})
    _eager(ex, 3.0, eout, 1)
    assert len(replays) == 4
    np.testing.assert_array_equal(x.to_numpy(), ex.to_numpy())
    assert out[None] == eout[None]


def test_replay_reports_a_kernels_error_at_its_step():
    """A kernel that fails inside the replayed sequence stops it there and raises as its launch would."""
    ti.init(arch=ti.cpu, debug=True)

    @ti.kernel
    def check(x: ti.types.ndarray(dtype=ti.f32, ndim=1), limit: ti.f32):
        for i in x:
            assert x[i] < limit, "too large"
            x[i] += 1.0

    sym = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "x", ti.f32, ndim=1)
    builder = ti.graph.GraphBuilder()
    builder.dispatch(check, sym, 3.5)
    builder.dispatch(check, sym, 2.5)
    builder.dispatch(check, sym, 100.0)
    graph = builder.compile()
    x = ti.ndarray(ti.f32, 4)
    graph.run({"x": x})  # 0 -> 3
    with pytest.raises(ti.TaichiAssertionError, match="too large"):
        graph.run({"x": x})  # the replay: 3 -> 4 passes the first step, the second fails (and adds, as eagerly)
    assert (x.to_numpy() == 5).all()  # the third step did not run
    ti.init(arch=ti.cpu)


def test_a_graph_under_a_tape_launches_from_python_so_the_tape_records():
    ti.init(arch=ti.cpu)
    w = ti.field(ti.f64, shape=3, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def energy(s: ti.f64):
        for i in w:
            loss[None] += s * w[i] * w[i]

    sym = ti.graph.Arg(ti.graph.ArgKind.SCALAR, "s", ti.f64)
    builder = ti.graph.GraphBuilder()
    builder.dispatch(energy, sym)
    graph = builder.compile()
    w.from_numpy(np.array([1.0, 2.0, 3.0]))
    graph.run({"s": 0.5})
    graph.run({"s": 0.5})  # captured
    loss[None] = 0.0
    with ti.ad.Tape(loss=loss):
        graph.run({"s": 0.5})
    np.testing.assert_allclose(w.grad.to_numpy(), [1.0, 2.0, 3.0])
