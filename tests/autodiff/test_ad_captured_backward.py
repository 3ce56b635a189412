"""A Tape's backward pass as one native call (lang/tape.py `_backward_sequence`): the adjoints of the recorded
launches run from a captured sequence, reused while a training loop records the same launches with the same
arguments; the gradients equal the backward pass launched from Python bit for bit, and those equal central
differences in f64."""

import numpy as np

import simgrad as ti
from simgrad.lang import tape as tape_module
from simgrad.runtime import launch

STEPS = 6


def _sim():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=(STEPS + 1, 4), needs_grad=True)
    w = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def step(t: ti.i32, dt: ti.f64):
        for i in range(4):
            x[t + 1, i] = x[t, i] + dt * ti.sin(w[i] * x[t, i] + t)

    @ti.kernel
    def measure():
        for i in range(4):
            loss[None] += x[STEPS, i] ** 2

    def run(dt=0.1):
        for t in range(STEPS):
            step(t, dt)
        measure()

    run.step, run.measure = step, measure
    return x, w, loss, run


def _grads(x, w, loss, run, wv):
    w.from_numpy(wv)
    x.fill(0.0)
    for i in range(4):
        x[0, i] = 0.3 * (i + 1)
    with ti.ad.Tape(loss=loss):
        run()
    return loss[None], w.grad.to_numpy().copy(), x.grad.to_numpy().copy()


def test_captured_backward_equals_python_backward_and_finite_differences(monkeypatch):
    x, w, loss, run = _sim()
    replays = []
    real = launch.Sequence.run
    monkeypatch.setattr(launch.Sequence, "run", lambda self: (replays.append(len(self.launchers)), real(self)))
    wv = np.array([0.5, -1.0, 2.0, 0.25])
    captured = [_grads(x, w, loss, run, wv) for _ in range(3)]
    assert replays == [STEPS + 1] * 3  # every backward pass: one native call over the 7 adjoints
    assert tape_module._backward is not None
    first = tape_module._backward[2]
    _grads(x, w, loss, run, wv * 1.1)  # new field values, same launches: the same capture
    assert tape_module._backward[2] is first
    monkeypatch.setattr(tape_module, "_backward_sequence", lambda entries: None)
    eager = _grads(x, w, loss, run, wv)
    for c in captured:
        assert c[0] == eager[0]
        np.testing.assert_array_equal(c[1], eager[1])
        np.testing.assert_array_equal(c[2], eager[2])
    h, fd = 1e-6, []
    for i in range(4):
        e = np.zeros(4)
        e[i] = h
        fd.append((_grads(x, w, loss, run, wv + e)[0] - _grads(x, w, loss, run, wv - e)[0]) / (2 * h))
    np.testing.assert_allclose(eager[1], fd, rtol=1e-6, atol=1e-9)


def test_another_argument_or_a_custom_gradient_is_not_replayed_stale():
    x, w, loss, run = _sim()
    wv = np.array([0.5, -1.0, 2.0, 0.25])
    a = _grads(x, w, loss, run, wv)
    first = tape_module._backward[2]
    b = _grads(x, w, loss, lambda: run(0.2), wv)  # another scalar argument: captured anew
    assert tape_module._backward[2] is not first and not np.array_equal(a[1], b[1])
    calls = []

    @ti.ad.grad_replaced
    def custom(t):
        run.step(t, 0.2)

    @ti.ad.grad_for(custom)
    def custom_grad(t):
        calls.append(t)
        run.step.grad(t, 0.2)

    def run_custom():
        for t in range(STEPS):
            custom(t)
        run.measure()

    c = _grads(x, w, loss, run_custom, wv)
    assert calls == list(reversed(range(STEPS)))  # the custom gradient ran from Python, in reverse
    np.testing.assert_array_equal(c[1], b[1])


def test_launches_found_not_capturable_are_not_tried_again(monkeypatch):
    # a training loop whose recorded launches include a custom gradient runs its backward from Python; the
    # adjoints' launchers are made once to find that out, not at every iteration (diffmpm: 1025 launchers a
    # backward pass, 0.3 s an iteration)
    x, w, loss, run = _sim()

    @ti.ad.grad_replaced
    def custom(t):
        run.step(t, 0.1)

    @ti.ad.grad_for(custom)
    def custom_grad(t):
        run.step.grad(t, 0.1)

    def run_custom():
        for t in range(STEPS):
            custom(t)
        run.measure()

    made = []
    real = type(run.measure.grad).launcher
    monkeypatch.setattr(type(run.measure.grad), "launcher", lambda self, args: (made.append(1), real(self, args))[1])
    wv = np.array([0.5, -1.0, 2.0, 0.25])
    results = [_grads(x, w, loss, run_custom, wv) for _ in range(3)]
    assert len(made) == 1  # the last launch's adjoint is made first; the custom gradient stops the capture
    assert tape_module._backward is not None and tape_module._backward[2] is None
    for r in results[1:]:
        np.testing.assert_array_equal(r[1], results[0][1])


def test_a_negative_zero_argument_is_not_replayed_as_zero():
    # the replayed contexts hold the scalars they were packed with: -0.0 after 0.0 is another argument
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=(), needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f(s: ti.f64):
        loss[None] = ti.atan2(s, -1.0) * x[None]

    grads = []
    for s in (0.0, 0.0, -0.0):
        x[None] = 1.0
        with ti.ad.Tape(loss=loss):
            f(s)
        grads.append(x.grad[None])
    assert grads[0] == grads[1] == np.arctan2(0.0, -1.0)
    assert grads[2] == np.arctan2(-0.0, -1.0)  # -pi: replaying the 0.0 capture would give pi


def test_a_graph_replays_negative_zero_as_itself():
    ti.init(arch=ti.cpu, default_fp=ti.f64)

    @ti.kernel
    def f(x: ti.types.ndarray(ndim=1), s: ti.f64):
        x[0] = ti.atan2(s, -1.0)

    sym_x = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "x", ti.f64, ndim=1)
    sym_s = ti.graph.Arg(ti.graph.ArgKind.SCALAR, "s", ti.f64)
    gb = ti.graph.GraphBuilder()
    gb.dispatch(f, sym_x, sym_s)
    g = gb.compile()
    x = ti.ndarray(ti.f64, shape=1)
    got = []
    for s in (0.0, 0.0, -0.0):  # the second run replays the first's capture; the third must not
        g.run({"x": x, "s": s})
        got.append(x.to_numpy()[0])
    assert got == [np.pi, np.pi, -np.pi]
