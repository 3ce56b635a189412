"""Quantized types (Taichi's QuanTaichi): ti.types.quant.int / fixed / float, ti.BitpackedFields (shared exponents),
ti.root.quant_array; reads, writes and atomics on packed bits, in kernels and Python scope.

EXPECTED holds what Taichi 1.7.4 prints for tests/lang/quant_reference.py (`cd tests/lang &&
/work/tivenv/bin/python quant_reference.py`); simgrad must give exactly the same values. Everything else is checked
against numpy."""

import numpy as np
import pytest

import simgrad as ti
from tests.lang.quant_reference import cases

EXPECTED = {'int5': [0.0, 1.0, -1.0, 15.0, -16.0, -16.0, -12.0, 15.0, 4.0, -4.0],
 'uint3': [0.0, 1.0, 7.0, 0.0, 1.0, 7.0, 0.0],
 'int7_f': [10.0, -10.0, 10.0, -10.0, 63.0, -64.0],
 'fixed8': [0.0, 0.296875, -0.296875, 1.984375, -2.0, -1.5, 1.5, 0.015625, -0.015625, 0.03125, 1.0, -1.0, 0.0625],
 'ufixed8': [0.0, 0.296875, 1.9921875, 0.5, 0.0078125, 0.0234375, 1.0, 0.0546875, 1.9921875],
 'fixed13s': [0.699999988079071, 1.2000000476837158, -0.4000000059604645, 0.30000001192092896, -0.30000001192092896,
              409.5, -409.6000061035156, -409.6000061035156],
 'float5_10': [0.0, 1.0, -1.0, 1.5, 3.140625, -3.140625, 0.00099945068359375, 0.0, 0.0, 65536.0, 70016.0,
               2.33203125, 0.0999755859375, -0.0999755859375, 6.103515625e-05, 0.0, 1.001953125, 1.0],
 'ufloat5_11': [0.0, 1.0, 1.0, 1.5, 3.1416015625, 3.1416015625, 0.0009999275207519531, 0.0, 0.0, 65504.0, 70016.0,
                2.3291015625, 0.100006103515625, 0.100006103515625, 6.103515625e-05, 0.0, 1.0009765625,
                1.00048828125],
 'float8_24': [0.0, 1.0, -1.0, 1.5, 3.141590118408203, -3.141590118408203, 0.0010000000474974513,
               9.999999974752427e-07, 9.999999717180685e-10, 65504.0, 70000.0, 10000000000.0, 0.10000000149011612,
               -0.10000000149011612, 6.103515625e-05, 3.0517578125e-05, 1.0009765625, 1.00048828125,
               1.0000000150474662e+30, -1.0000000031710769e-30, 3.3999999521443642e+38],
 'shared_u': [[0.0, 1.0, 3.19921875, 100.0, 0.27001953125, 1000.0, 5.0, 0.00099945068359375, 7.0, 0.0],
              [0.0, 1.0, 3.19921875, 100.0, 0.27001953125, 1000.0, 5.0, 0.0, 7.0, 0.0],
              [0.0, 0.25, 0.25, 0.25, 0.0, 1000.0, 3.0, 123.0, 0.0, 5.5]],
 'shared_s': [[0.0, 1.0, 3.19921875, 100.0, 0.27001953125, 1000.0, 5.0, 0.00099945068359375, 7.0, 0.0],
              [0.0, 1.0, 3.19921875, 100.0, 0.27001953125, 1000.0, 5.0, 0.0, 7.0, 0.0],
              [0.0, 0.25, 0.25, 0.25, 0.0, 1000.0, -3.0, 123.0, -0.000244140625, 5.5]],
 'fused': [[14.25, -17.875], [2.921875, -3.96875], [-3.171875, -1.515625], [-14.125, -1.625], [-6.0, 23.25],
           [1.578125, -2.46875], [-1.96875, -4.6875], [-7.375, -2.75], [3.375, -1.671875], [6.71875, -1.40625],
           [0.1875, 10.8125], [3.8125, -3.53125], [-1.28125, 3.78125], [13.5625, -1.875], [-1.71875, 7.03125],
           [-6.21875, -2.03125], [6.1875, 4.0625], [0.625, 4.6875], [-19.75, 7.125], [-6.6875, -11.6875],
           [1.9375, 4.90625], [-3.125, -7.53125], [0.18359375, -0.369140625], [9.8125, 5.25], [1.34375, 7.78125],
           [-1.4375, -6.46875], [4.09375, 4.0625], [-1.5, -5.46875], [1.625, -17.5], [4.84375, 3.4375],
           [-11.5, 0.4375], [-6.75, 5.3125], [-14.25, -6.375], [4.9375, 8.125], [-15.125, -3.5], [2.28125, -4.25],
           [11.125, -8.3125], [2.46875, -7.34375], [9.8125, -0.125], [-2.625, -12.0], [11.75, 5.25],
           [5.28125, 7.96875], [2.4375, -4.46875], [-5.59375, -5.59375], [9.5625, -10.25], [-4.1875, -2.25],
           [1.5625, 4.03125], [-8.75, -12.125], [-0.015625, 8.5], [5.3125, 1.5], [-2.21875, 2.046875],
           [-1.71875, 5.71875], [-5.5625, 0.9375], [-0.78125, 3.796875], [1.625, 17.875], [10.5, 10.5],
           [-14.25, -2.375], [-4.25, 3.71875], [-15.9375, 8.25], [7.5, -9.125], [-6.84375, -5.59375], [0.3125, 4.5],
           [14.3125, -1.375], [5.375, 1.09375]],
 'not_fused': [[14.375, -17.875], [2.921875, -3.96875], [-3.171875, -1.515625], [-14.125, -1.625], [-6.125, 23.25],
               [1.578125, -2.46875], [-1.96875, -4.6875], [-7.375, -2.75], [3.375, -1.671875], [6.71875, -1.40625],
               [0.1875, 10.8125], [3.8125, -3.53125], [-1.28125, 3.78125], [13.5625, -1.875], [-1.71875, 7.03125],
               [-6.21875, -2.03125], [6.1875, 4.0625], [0.65625, 4.6875], [-19.75, 7.125], [-6.75, -11.6875],
               [1.9375, 4.90625], [-3.125, -7.53125], [0.18359375, -0.369140625], [9.8125, 5.25], [1.375, 7.78125],
               [-1.4375, -6.46875], [4.09375, 4.0625], [-1.5, -5.46875], [1.625, -17.5], [4.84375, 3.4375],
               [-11.5, 0.4375], [-6.75, 5.3125], [-14.25, -6.375], [5.0, 8.125], [-15.125, -3.5], [2.3125, -4.25],
               [11.125, -8.3125], [2.5, -7.34375], [9.8125, -0.125], [-2.625, -12.0], [11.75, 5.25],
               [5.28125, 7.96875], [2.4375, -4.46875], [-5.59375, -5.59375], [9.5625, -10.25], [-4.1875, -2.25],
               [1.5625, 4.03125], [-8.75, -12.125], [-0.015625, 8.5], [5.3125, 1.5], [-2.21875, 2.046875],
               [-1.71875, 5.71875], [-5.5625, 0.9375], [-0.78125, 3.796875], [1.625, 17.875], [10.5, 10.5],
               [-14.25, -2.375], [-4.25, 3.71875], [-15.9375, 8.25], [7.5, -9.125], [-6.84375, -5.59375],
               [0.3125, 4.5], [14.3125, -1.375], [5.375, 1.09375]],
 'atomics': [3000, -8, 10.0, [-200, -100, 0, 100], 1.25]}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_values_as_taichi(name):
    """Wrap-around of ints, fixed-point rounding (half away from zero), float rounding, flush to zero and
    exponent overflow, shared exponents, store fusion (`fused` differs from `not_fused`, where a read between
    the two stores makes each recode the other's rounded digits) and atomics: bit for bit Taichi 1.7.4's."""
    got = _cases()
    assert got[name] == EXPECTED[name]


