"""`@simgrad.torch.function` (simgrad/torch/bridge.py): a Python function launching kernels over tensors and
fields as one torch autograd node. Gradients checked by torch.autograd.gradcheck in f64 (finite differences)
for ndarray-based and field-based functions; accumulation over two calls in one graph, no_grad, batches,
views; what the bridge cannot differentiate is a located error."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import simgrad as ti
from simgrad.errors import GradientError, SimgradTypeError


@pytest.fixture(autouse=True)
def f64():
    ti.init(arch=ti.cpu, default_fp=ti.f64)


@ti.kernel
def _wave(x: ti.types.ndarray(), w: ti.types.ndarray(), y: ti.types.ndarray(), s: ti.types.ndarray()):
    for i in x:
        y[i] = ti.sin(x[i] * w[i]) + x[(i + 1) % x.shape[0]] ** 2
        s[0] += y[i] * w[i]


@ti.torch.function
def wave(x, w):
    y = torch.zeros_like(x)
    s = torch.zeros(1, dtype=x.dtype)
    _wave(x, w, y, s)
    return y, s


def _rand(*shape, grad=True):
    return torch.rand(*shape, dtype=torch.float64, requires_grad=grad)


def test_the_decorator_is_the_public_form():
    import simgrad.torch

    assert simgrad.torch.function is ti.torch.function
    assert wave.__name__ == "wave" and wave.__wrapped__ is not None


def test_gradcheck_of_an_ndarray_function_in_f64():
    torch.manual_seed(0)
    x, w = _rand(6), _rand(6)
    assert torch.autograd.gradcheck(wave, (x, w))
    y, s = wave(x, w)
    ref_y = torch.sin(x * w) + torch.roll(x, -1) ** 2
    torch.testing.assert_close(y, ref_y)
    torch.testing.assert_close(s, (ref_y * w).sum().reshape(1))


def test_the_function_matches_torch_in_a_larger_graph():
    torch.manual_seed(1)
    x, w = _rand(5), _rand(5)
    y, s = wave(x * 2, w)
    loss = (y ** 2).sum() + 3 * s.sum()
    loss.backward()
    gx, gw = x.grad.clone(), w.grad.clone()
    x.grad = w.grad = None
    x2 = x * 2
    ref_y = torch.sin(x2 * w) + torch.roll(x2, -1) ** 2
    ((ref_y ** 2).sum() + 3 * (ref_y * w).sum()).backward()
    torch.testing.assert_close(gx, x.grad)
    torch.testing.assert_close(gw, w.grad)


def test_two_calls_in_one_graph_accumulate():
    torch.manual_seed(2)
    x, w = _rand(4), _rand(4)
    y1, _ = wave(x, w)
    y2, _ = wave(y1, w)  # the second call's input is the first's output
    (y1.sum() + y2.sum()).backward()
    gx, gw = x.grad.clone(), w.grad.clone()
    x.grad = w.grad = None

    def ref(x):
        return torch.sin(x * w) + torch.roll(x, -1) ** 2

    r1 = ref(x)
    (r1.sum() + ref(r1).sum()).backward()
    torch.testing.assert_close(gx, x.grad)
    torch.testing.assert_close(gw, w.grad)


def test_one_tensor_passed_twice_counts_once_per_use():
    torch.manual_seed(6)
    x = _rand(4)
    y, s = wave(x, x)  # y = sin(x * x) + roll(x) ** 2
    (y.sum() + s.sum()).backward()
    g = x.grad.clone()
    x.grad = None
    ref = torch.sin(x * x) + torch.roll(x, -1) ** 2
    (ref.sum() + (ref * x).sum()).backward()
    torch.testing.assert_close(g, x.grad)


def test_backward_twice_with_retain_graph():
    x, w = _rand(3), _rand(3)
    y, _ = wave(x, w)
    y.sum().backward(retain_graph=True)
    once = x.grad.clone()
    y.sum().backward()
    torch.testing.assert_close(x.grad, 2 * once)


def test_no_grad_records_nothing_and_leaves_grads_alone():
    x, w = _rand(3), _rand(3)
    with torch.no_grad():
        y, s = wave(x, w)
    assert y.grad_fn is None and not y.requires_grad
    assert x.grad is None and w.grad is None  # the kernels saw detached tensors
    y2, _ = wave(x.detach(), w.detach())  # nothing requires grad: a plain call too
    assert y2.grad_fn is None
    torch.testing.assert_close(y, y2)


@ti.kernel
def _rows(x: ti.types.ndarray(dtype=ti.f64, ndim=2), y: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    for b, i in x:
        y[b] += ti.exp(-x[b, i]) * (i + 1)


@ti.torch.function
def rows(x):
    y = x.new_zeros(x.shape[0])
    _rows(x, y)
    return y


def test_batched_inputs():
    torch.manual_seed(3)
    x = _rand(4, 7)
    assert torch.autograd.gradcheck(rows, (x,))
    torch.testing.assert_close(rows(x), (torch.exp(-x) * torch.arange(1, 8)).sum(1))


def test_a_view_of_an_input_gets_the_inputs_gradient():
    @ti.torch.function
    def second_half(x):
        y = x.new_zeros(x.shape[0] // 2)
        _scale_into(x[x.shape[0] // 2:], y)  # a view: its gradient is that part of x's
        return y

    x = _rand(6)
    second_half(x).sum().backward()
    np.testing.assert_array_equal(x.grad.numpy(), [0, 0, 0, 3, 3, 3])


@ti.kernel
def _scale_into(x: ti.types.ndarray(), y: ti.types.ndarray()):
    for i in x:
        y[i] = 3 * x[i]


# -- field-based functions ------------------------------------------------------------------------------
N, STEPS = 8, 5


def _spring_program():
    pos = ti.field(ti.f64, shape=(STEPS + 1, N), needs_grad=True)
    vel = ti.field(ti.f64, shape=(STEPS + 1, N), needs_grad=True)
    k = ti.field(ti.f64, shape=(), needs_grad=True)  # a parameter read by the function

    @ti.kernel
    def load(x: ti.types.ndarray()):
        for i in range(N):
            pos[0, i] = x[i]
            vel[0, i] = 0.0

    @ti.kernel
    def step(t: ti.i32):
        for i in range(N):
            f = -k[None] * ti.sin(pos[t - 1, i]) + pos[t - 1, (i + 1) % N] - pos[t - 1, i]
            vel[t, i] = vel[t - 1, i] + 0.1 * f
            pos[t, i] = pos[t - 1, i] + 0.1 * vel[t, i]

    @ti.kernel
    def store(y: ti.types.ndarray()):
        for i in range(N):
            y[i] = pos[STEPS, i] ** 2

    @ti.torch.function
    def simulate(x):
        load(x)
        for t in range(1, STEPS + 1):
            step(t)
        y = torch.zeros_like(x)
        store(y)
        return y

    k[None] = 0.7
    return simulate, k


def test_gradcheck_of_a_field_based_function():
    simulate, k = _spring_program()
    torch.manual_seed(4)
    x = _rand(N)
    assert torch.autograd.gradcheck(simulate, (x,))


def test_a_second_call_overwriting_the_fields_keeps_the_first_calls_gradient():
    simulate, k = _spring_program()
    torch.manual_seed(5)
    a, b = _rand(N), _rand(N)
    ya = simulate(a)
    yb = simulate(b)  # overwrites the simulation's fields
    (ya.sum() + 2 * yb.sum()).backward()
    ga, gb = a.grad.clone(), b.grad.clone()
    a.grad = b.grad = None
    simulate(a).sum().backward()
    simulate(b).sum().backward()
    torch.testing.assert_close(ga, a.grad)
    torch.testing.assert_close(gb, 2 * b.grad)


def test_a_parameter_fields_gradient_accumulates_outside_torch():
    simulate, k = _spring_program()
    x = _rand(N)
    simulate(x).sum().backward()
    g = k.grad[None]
    h = 1e-6
    k[None] = 0.7 + h
    with torch.no_grad():
        up = simulate(x).sum().item()
    k[None] = 0.7 - h
    with torch.no_grad():
        down = simulate(x).sum().item()
    assert g == pytest.approx((up - down) / (2 * h), rel=1e-5)


def test_a_field_another_pending_call_wrote_is_refused():
    state = ti.field(ti.f64, shape=N, needs_grad=True)

    @ti.kernel
    def put(x: ti.types.ndarray()):
        for i in range(N):
            state[i] = x[i] * 2

    @ti.kernel
    def get(y: ti.types.ndarray()):
        for i in range(N):
            y[i] = state[i] + 1

    @ti.torch.function
    def write(x):
        put(x)
        return x.new_zeros(1)

    @ti.torch.function
    def read(x):
        y = torch.zeros_like(x)
        get(y)
        return y

    x = _rand(N)
    out = write(x)
    with pytest.raises(GradientError, match="reads field 'state', which a pending call of write wrote") as e:
        read(x)
    assert "test_bridge.py" in str(e.value)
    out.sum().backward()  # once its backward ran, the field is no longer pending
    read(x)


def test_a_field_without_gradient_carrying_values_is_refused():
    tmp = ti.field(ti.f64, shape=N)

    @ti.kernel
    def put(x: ti.types.ndarray()):
        for i in range(N):
            tmp[i] = x[i] * 2

    @ti.kernel
    def get(y: ti.types.ndarray()):
        for i in range(N):
            y[i] = tmp[i]

    @ti.torch.function
    def through(x):
        y = torch.zeros_like(x)
        put(x)
        get(y)
        return y

    with pytest.raises(GradientError, match="field 'tmp' carries values between kernels .* no gradient"):
        through(_rand(N))


def test_torch_computations_on_inputs_inside_the_function_are_refused():
    @ti.torch.function
    def bad(x):
        y = torch.zeros_like(x)
        _scale_into(torch.sin(x), y)
        return y

    with pytest.raises(GradientError, match="torch operation 'sin' on an input") as e:
        bad(_rand(3))
    assert "test_bridge.py" in str(e.value)

    @ti.torch.function
    def in_place(x):
        x.mul_(2)
        return x.new_zeros(1)

    with pytest.raises(GradientError, match="'mul_'"):
        in_place(_rand(3))

    @ti.torch.function
    def assign(x):
        x[0] = 1.0
        return x.new_zeros(1)

    with pytest.raises(GradientError, match="'__setitem__'"):
        assign(_rand(3))


def test_a_kernel_writing_into_an_input_is_refused():
    @ti.torch.function
    def overwrite(x):
        _scale_into(x.new_ones(x.shape), x)  # writes x in place, behind torch's back
        return x.new_zeros(1)

    x = _rand(3)
    before = x.detach().clone()
    with pytest.raises(GradientError, match="kernel _scale_into writes into an input tensor \\(argument 'y'\\)"):
        overwrite(x)
    assert torch.equal(x.detach(), before)  # refused before the launch


def test_grad_replaced_units_inside_are_refused():
    @ti.ad.grad_replaced
    def unit(x, y):
        _scale_into(x, y)

    @ti.torch.function
    def uses_unit(x):
        y = torch.zeros_like(x)
        unit(x, y)
        return y

    with pytest.raises(ti.SimgradNotSupportedError, match="grad_replaced functions and ti.ad.checkpoint") as e:
        uses_unit(_rand(3))
    assert "test_bridge.py" in str(e.value)


def test_the_function_must_return_tensors():
    @ti.torch.function
    def nothing(x):
        return None

    with pytest.raises(SimgradTypeError, match="must return a tensor or a tuple of tensors"):
        nothing(_rand(2))
