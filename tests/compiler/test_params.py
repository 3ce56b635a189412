"""Kernel parameters are one typed family (compiler/params.py): a new kind of argument is one class and a
`register`, with no edit to the driver, the @ti.kernel object, the launcher or the Tape. Two toy kinds show it:
a boxed scalar under a new annotation (an object whose `.value` travels as a scalar: the built-in packing with
a member path), and a new argument type under ti.types.ndarray() (an object with a pointer `.ptr` and a length
`.n`, as a torch tensor or a device array would be: a subclass of the ndarray kind with its own Packing).
Also: the Tape's slice watching reads each parameter's slots through its packing, so struct arguments no
longer shift the scalar arguments after them."""

import pickle

import numpy as np
import pytest

import simgrad as ti
from simgrad import dtypes as dt
from simgrad.compiler import params
from simgrad.errors import GradientError, SimgradTypeError
from simgrad.frontend.arrays import ArrayArg
from simgrad.runtime.args import LaunchCode, Packing, ScalarPacking, TensorPacking


class Boxed:
    """The toy annotation: `b: Boxed(ti.f32)` takes any object with a `.value`."""

    def __init__(self, dtype):
        self.dtype = dtype


class Box:
    def __init__(self, value):
        self.value = value


class BoxedParam(params.Param):
    @classmethod
    def accepts(cls, ann) -> bool:
        return isinstance(ann, Boxed)

    def bind(self, a, slots):
        value, slot = slots.arg(self.ann.dtype)
        return value, ScalarPacking(self.name, slot, self.ann.dtype, path=("value",))


class Raw:
    """A raw array: a base address `.ptr` and a length `.n`, what a device array would pass (a pointer the
    Python side cannot look into)."""

    def __init__(self, arr: np.ndarray):
        self.arr, self.ptr, self.n = arr, arr.ctypes.data, arr.shape[0]


class RawPacking(Packing):
    def __init__(self, name: str, slot: int):
        super().__init__(name)
        self.slot = slot

    def launch_code(self, gen: LaunchCode, src: str) -> list[str]:
        return [f"_buf[{gen.word(self.slot)}] = {src}.ptr", f"_buf[{gen.word(self.slot + 1)}] = {src}.n"]


class RawOrNdarrayParam(params.NdarrayParam):
    """A kind for a new argument type under an existing annotation (as torch tensors or device arrays are
    under ti.types.ndarray()): it takes over the annotation and defers to the ndarray kind for other values."""

    def key(self, a, keep):
        if isinstance(a, Raw):
            return ("raw", self.ann.dtype)
        return super().key(a, keep)

    def bind(self, a, slots):
        if not isinstance(a, Raw):
            return super().bind(a, slots)
        arg = ArrayArg(self.name, slots.count, dt.from_any(self.ann.dtype), 1)
        slots.take(arg.num_slots)
        return arg, RawPacking(self.name, arg.slot)


@pytest.fixture
def toy_kinds():
    params.register(BoxedParam)
    params.register(RawOrNdarrayParam)
    yield
    params.KINDS.remove(BoxedParam)
    params.KINDS.remove(RawOrNdarrayParam)


def test_a_boxed_scalar_kind_is_one_registered_class(toy_kinds):
    out = np.zeros(3, np.float64)

    @ti.kernel
    def k(b: Boxed(ti.f64), n: ti.i32, o: ti.types.ndarray()):
        for i in range(n):
            o[i] = b * i

    k(Box(1.5), 3, out)
    np.testing.assert_array_equal(out, [0.0, 1.5, 3.0])
    k(Box(-2), 3, out)  # one instantiation: the value is a run-time argument, checked as a scalar's
    np.testing.assert_array_equal(out, [0.0, -2.0, -4.0])
    assert len(k._caches[""]) == 1
    with pytest.raises(SimgradTypeError, match="'b__value' expects a f64 scalar, got str"):
        k(Box("x"), 3, out)