_memo: dict = {}


def _cases():
    if "out" not in _memo:  # one program for all the cases (they make many fields)
        _memo["out"] = cases(ti)
    return _memo["out"]


def test_memory_is_packed():
    """Bytes per element: a 13-bit and a 19-bit int share one u32 per cell; 1-bit ints take 1/8 byte each in a
    quant_array; an 8 + 8-bit pair in BitpackedFields(16) takes 2 bytes (Taichi's physical types)."""
    x = ti.field(dtype=ti.types.quant.int(13, True))
    y = ti.field(dtype=ti.types.quant.int(19, False))
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(x, y)
    ti.root.dense(ti.i, 1000).place(bp)
    x[0] = 1  # (a field made before this and still unplaced would be an error here, as in Taichi)
    assert x.snode.tree.size == 4 * 1000
    bits = ti.field(dtype=ti.types.quant.int(1, False))
    ti.root.dense(ti.i, 4096 // 32).quant_array(ti.i, 32, max_num_bits=32).place(bits)
    bits[5] = 1
    assert bits.snode.tree.size == 4096 // 8
    a = ti.field(dtype=ti.types.quant.fixed(8, max_value=1.0))
    c = ti.field(dtype=ti.types.quant.int(8, False))
    bp16 = ti.BitpackedFields(max_num_bits=16)
    bp16.place(a, c)
    ti.root.dense(ti.ij, (10, 10)).place(bp16)
    a[1, 2] = 0.5
    assert a.snode.tree.size == 2 * 100
    assert bits.to_numpy().sum() == 1 and bits[5] == 1


def test_parallel_writes_of_neighbouring_bits():
    """The elements of a cell are written by iterations on different threads (32 1-bit values per u32, 3-bit
    values in u8 cells): no write is lost (compare-and-swap on the cell; plain read-modify-writes fail this)."""
    n = 1 << 20
    b = ti.field(dtype=ti.types.quant.int(1, False))
    ti.root.dense(ti.i, n // 32).quant_array(ti.i, 32, max_num_bits=32).place(b)
    t = ti.field(dtype=ti.types.quant.int(3, True))
    ti.root.dense(ti.i, n // 2).quant_array(ti.i, 2, max_num_bits=8).place(t)
    ref = ti.field(ti.i32, shape=n)
    rng = np.random.default_rng(1)
    want = rng.integers(0, 2, n).astype(np.int32)
    want3 = rng.integers(-4, 4, n).astype(np.int32)
    ref.from_numpy(want3)

    @ti.kernel
    def write(src: ti.types.ndarray()):
        for i in range(n):
            e = i * 7919 % n  # a permutation: every thread writes into every cell
            b[e] = src[e]
            t[e] = ref[e]

    for _ in range(3):
        b.fill(0)
        write(want)
        np.testing.assert_array_equal(b.to_numpy(), want)
        np.testing.assert_array_equal(t.to_numpy(), want3)


def test_parallel_atomics_on_shared_cells():
    """Many iterations update three members of one cell and the elements of a quant_array at once: the sums are
    numpy's, wrapped to the members' widths."""
    x = ti.field(dtype=ti.types.quant.int(12, True))
    y = ti.field(dtype=ti.types.quant.int(10, False))
    z = ti.field(dtype=ti.types.quant.fixed(10, scale=0.5))
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(x, y, z)
    ti.root.place(bp)
    q = ti.field(dtype=ti.types.quant.int(8, True))
    ti.root.quant_array(ti.i, 4, max_num_bits=32).place(q)
    n = 400000

    @ti.kernel
    def go():
        for i in range(n):
            x[None] += 1
            y[None] += i % 3
            z[None] -= 0.5
            q[i % 4] += (i % 7) - 3

    go()
    w = lambda v, bits: (v + (1 << (bits - 1))) % (1 << bits) - (1 << (bits - 1))  # noqa: E731
    i = np.arange(n)
    assert x[None] == w(n, 12)
    assert y[None] == int((i % 3).sum()) % 1024
    assert z[None] == w(-n, 10) * 0.5
    assert [q[k] for k in range(4)] == [w(int((i[i % 4 == k] % 7 - 3).sum()), 8) for k in range(4)]


def test_atomic_min_max_and_result():
    """ti.atomic_max / min / and / or on quant ints (Taichi 1.7.4 aborts in LLVM on these) and the old value an
    atomic add returns (taichi returns the whole physical word): numpy's values."""
    m = ti.field(dtype=ti.types.quant.int(10, True))
    u = ti.field(dtype=ti.types.quant.int(6, False))
    bp = ti.BitpackedFields(max_num_bits=16)
    bp.place(m, u)
    ti.root.dense(ti.i, 4).place(bp)
    olds = ti.field(ti.i32, shape=3)
    vals = np.array([5, -300, 17, 250, -2, 99, 400, -511, 0, 3], np.int32)

    @ti.kernel
    def go(v: ti.types.ndarray()):
        for k in range(4):
            m[k] = -512
            u[k] = 0b101010
        for i in range(10):
            ti.atomic_max(m[i % 4], v[i])
        ti.atomic_min(m[3], -3)
        ti.atomic_and(u[1], 0b001111)
        ti.atomic_or(u[2], 0b000101)
        ti.atomic_xor(u[3], 0b111111)
        olds[0] = ti.atomic_add(m[0], 10)
        olds[1] = ti.atomic_sub(u[0], 50)
        olds[2] = ti.atomic_add(m[0], 0)

    go(vals)
    want = [int(max([-512] + [int(v) for v in vals[k::4]])) for k in range(4)]
    want[3] = min(want[3], -3)
    want[0] += 10
    assert [m[k] for k in range(4)] == want
    assert [u[k] for k in range(4)] == [(0b101010 - 50) % 64, 0b001010, 0b101111, 0b010101]
    assert olds.to_numpy().tolist() == [want[0] - 10, 0b101010, want[0]]


def test_python_scope_numpy_and_vectors():
    """x[i] = v, to_numpy, from_numpy and fill in Python scope (through kernels), on scalar and vector quant
    fields; values rounded as in kernels."""
    fx = ti.types.quant.fixed(bits=16, max_value=2.0)
    v = ti.Vector.field(2, dtype=fx)
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(v)
    ti.root.dense(ti.i, 8).place(bp)
    s = ti.field(dtype=ti.types.quant.int(5, True))
    ti.root.dense(ti.ij, (2, 3)).quant_array(ti.j, 2, max_num_bits=16).place(s)
    assert s.shape == (2, 6)
    arr = np.linspace(-1.9, 1.9, 16, dtype=np.float32).reshape(8, 2)
    v.from_numpy(arr)
    scale = np.float32(2.0 / 2**15)
    coded = np.floor(np.abs(arr * np.float32(1 / scale)) + np.float32(0.5)) * np.sign(arr)
    np.testing.assert_array_equal(v.to_numpy(), coded.astype(np.float32) * scale)
    v[3] = [0.25, -0.5]
    assert v[3][0] == 0.25 and v[3][1] == -0.5
    ints = np.arange(12, dtype=np.int32).reshape(2, 6) * 5 - 30
    s.from_numpy(ints)
    np.testing.assert_array_equal(s.to_numpy(), (ints + 16) % 32 - 16)
    s.fill(-7)
    assert (s.to_numpy() == -7).all()
    s[1, 4] = 15
    assert s[1, 4] == 15 and s[1, 5] == -7 and s[0, 4] == -7


def test_struct_for_and_sparse():
    """A struct-for over a quant field under a pointer visits its active cells; reads of inactive ones give 0."""
    x = ti.field(dtype=ti.types.quant.int(7, True))
    cell = ti.root.pointer(ti.i, 4)
    cell.dense(ti.i, 4).quant_array(ti.i, 4, max_num_bits=32).place(x)
    y = ti.field(dtype=ti.types.quant.fixed(bits=12, max_value=100.0))
    bp = ti.BitpackedFields(max_num_bits=16)
    bp.place(y)
    ti.root.pointer(ti.i, 4).dense(ti.i, 16).place(bp)

    @ti.kernel
    def fill():
        for i in range(64):
            if i // 16 % 2 == 0:
                x[i] = i - 40
                y[i] = i * 1.5

    @ti.kernel
    def bump():
        for i in x:
            x[i] += 1
        for i in y:
            y[i] -= 1.0

    fill()
    bump()
    i = np.arange(64)
    on = (i // 16 == 0) | (i // 16 == 2)
    np.testing.assert_array_equal(x.to_numpy(), np.where(on, i - 39, 0))
    step = np.float32(100.0 / 2**11)
    want = (np.round(np.float32(1.5) * i / step) - np.round(1.0 / step)) * step
    np.testing.assert_allclose(y.to_numpy(), np.where(on, want, 0).astype(np.float32), rtol=0, atol=1e-6)


def test_kernel_cache_keys_the_quant_type():
    """The same kernel source over a field of another quant type (same layout) compiles again: the kernel cache
    must not hand back the first type's code."""
    results = []
    for bits in (4, 6):
        ti.init(arch=ti.cpu)
        x = ti.field(dtype=ti.types.quant.int(bits, True))
        bp = ti.BitpackedFields(max_num_bits=8)
        bp.place(x)
        ti.root.place(bp)
        results.append(_store_and_read(x))
    assert results == [4, 20]


def _store_and_read(x):
    @ti.kernel
    def go() -> ti.i32:
        x[None] = 20
        return x[None]

    return go()


def test_with_autodiff_values_are_constants():
    """A kernel differentiated under a Tape may read quant fields: they are constants to the gradient."""
    w = ti.field(dtype=ti.types.quant.fixed(bits=16, max_value=4.0))
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(w)
    ti.root.dense(ti.i, 4).place(bp)
    p = ti.field(ti.f32, shape=4, needs_grad=True)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)
    w.from_numpy(np.array([0.5, 1.0, -2.0, 3.0], np.float32))
    p.from_numpy(np.array([1.0, 2.0, 3.0, 4.0], np.float32))

    @ti.kernel
    def f():
        for i in range(4):
            loss[None] += w[i] * p[i] ** 2

    with ti.ad.Tape(loss):
        f()
    np.testing.assert_allclose(p.grad.to_numpy(), 2 * np.array([0.5, 1.0, -2.0, 3.0]) * np.arange(1, 5))


def _here():
    import inspect

    return inspect.currentframe().f_back.f_lineno


@pytest.mark.parametrize("case", ["needs_grad", "shape", "direct", "overflow", "shared_one", "not_quant", "array"])
def test_refusals_are_located(case):
    """Misuse is a located error at the user's line (needs_grad: Taichi does not differentiate quant types)."""
    qi = ti.types.quant.int(20, True)
    x = ti.field(dtype=qi)
    with pytest.raises(ti.TaichiCompilationError if case in ("shared_one", "not_quant") else Exception) as e:
        if case == "needs_grad":
            line = _here() + 1
            ti.field(dtype=ti.types.quant.fixed(8), needs_grad=True)
        elif case == "shape":
            line = _here() + 1
            ti.field(dtype=qi, shape=4)
        elif case == "direct":
            line = _here() + 1
            ti.root.dense(ti.i, 4).place(x)
        elif case == "overflow":
            bp = ti.BitpackedFields(max_num_bits=32)
            line = _here() + 1
            bp.place(x, ti.field(dtype=qi))
        elif case == "shared_one":
            bp = ti.BitpackedFields(max_num_bits=32)
            line = _here() + 1
            bp.place(ti.field(dtype=ti.types.quant.float(exp=5, frac=10)), shared_exponent=True)
        elif case == "not_quant":
            bp = ti.BitpackedFields(max_num_bits=32)
            line = _here() + 1
            bp.place(ti.field(ti.f32))
        else:
            line = _here() + 1
            ti.root.quant_array(ti.i, 2, max_num_bits=32).place(x)
    loc = e.value.loc
    assert loc is not None and loc.file == __file__ and loc.line == line, (str(e.value), loc)
    if case == "shared_one":
        assert "At least 2 fields need to be placed when shared_exponent=True" in str(e.value)


def test_types_namespace():
    """ti.types.quant's public names are Taichi's."""
    assert sorted(n for n in dir(ti.types.quant) if not n.startswith("_")) == ["fixed", "float", "i32", "impl", "int"]
    assert ti.types.quant.i32 is ti.i32
    assert repr(ti.types.quant.int(5, False)) == "qu5"


def test_python_scope_write_wraps_like_a_kernel():
    """`b[None] = -64` on a 7-bit unsigned quant int computing in u16 keeps the low bits (64), as a kernel's store
    and Taichi do (Taichi's test_cast.py test_quant_int_extension); a plain u16 field would refuse the value."""
    a = ti.field(dtype=ti.types.quant.int(5, True, ti.i16))
    b = ti.field(dtype=ti.types.quant.int(7, False, ti.u16))
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(a, b)
    ti.root.place(bp)
    a[None] = -16
    b[None] = -64
    assert a[None] == -16 and b[None] == 64
    x = ti.field(ti.u32, shape=2)

    @ti.kernel
    def widen():
        x[0] = ti.cast(a[None], ti.u32)
        x[1] = ti.cast(b[None], ti.u32)

    widen()
    assert x.to_numpy().tolist() == [0xFFFFFFF0, 64]


def test_matrix_field_of_entry_types():
    """ti.Matrix.field(2, 2, dtype=[[qflt, qfxt], [qflt, qfxt]]): one quant type per entry, one compute type;
    mixing compute types is Taichi's RuntimeError. FieldsBuilder has quant_array too."""
    qflt = ti.types.quant.float(exp=8, frac=5)
    qfxt = ti.types.quant.fixed(bits=10, scale=0.1)
    a = ti.Matrix.field(2, 2, dtype=[[qflt, qfxt], [qflt, qfxt]])
    for r in range(2):
        bp = ti.BitpackedFields(max_num_bits=32)
        bp.place(a.get_scalar_field(r, 0), a.get_scalar_field(r, 1))
        ti.root.dense(ti.i, 1).place(bp)

    @ti.kernel
    def init():
        a[0] = [[1.3, 3.14], [-2.6, 0.06]]

    init()
    # 4 digit bits of f32 1.3 round to 1.3125 (1.0101b); fixed 3.14 -> 31 * 0.1; -2.6 -> -2.625; 0.06 -> 0.1
    np.testing.assert_allclose(a.to_numpy()[0], [[1.3125, 3.1], [-2.625, 0.1]], rtol=1e-6)
    with pytest.raises(RuntimeError, match="Member fields of a matrix field must have the same compute type"):
        ti.Vector.field(2, dtype=[ti.types.quant.int(10), qfxt])
    fb = ti.FieldsBuilder()
    q = ti.field(dtype=ti.types.quant.int(2, False))
    fb.quant_array(ti.i, 16, max_num_bits=32).place(q)
    fb.finalize()
    q[15] = 3
    assert q[15] == 3 and q[14] == 0


def test_layout_inspection():
    """Taichi's `_cell_size_bytes` / `_offset_bytes_in_parent_cell` (its test_snode_layout_inspection.py): a
    BitpackedFields takes its physical integer's bytes in its parent's cell."""
    x = ti.field(dtype=ti.types.quant.int(16, False))
    y = ti.field(dtype=ti.types.quant.fixed(16, False))
    z = ti.field(dtype=ti.f32)
    n1 = ti.root.dense(ti.i, 32)
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(x)
    n1.place(bp)
    n2 = ti.root.dense(ti.i, 4)
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(y)
    n2.place(bp)
    n2.place(z)
    assert (n1._cell_size_bytes, n2._cell_size_bytes) == (4, 8)
    assert (n1._offset_bytes_in_parent_cell, n2._offset_bytes_in_parent_cell) == (0, 4 * 32)
    assert z.snode._offset_bytes_in_parent_cell == 4


def test_store_forms():
    """How stores reach memory (the compiled IR): storing every member of a cell in a row is one plain store
    (Taichi's store fusion and atomic demotion), storing one of several members is a compare-and-swap loop
    (ATOMIC kind cas, kept atomic in parallel loops), a value alone in its cell a plain store."""
    from simgrad.ir.nodes import walk
    from simgrad.ir.ops import Op

    x = ti.field(dtype=ti.types.quant.int(5, True))
    y = ti.field(dtype=ti.types.quant.fixed(7, max_value=2))
    bp = ti.BitpackedFields(max_num_bits=16)
    bp.place(x, y)
    ti.root.dense(ti.i, 8).place(bp)
    w = ti.field(dtype=ti.types.quant.int(32, False))
    bp32 = ti.BitpackedFields(max_num_bits=32)
    bp32.place(w)
    ti.root.dense(ti.i, 8).place(bp32)

    @ti.kernel
    def both():
        for i in range(8):
            x[i] = i
            y[i] = 0.5

    @ti.kernel
    def one():
        for i in range(8):
            y[i] = 0.25
            w[i] = i

    def forms(k):
        k()
        ir = k.instance(()).ir
        return sorted((s.op.name, s.attrs.get("kind"), s.attrs.get("strategy")) for s in walk(ir.body)
                      if s.op in (Op.GLOBAL_STORE, Op.ATOMIC))

    assert forms(both) == [("GLOBAL_STORE", None, None)]
    assert forms(one) == [("ATOMIC", "cas", "atomic"), ("GLOBAL_STORE", None, None)]
    assert x.to_numpy().tolist() == list(range(8)) and (y.to_numpy() == 0.25).all()
    assert w.to_numpy().tolist() == list(range(8))
