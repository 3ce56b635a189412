"""Fields: shapes, dtypes, layouts (AoS, SoA, nested and blocked dense), numpy interop, Python-scope
access, offsets, and fields created after a kernel ran."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradError


@pytest.mark.parametrize("t", [ti.i8, ti.i16, ti.i32, ti.i64, ti.u8, ti.u16, ti.u32, ti.u64, ti.f32, ti.f64],
                         ids=str)
def test_field_dtype_shape_and_numpy_roundtrip(t):
    x = ti.field(t, shape=(3, 5))
    assert x.shape == (3, 5) and x.dtype == t
    a = (np.arange(15).reshape(3, 5) * 7 + 1).astype(t.np)
    x.from_numpy(a)
    got = x.to_numpy()
    assert got.dtype == t.np
    np.testing.assert_array_equal(got, a)
    x.fill(9)
    np.testing.assert_array_equal(x.to_numpy(), np.full((3, 5), 9, t.np))


def test_shapes_int_tuple_and_0d():
    a = ti.field(ti.f32, shape=7)
    b = ti.field(ti.f32, shape=(2, 3, 4))
    c = ti.field(ti.f32, shape=())
    assert a.shape == (7,) and b.shape == (2, 3, 4) and c.shape == ()

    @ti.kernel
    def k():
        c[None] = 2.5
        for i in a:
            a[i] = c[None] * i
        for i, j, q in b:
            b[i, j, q] = c[None] + i + j + q

    k()
    assert c[None] == 2.5
    assert c.to_numpy().shape == () and c.to_numpy() == 2.5
    np.testing.assert_array_equal(a.to_numpy(), 2.5 * np.arange(7))
    np.testing.assert_array_equal(b.to_numpy(), 2.5 + np.indices((2, 3, 4)).sum(axis=0))


def test_vector_and_matrix_fields():
    v = ti.Vector.field(3, ti.f32, shape=4)
    m = ti.Matrix.field(2, 3, ti.i32, shape=(2, 2))
    assert v.shape == (4,) and m.shape == (2, 2) and v.dtype == ti.f32 and m.dtype == ti.i32
    assert v.n == 3 and m.n == 2 and m.m == 3

    @ti.kernel
    def k():
        for i in v:
            v[i] = ti.Vector([i, i * 2, i * 3]) * 0.5
        for i, j in m:
            for r, c in ti.static(ti.ndrange(2, 3)):
                m[i, j][r, c] = i * 1000 + j * 100 + r * 10 + c

    k()
    assert v.to_numpy().shape == (4, 3) and m.to_numpy().shape == (2, 2, 2, 3)
    np.testing.assert_array_equal(v.to_numpy(), np.arange(4)[:, None] * np.array([0.5, 1.0, 1.5]))
    i, j, r, c = np.indices((2, 2, 2, 3))
    np.testing.assert_array_equal(m.to_numpy(), i * 1000 + j * 100 + r * 10 + c)


def test_vector_field_python_scope_access():
    v = ti.Vector.field(3, ti.f64, shape=(2, 2))
    v[1, 0] = [1.0, 2.0, 3.0]
    v[0, 1] = np.array([4.0, 5.0, 6.0])
    v[1, 1] = ti.Vector([7.0, 8.0, 9.0])
    assert list(v[1, 0]) == [1.0, 2.0, 3.0]
    assert v[0, 1][2] == 6.0
    np.testing.assert_array_equal(v.to_numpy()[1, 1], [7, 8, 9])
    assert v[0, 0].to_numpy().tolist() == [0, 0, 0]
    m = ti.Matrix.field(2, 2, ti.f32, shape=())
    m[None] = [[1, 2], [3, 4]]
    assert m[None][1, 0] == 3
    np.testing.assert_array_equal(m.to_numpy(), [[1, 2], [3, 4]])
    v.fill(1.5)
    np.testing.assert_array_equal(v.to_numpy(), np.full((2, 2, 3), 1.5))


def test_python_scope_scalar_reads_and_writes():
    x = ti.field(ti.i32, shape=(3, 4))
    x[2, 3] = 7
    x[0, 1] = -5
    assert x[2, 3] == 7 and x[0, 1] == -5 and x[1, 1] == 0
    assert isinstance(x[2, 3], int)
    f = ti.field(ti.f32, shape=2)
    f[0] = 0.1
    assert f[0] == np.float32(0.1) and isinstance(f[0], float)
    with pytest.raises(IndexError):
        x[3, 0]
    with pytest.raises(IndexError):
        x[0, 4] = 1
    with pytest.raises(IndexError):
        x[0]


def test_python_scope_rejects_negative_indices():
    """A negative index is out of bounds (as in a kernel), never a numpy-style wrap to the end."""
    x = ti.field(ti.i32, shape=4)
    with pytest.raises(IndexError):
        x[-1]
    with pytest.raises(IndexError):
        x[-1] = 3
    with pytest.raises(IndexError):
        x[np.int64(-1)]
    with pytest.raises(IndexError):
        x[np.int32(4)]
    x[np.int64(3)] = 2
    assert x[3] == 2
    y = ti.field(ti.i32, shape=4, offset=-2)  # valid indices -2..1
    y[-2] = 5
    assert y[-2] == 5
    with pytest.raises(IndexError):
        y[-3]  # would alias element 1 if shifted indices wrapped


def test_aos_and_soa_layouts():
    n, m = 4, 6
    a, b = ti.field(ti.f32), ti.field(ti.i32)
    ti.root.dense(ti.ij, (n, m)).place(a, b)  # AoS: a and b interleaved
    c, d = ti.field(ti.f64), ti.field(ti.i16)
    ti.root.dense(ti.i, n).place(c)  # SoA: separate dense nodes
    ti.root.dense(ti.i, n).place(d)
    e, f = ti.field(ti.f32), ti.field(ti.f32)
    ti.root.dense(ti.ijk, (2, 3, 4)).place(e, f)
    assert a.shape == (n, m) and c.shape == (n,) and e.shape == (2, 3, 4)

    @ti.kernel
    def k():
        for i, j in a:
            a[i, j] = i + j * 0.5
            b[i, j] = i * j
        for i in c:
            c[i] = i * 0.25
            d[i] = -i
        for i, j, q in e:
            e[i, j, q] = i * 100 + j * 10 + q
            f[i, j, q] = -e[i, j, q]

    k()
    i, j = np.indices((n, m))
    np.testing.assert_array_equal(a.to_numpy(), i + j * 0.5)
    np.testing.assert_array_equal(b.to_numpy(), i * j)
    np.testing.assert_array_equal(c.to_numpy(), np.arange(n) * 0.25)
    np.testing.assert_array_equal(d.to_numpy(), -np.arange(n))
    want = np.fromfunction(lambda i, j, q: i * 100 + j * 10 + q, (2, 3, 4))
    np.testing.assert_array_equal(e.to_numpy(), want)
    np.testing.assert_array_equal(f.to_numpy(), -want)
    a[1, 2] = 42.0  # Python-scope writes land where the kernel reads
    b[3, 5] = 17

    @ti.kernel
    def read() -> ti.f32:
        return a[1, 2] + b[3, 5]

    assert read() == 59.0


def test_vector_field_placed_in_aos():
    v = ti.Vector.field(2, ti.f32)
    s = ti.field(ti.i32)
    ti.root.dense(ti.i, 5).place(v, s)

    @ti.kernel
    def k():
        for i in s:
            v[i] = [i, -i]
            s[i] = i * i

    k()
    np.testing.assert_array_equal(v.to_numpy(), np.stack([np.arange(5), -np.arange(5)], axis=1))
    np.testing.assert_array_equal(s.to_numpy(), np.arange(5) ** 2)


def test_nested_and_blocked_dense():
    x = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).dense(ti.j, 8).place(x)
    y = ti.field(ti.i32)
    ti.root.dense(ti.ij, 2).dense(ti.ij, 4).place(y)  # 2x2 blocks of 4x4
    z = ti.field(ti.f32)
    w = ti.field(ti.f32)
    blk = ti.root.dense(ti.i, 3)
    blk.dense(ti.i, 5).place(z)
    blk.dense(ti.i, 5).place(w)
    assert x.shape == (4, 8) and y.shape == (8, 8) and z.shape == (15,)

    @ti.kernel
    def k():
        for i, j in x:
            x[i, j] = i * 100 + j
        for i, j in y:
            y[i, j] = i * 100 + j
        for i in z:
            z[i] = i * 0.5
            w[i] = -i

    k()
    i, j = np.indices((4, 8))
    np.testing.assert_array_equal(x.to_numpy(), i * 100 + j)
    i, j = np.indices((8, 8))
    np.testing.assert_array_equal(y.to_numpy(), i * 100 + j)
    np.testing.assert_array_equal(z.to_numpy(), np.arange(15) * 0.5)
    np.testing.assert_array_equal(w.to_numpy(), -np.arange(15))
    y.from_numpy(np.arange(64, dtype=np.int32).reshape(8, 8))
    y[5, 2] = -1
    assert y[5, 2] == -1 and y[7, 7] == 63

    @ti.kernel
    def total() -> ti.i32:
        s = 0
        for i, j in y:
            s += y[i, j] * (i * 8 + j)
        return s

    want = np.arange(64) * np.arange(64)
    want[5 * 8 + 2] = -(5 * 8 + 2)
    assert total() == want.sum()


def test_one_size_in_a_list_is_given_to_every_axis():
    # Taichi's SNode::create_node broadcasts a single size (mgpcg.py: ti.root.pointer(ti.ijk, [n // 4]))
    x = ti.field(ti.i32)
    ti.root.dense(ti.ijk, [2]).dense(ti.ijk, (3,)).place(x)
    assert x.shape == (6, 6, 6)
    with pytest.raises(ti.SimgradError, match="3 axes but 2 sizes"):
        ti.root.dense(ti.ijk, [2, 3])


def test_copy_from_and_fill():
    a = ti.field(ti.f32, shape=(3, 3))
    b = ti.field(ti.f32, shape=(3, 3))
    a.from_numpy(np.arange(9, dtype=np.float32).reshape(3, 3))
    b.copy_from(a)
    np.testing.assert_array_equal(b.to_numpy(), np.arange(9).reshape(3, 3))
    a.fill(0)
    assert b[2, 2] == 8 and a[2, 2] == 0
    v = ti.Vector.field(2, ti.i32, shape=3)
    u = ti.Vector.field(2, ti.i32, shape=3)
    v.fill(4)
    u.copy_from(v)
    np.testing.assert_array_equal(u.to_numpy(), np.full((3, 2), 4))
    with pytest.raises(ValueError):
        a.from_numpy(np.zeros((3, 4), np.float32))


def test_to_numpy_dtype_and_from_numpy_casts():
    x = ti.field(ti.f32, shape=3)
    x.from_numpy(np.array([1, 2, 3], np.int64))
    assert x.to_numpy().dtype == np.float32
    assert x.to_numpy(dtype=np.float64).dtype == np.float64
    np.testing.assert_array_equal(x.to_numpy(), [1, 2, 3])


def test_field_offsets():
    x = ti.field(ti.i32, shape=(4, 3), offset=(-2, 5))
    v = ti.Vector.field(2, ti.f32, shape=4, offset=10)

    @ti.kernel
    def k():
        for i, j in x:
            x[i, j] = i * 10 + j
        for i in v:
            v[i] = [i, 2 * i]

    k()
    i, j = np.indices((4, 3))
    np.testing.assert_array_equal(x.to_numpy(), (i - 2) * 10 + (j + 5))
    assert x[-2, 5] == -20 + 5 and x[1, 7] == 17
    np.testing.assert_array_equal(v.to_numpy()[:, 1], 2 * np.arange(10, 14))
    assert list(v[13]) == [13, 26]

    @ti.kernel
    def read(a: ti.i32, b: ti.i32) -> ti.i32:
        return x[a, b]

    assert read(-1, 6) == -4


def test_fields_created_after_a_kernel_ran():
    a = ti.field(ti.i32, shape=4)

    @ti.kernel
    def fill_a():
        for i in a:
            a[i] = i + 1

    fill_a()
    b = ti.field(ti.i32, shape=4)  # a new tree after the first one is in use
    c = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).place(c)  # ti.root also starts a fresh tree

    @ti.kernel
    def combine():
        for i in b:
            b[i] = a[i] * 10
            c[i] = a[i] + b[i]

    combine()
    fill_a()
    np.testing.assert_array_equal(a.to_numpy(), [1, 2, 3, 4])
    np.testing.assert_array_equal(b.to_numpy(), [10, 20, 30, 40])
    np.testing.assert_array_equal(c.to_numpy(), [11, 22, 33, 44])


def test_same_kernel_with_fields_of_different_layouts():
    @ti.kernel
    def set_all(x: ti.template(), v: ti.i32):
        for I in ti.grouped(x):
            x[I] = v + I.sum()

    p = ti.field(ti.i32, shape=(3, 3))
    q = ti.field(ti.i32)
    ti.root.dense(ti.ij, 3).dense(ti.ij, 2).place(q)
    set_all(p, 1)
    set_all(q, 2)
    np.testing.assert_array_equal(p.to_numpy(), 1 + np.indices((3, 3)).sum(axis=0))
    np.testing.assert_array_equal(q.to_numpy(), 2 + np.indices((6, 6)).sum(axis=0))


def test_integer_field_stores_wrap_and_float_stores_truncate():
    x = ti.field(ti.u8, shape=3)
    y = ti.field(ti.i32, shape=2)

    @ti.kernel
    def k(a: ti.i32, b: ti.f32):
        x[0] = a
        x[1] = -1
        x[2] = a + 256
        y[0] = b
        y[1] = -b

    k(300, 2.9)
    assert x.to_numpy().tolist() == [300 % 256, 255, 300 % 256]
    assert y.to_numpy().tolist() == [2, -2]


def test_runtime_index_into_vector_and_matrix_elements():
    v = ti.Vector.field(3, ti.f32, shape=4)
    m = ti.Matrix.field(2, 3, ti.i32, shape=())

    @ti.kernel
    def k():
        for i in v:
            for j in range(3):
                v[i][j] = i * 10 + j
                v[i][j] += 0.5
        for r in range(2):
            for c in range(3):
                m[None][r, c] = r * 10 + c
        m[None][1, 2] = 99

    @ti.kernel
    def read(i: ti.i32, j: ti.i32) -> ti.f32:
        return v[i][j] + m[None][1, j] * 1000

    k()
    np.testing.assert_array_equal(v.to_numpy(), np.arange(4)[:, None] * 10 + np.arange(3) + 0.5)
    np.testing.assert_array_equal(m.to_numpy(), [[0, 1, 2], [10, 11, 99]])
    assert read(2, 1) == 21.5 + 11000
    assert read(3, 2) == 32.5 + 99000


def test_python_scope_multi_index_reads_on_every_layout():
    """`f[i, j]` reads (numpy's item() on the field's view or gather index) equal to_numpy on a dense, a nested
    (gathered) and a u1 field; a negative, float, short or out-of-range index is still refused; a bool is 0 or 1,
    as in Taichi (numpy took it for a mask)."""
    rng = np.random.default_rng(6)
    dense = ti.field(ti.f32, shape=(4, 8))
    nested = ti.field(ti.i32)
    ti.root.dense(ti.ij, (1, 2)).dense(ti.ij, 2).dense(ti.ij, 2).place(nested)
    flags = ti.field(ti.u1, shape=(3, 5))
    dense.from_numpy(rng.random((4, 8)).astype(np.float32))
    nested.from_numpy(rng.integers(-100, 100, (4, 8)).astype(np.int32))
    flags.from_numpy(rng.integers(0, 2, (3, 5)).astype(bool))
    for f in (dense, nested, flags):
        want = f.to_numpy()
        for i, j in np.ndindex(*want.shape):
            got = f[i, j]
            assert got == want[i, j] and type(got) is (float if f is dense else int), (f, i, j)
            assert f[np.int64(i), np.int32(j)] == want[i, j]
        n, m = want.shape
        for bad in ((n, 0), (0, m), (-1, 0), (0, -1), (0,), (0, 0, 0)):
            with pytest.raises(IndexError):
                f[bad]
        with pytest.raises((IndexError, TypeError)):
            f[0.5, 0]
        assert f[True, 0] == want[1, 0] and f[np.True_, False] == want[1, 0]  # Taichi's 1 and 0


def test_python_scope_misuse_of_fields_is_loud():
    x = ti.field(ti.i32, shape=(1, 2, 3))
    with pytest.raises(AssertionError, match="Slicing is not supported on ti.field"):
        x[0, 0] = 1
    with pytest.raises(NotImplementedError, match="Struct for is only available in Taichi scope"):
        for _ in x:
            pass
    with pytest.raises(TypeError, match="copies from another field"):
        x.copy_from(np.zeros((1, 2, 3)))
    v = ti.Vector.field(3, ti.f32, shape=2, name="vel")
    assert v._name == "vel" and v.snode._name == "vel"


def test_vector_and_matrix_to_from_numpy_through_packed_views_and_soa():
    """AoS components are read and written as one strided view; SoA components (placed apart) one by one:
    both must give the same arrays, element access agreeing."""
    rng = np.random.default_rng(3)
    v = ti.Vector.field(3, ti.f32, shape=(3, 4), needs_grad=True)
    m = ti.Matrix.field(2, 3, ti.f64, shape=5)
    a, b = rng.random((3, 4, 3)).astype(np.float32), rng.random((5, 2, 3))
    v.from_numpy(a)
    m.from_numpy(b)
    np.testing.assert_array_equal(v.to_numpy(), a)
    np.testing.assert_array_equal(m.to_numpy(), b)
    assert v[2, 1][2] == a[2, 1, 2] and m[4][1, 0] == b[4, 1, 0]
    assert not v.grad.to_numpy().any()
    u = ti.Vector.field(2, ti.f32)
    ti.root.dense(ti.i, 4).place(u.get_scalar_field(0))
    ti.root.dense(ti.i, 4).place(u.get_scalar_field(1))
    c = np.arange(8, dtype=np.float32).reshape(4, 2)
    u.from_numpy(c)
    np.testing.assert_array_equal(u.to_numpy(), c)
    assert u[2][1] == 5


def test_get_addr_shows_the_layout():
    """ti.get_addr(x.snode or x, indices): the element's address (u64); differences follow the SNode layout
    (here the hierarchical one of Taichi's print_offset example, and a field with offsets), as in taichi."""
    ti.init(arch=ti.cpu)
    a = ti.field(ti.i32)
    ti.root.dense(ti.ij, (1, 2)).dense(ti.ij, 2).dense(ti.ij, 2).place(a)
    b = ti.field(ti.f64, shape=(3, 5), offset=(-1, 2))

    @ti.kernel
    def fill():
        for i, j in a:
            a[i, j] = int(ti.get_addr(a.snode, [i, j]) - ti.get_addr(a.snode, [0, 0])) // 4
        for i, j in b:
            b[i, j] = ti.cast(ti.get_addr(b, [i, j]) - ti.get_addr(b, ti.Vector([-1, 2])), ti.f64)

    fill()
    i, j = np.meshgrid(np.arange(4), np.arange(8), indexing="ij")
    want = (j // 4) * 16 + ((i // 2) % 2 * 2 + (j // 2) % 2) * 4 + (i % 2) * 2 + j % 2
    np.testing.assert_array_equal(a.to_numpy(), want)
    np.testing.assert_array_equal(b.to_numpy(), np.arange(15).reshape(3, 5) * 8.0)
    with pytest.raises(ti.TaichiSyntaxError, match="get_addr expects a scalar field"):
        @ti.kernel
        def bad():
            print(ti.get_addr(3, [0]))

        bad()
    with pytest.raises(SimgradError, match="get_addr can only be called inside a kernel"):
        ti.get_addr(a, [0, 0])