def test_a_boxed_scalar_is_differentiable_and_its_slot_is_watched(toy_kinds):
    """The Tape reads the box's value through the packing: `x[t - 1, i]` with a boxed t watches one slice."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=(3, 2), needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def step(t: Boxed(ti.i32), c: Boxed(ti.f64)):
        for i in range(2):
            x[t, i] = x[t - 1, i] * c

    @ti.kernel
    def total():
        for i in range(2):
            loss[None] += x[2, i]

    x.from_numpy(np.ones((3, 2)))
    with ti.ad.Tape(loss=loss, validation=True):
        step(Box(1), Box(3.0))  # reads x[0]
        step(Box(2), Box(3.0))  # reads x[1], writes x[2]: allowed, x[0] is untouched
        total()
    np.testing.assert_allclose(x.grad.to_numpy()[0], [9.0, 9.0])


def test_a_new_argument_type_of_the_ndarray_annotation_brings_its_own_packing(toy_kinds):
    data = np.zeros(5, np.float32)

    @ti.kernel
    def fill(a: ti.types.ndarray(dtype=ti.f32, ndim=1), s: ti.f32):
        for i in range(a.shape[0]):
            a[i] = s * i

    fill(Raw(data), 2.0)
    ti.sync()  # memory simgrad does not know of: the host waits for the kernel itself (arch=cuda)
    np.testing.assert_array_equal(data, [0, 2, 4, 6, 8])
    short = np.zeros(3, np.float32)
    fill(Raw(short), 1.0)  # the extent is a run-time value: same instantiation
    ti.sync()
    np.testing.assert_array_equal(short, [0, 1, 2])
    assert len(fill._caches[""]) == 1
    fill(data, 3.0)  # a numpy array still goes the ndarray kind's way: its own instantiation
    np.testing.assert_array_equal(data, [0, 3, 6, 9, 12])
    assert len(fill._caches[""]) == 2
    with pytest.raises(SimgradTypeError, match="expects an ndarray, got Box"):
        fill(Box(1), 1.0)


def test_an_unregistered_annotation_is_refused():
    with pytest.raises(SimgradTypeError, match="parameter 'b' has an unsupported annotation"):
        @ti.kernel
        def k(b: Boxed(ti.f32)):
            pass


def test_every_kind_is_a_class_and_packings_pickle():
    """Each built-in annotation gets its own Param class; the packings go to the kernel cache (pickled)."""
    S = ti.types.struct(a=ti.f32, b=ti.types.vector(2, ti.i32))
    # ti.types.ndarray(): the tensor kind, a subclass of the ndarray kind that defers to it for numpy arrays
    anns = {ti.template(): params.TemplateParam, ti.types.ndarray(): params.TensorParam,
            ti.types.vector(3, ti.f32): params.MatrixParam, ti.types.sparse_matrix_builder(): params.BuilderParam,
            S: params.StructParam, ti.f32: params.ScalarParam, int: params.ScalarParam}
    for ann, kind in anns.items():
        assert type(params.make_param("p", ann, "k")) is kind
    assert type(params.make_param("self", params.inspect.Parameter.empty, "k", first=True)) is params.TemplateParam
    leaf = ScalarPacking("s", 3, dt.i64, path=("c", "d"))
    back = pickle.loads(pickle.dumps(leaf))
    assert (back.name, back.slot, back.dtype, back.path) == ("s", 3, dt.i64, ("c", "d"))
    assert back.slot_values({"c": {"d": 7}}) == {3: 7}
    tp = pickle.loads(pickle.dumps(TensorPacking("t", 2, dt.f32, 1, 1, 4, pair=True)))
    assert (tp.slot, tp.grad_slot, tp.pair) == (2, 4, True)


def _sliced_program():
    x = ti.field(ti.f64, shape=(3, 2), needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    x.from_numpy(np.ones((3, 2)))

    @ti.kernel
    def total():
        for i in range(2):
            loss[None] += x[2, i]

    return x, loss, total


def test_a_scalar_after_a_struct_argument_picks_the_watched_slice():
    """Tape(validation=True) used to pair the struct's leaves with the arguments after it: `t` had no value,
    so the whole field was watched and a legal t - 1 / t program was refused."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    S = ti.types.struct(c=ti.f64)
    x, loss, total = _sliced_program()

    @ti.kernel
    def step(s: S, t: ti.i32):
        for i in range(2):
            x[t, i] = x[t - 1, i] * s.c

    with ti.ad.Tape(loss=loss, validation=True):
        step(S(c=3.0), 1)
        step(S(c=3.0), 2)
        total()
    np.testing.assert_allclose(x.grad.to_numpy()[0], [9.0, 9.0])


def test_a_struct_leaf_index_watches_its_own_slice():
    """A struct leaf as the leading index: its own value picks the watched slice (it used to take the next
    argument's, so overwriting the slice really read went unnoticed: a silently wrong gradient)."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    S = ti.types.struct(t=ti.i32)
    x, loss, total = _sliced_program()

    @ti.kernel
    def read(s: S, k: ti.i32):
        for i in range(2):
            x[2, i] += x[s.t, i] * k

    @ti.kernel
    def clobber():
        for i in range(2):
            x[0, i] = 5.0

    with pytest.raises(GradientError, match="field 'x' was modified after kernel read"):
        with ti.ad.Tape(loss=loss, validation=True):
            read(S(t=0), 1)  # reads x[0]
            clobber()  # overwrites x[0]
            total()


def test_a_constant_vector_template_is_keyed_by_value():
    """`k(ti.Vector([1, 2]))` with a new but equal vector each call finds the same instance (it was keyed by
    identity: a compile and a kept object per call, 2.8 ms per sparse to_numpy); another value compiles its own."""
    ti.init(arch=ti.cpu)
    out = ti.field(ti.i32, shape=2)

    @ti.kernel
    def k(v: ti.template()):
        for i in range(2):
            out[i] = v[i] * 10

    for _ in range(5):
        k(ti.Vector([1, 2]))
    assert len(k._caches[""]) == 1 and out.to_numpy().tolist() == [10, 20]
    k(ti.Vector([3, 4]))
    assert len(k._caches[""]) == 2 and out.to_numpy().tolist() == [30, 40]
    v = ti.Vector([5, 6])
    k(v)
    v[0] = 7  # changed after its instance was made: the new value compiles anew, never the stale constant
    k(v)
    assert out.to_numpy().tolist() == [70, 60]
