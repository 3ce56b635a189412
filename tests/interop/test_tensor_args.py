"""Torch tensors and DLPack arrays as ti.types.ndarray() arguments (compiler/params.py TensorParam,
runtime/tensors.py): zero copy (one data pointer, writes seen by both sides), what cannot be passed by
reference refused at the user's line, gradients into a tensor's .grad or an explicit pair (ti.ad.with_grad),
in kernel.grad and in a Tape; fields' to_torch/from_torch."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import simgrad as ti
from simgrad.errors import SimgradTypeError, SimgradValueError


def _here(excinfo) -> bool:
    """The error names this test file (the user's line), not simgrad's."""
    return __file__ in str(excinfo.value)


@ti.kernel
def _scale(x: ti.types.ndarray(), s: ti.f32):
    for i in x:
        x[i] = x[i] * s


def test_a_tensor_argument_is_the_tensors_memory():
    t = torch.arange(6, dtype=torch.float32)
    view = t.numpy()  # shares t's memory
    _scale(t, 2.0)
    np.testing.assert_array_equal(view, np.arange(6) * 2.0)  # the kernel wrote into t itself

    # the launch put the tensor's own data pointer in the kernel's context
    from simgrad.runtime.abi import CTX_ARGS

    launcher = _scale.instance((t, 2.0)).launcher
    assert int(launcher.buf[CTX_ARGS + launcher.params[0].slot]) == t.data_ptr()
    t[0] = 21.0
    _scale(t, 2.0)
    assert t[0].item() == 42.0  # a torch write is seen by the kernel, the kernel's write by torch
    t[1] = -1.0  # a torch write is seen by the next launch
    _scale(t, 3.0)
    assert t[1].item() == -3.0


def test_a_contiguous_slice_is_passed_at_its_offset():
    t = torch.zeros(10)
    _scale(t[4:], 0.0)
    t[4:].fill_(1.0)
    _scale(t[4:], 5.0)
    np.testing.assert_array_equal(t.numpy(), [0] * 4 + [5] * 6)


def test_a_non_contiguous_tensor_is_refused_at_the_users_line():
    @ti.kernel
    def copy(x: ti.types.ndarray(), y: ti.types.ndarray()):
        for i, j in x:
            y[i, j] = x[i, j]

    t = torch.ones(4, 4)
    with pytest.raises(SimgradValueError, match="Non contiguous tensors are not supported") as e:
        copy(torch.arange(16.0).reshape(4, 4).T, t)
    assert _here(e)
    with pytest.raises(SimgradValueError, match="Non contiguous"):
        _scale(t[:, 0], 2.0)
    assert (t == 1).all()  # nothing was written


def test_an_unsupported_dtype_is_refused():
    with pytest.raises(SimgradTypeError, match="torch.bool cannot be a kernel argument") as e:
        _scale(torch.zeros(3, dtype=torch.bool), 1.0)
    assert _here(e)
    with pytest.raises(SimgradTypeError, match="torch.complex64"):
        _scale(torch.zeros(3, dtype=torch.complex64), 1.0)


def test_a_wrong_dtype_for_the_annotation_is_refused():
    @ti.kernel
    def k(x: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in x:
            x[i] = 1.0

    with pytest.raises(SimgradTypeError, match="Expect element type f32"):
        k(torch.zeros(3, dtype=torch.float64))


def test_a_tensor_on_another_device_is_refused():
    if not hasattr(torch, "device"):
        pytest.skip("torch without devices")
    meta = torch.empty(3, device="meta")  # a tensor with no host memory (as a CUDA tensor on arch=cpu)
    with pytest.raises(SimgradTypeError, match="is on device meta: the program runs on the CPU") as e:
        _scale(meta, 1.0)
    assert _here(e)


def test_dtypes_and_dimensions_pick_instances():
    @ti.kernel
    def fill(x: ti.types.ndarray()):
        for I in ti.grouped(x):
            x[I] = 7

    for dtype in (torch.float16, torch.float32, torch.float64, torch.int8, torch.int16, torch.int32, torch.int64,
                  torch.uint8):
        for shape in ((3,), (2, 3), (2, 1, 3)):
            t = torch.zeros(shape, dtype=dtype)
            fill(t)
            assert (t == 7).all(), (dtype, shape)


def test_zero_size_tensors():
    @ti.kernel
    def nothing(arr: ti.types.ndarray()):
        pass

    nothing(torch.zeros(0, dtype=torch.int32))
    nothing(torch.zeros((5, 0, 5), dtype=torch.int32))


def test_vector_elements_from_trailing_axes():
    @ti.kernel
    def norms(v: ti.types.ndarray(dtype=ti.math.vec3, ndim=1), out: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in v:
            out[i] = v[i].norm()

    v = torch.tensor([[3.0, 4.0, 0.0], [1.0, 2.0, 2.0]])
    out = torch.zeros(2)
    norms(v, out)
    np.testing.assert_allclose(out.numpy(), [5.0, 3.0])


class DLPackOnly:
    """An array that offers only the DLPack protocol (as a JAX or CuPy array does)."""

    def __init__(self, arr):
        self.arr = arr

    def __dlpack__(self, **kwargs):
        return self.arr.__dlpack__(**kwargs)

    def __dlpack_device__(self):
        return self.arr.__dlpack_device__()


class DeviceOnly(DLPackOnly):
    def __dlpack_device__(self):
        return (2, 0)  # kDLCUDA


def test_any_dlpack_array_is_taken_by_reference():
    a = np.arange(4, dtype=np.float32)
    _scale(DLPackOnly(a), 2.0)
    np.testing.assert_array_equal(a, [0, 2, 4, 6])
    with pytest.raises(SimgradValueError, match="Non contiguous arrays"):
        _scale(DLPackOnly(np.ones((4, 2), np.float32)[:, 0]), 2.0)
    with pytest.raises(SimgradTypeError, match="DLPack device 2") as e:
        _scale(DeviceOnly(a), 2.0)
    assert _here(e)


@ti.kernel
def _square_sum(x: ti.types.ndarray(), y: ti.types.ndarray()):
    for i in x:
        y[0] += x[i] * x[i]


def test_kernel_grad_accumulates_into_the_tensors_grad():
    x = torch.tensor([1.0, 2.0, 3.0], requires_grad=True)
    y = torch.zeros(1, requires_grad=True)
    _square_sum(x, y)
    assert y.item() == 14.0
    y.grad.fill_(1.0)  # made by the launch, as Taichi does
    _square_sum.grad(x, y)
    np.testing.assert_array_equal(x.grad.numpy(), [2, 4, 6])
    _square_sum.grad(x, y)  # accumulates, as torch does
    np.testing.assert_array_equal(x.grad.numpy(), [4, 8, 12])


def test_an_explicit_gradient_pair():
    x, gx = np.array([1.0, 2.0, 3.0]), np.zeros(3)
    y, gy = np.zeros(1), np.ones(1)
    _square_sum(ti.ad.with_grad(x, gx), ti.ad.with_grad(y, gy))
    assert y[0] == 14.0
    _square_sum.grad(ti.ad.with_grad(x, gx), ti.ad.with_grad(y, gy))
    np.testing.assert_array_equal(gx, [2, 4, 6])
    t, gt = torch.ones(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64)  # torch arrays too
    _square_sum.grad(ti.ad.with_grad(t, gt), ti.ad.with_grad(y, gy))
    np.testing.assert_array_equal(gt.numpy(), [2, 2, 2])
    assert t.grad is None
    with pytest.raises(SimgradValueError, match="the gradient must have the value's shape"):
        ti.ad.with_grad(x, np.zeros(2))
    with pytest.raises(SimgradTypeError, match="gradients need a floating-point array"):
        ti.ad.with_grad(np.zeros(3, np.int32), np.zeros(3, np.int32))


def test_tape_with_tensor_arguments_f64_against_finite_differences():
    ti.init(arch=ti.cpu, default_fp=ti.f64)

    @ti.kernel
    def energy(x: ti.types.ndarray(), w: ti.types.ndarray(), loss: ti.types.ndarray()):
        for i in x:
            loss[0] += ti.sin(x[i] * w[i]) * x[i]

    rng = np.random.default_rng(1)
    x0, w0 = rng.random(5), rng.random(5)
    x = torch.tensor(x0, requires_grad=True)
    w = torch.tensor(w0, requires_grad=True)
    loss = torch.zeros(1, dtype=torch.float64, requires_grad=True)
    with ti.ad.Tape(loss=loss):
        energy(x, w, loss)

    def f(xv, wv):
        out = np.zeros(1)
        energy(xv, wv, out)
        return out[0]

    eps = 1e-6
    for k in range(5):
        d = np.zeros(5)
        d[k] = eps
        assert x.grad[k].item() == pytest.approx((f(x0 + d, w0) - f(x0 - d, w0)) / (2 * eps), rel=1e-6)
        assert w.grad[k].item() == pytest.approx((f(x0, w0 + d) - f(x0, w0 - d)) / (2 * eps), rel=1e-6)


def test_needs_grad_false_leaves_the_tensors_gradient_alone():
    @ti.kernel
    def k(x: ti.types.ndarray(needs_grad=False), y: ti.types.ndarray()):
        for i in range(3):
            y[0] += x[i]

    x = torch.rand(3, requires_grad=True)
    y = torch.zeros(1, requires_grad=True)
    k(x, y)
    y.grad.fill_(1.0)
    k.grad(x, y)
    assert x.grad is None or (x.grad == 0).all()


def test_fields_to_and_from_torch():
    x = ti.Vector.field(3, ti.f32, shape=(4, 2))
    t = torch.arange(24, dtype=torch.float32).reshape(4, 2, 3)
    x.from_torch(t)
    assert x[1, 0][2] == 8.0
    back = x.to_torch()
    assert back.dtype == torch.float32 and (back == t).all()
    back[0, 0, 0] = -1.0  # to_torch is a copy
    assert x[0, 0][0] == 0.0
    assert x.to_torch(device="cpu").device == torch.device("cpu")
    s = ti.Struct.field({"a": ti.i32, "b": ti.f32}, shape=(3,))
    s.from_torch({"a": torch.tensor([1, 2, 3], dtype=torch.int32), "b": torch.tensor([0.5, 1.5, 2.5])})
    assert s[1].a == 2 and s[2].b == 2.5
    d = s.to_torch()
    assert (d["a"] == torch.tensor([1, 2, 3], dtype=torch.int32)).all()


def test_a_tape_loss_tensor_must_be_one_element_with_a_gradient():
    with pytest.raises(RuntimeError, match="must be a tensor only contains one element"):
        ti.ad.Tape(loss=torch.ones(2, requires_grad=True))
    with pytest.raises(RuntimeError, match="The loss tensor has no gradient"):
        ti.ad.Tape(loss=torch.ones(1))


def test_a_tape_in_a_training_loop_follows_a_replaced_grad_tensor():
    """optimizer.zero_grad(set_to_none=True) replaces x.grad between iterations: the captured backward pass
    (lang/tape.py) must not replay into the old buffer (a tensor's key never matches: it is packed anew)."""
    torch = pytest.importorskip("torch")
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f(x: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        for i in range(x.shape[0]):
            loss[None] += x[i] ** 2

    x = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64, requires_grad=True)
    for it in range(3):
        x.grad = None
        with ti.ad.Tape(loss=loss):
            f(x)
        assert x.grad is not None and torch.equal(x.grad, 2 * x.detach()), (it, x.grad)
        with torch.no_grad():
            x -= 0.1 * x.grad
