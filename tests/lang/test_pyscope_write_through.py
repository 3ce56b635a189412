"""Python-scope elements of vector/matrix fields are live views, as in taichi 1.7.4: `v[None][0] -= lr * g`
(the DiffTaichi parameter update) writes to the field. Before, `v[None]` returned a detached copy and such
writes were silently dropped, so billiards and diffmpm_simple never learned. One test per access form; the
expected values are plain numpy arithmetic on the same updates."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti


@pytest.fixture
def fields():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    v0 = ti.Vector.field(2, ti.f64, shape=(), needs_grad=True)
    v1 = ti.Vector.field(3, ti.f64, shape=4)
    v2 = ti.Vector.field(2, ti.f64, shape=(3, 2))
    m = ti.Matrix.field(2, 2, ti.f64, shape=3, needs_grad=True)
    off = ti.Vector.field(2, ti.f64, shape=4, offset=(-2,))
    a = ti.Vector.field(2, ti.f64)
    b = ti.field(ti.f64)
    ti.root.dense(ti.i, 4).place(a, b)  # AoS: a and b interleaved in one node
    return v0, v1, v2, m, off, a, b


def test_augmented_assignment_on_a_0d_vector_and_its_grad(fields):
    v0 = fields[0]
    v0[None] = [1.0, 2.0]
    v0.grad[None] = [0.5, -1.0]
    lr = 0.1
    for d in range(2):
        v0[None][d] -= lr * v0.grad[None][d]
    np.testing.assert_allclose(v0.to_numpy(), [1.0 - 0.05, 2.0 + 0.1])
    v0.grad[None][1] = 3.0
    np.testing.assert_allclose(v0.grad.to_numpy(), [0.5, 3.0])


def test_element_assignment_on_1d_and_2d_vector_fields(fields):
    _, v1, v2, *_ = fields
    v1[2][1] = 7.0
    v1[3][0] += 2.5
    v2[1, 1][0] = -4.0
    want1 = np.zeros((4, 3))
    want1[2, 1], want1[3, 0] = 7.0, 2.5
    want2 = np.zeros((3, 2, 2))
    want2[1, 1, 0] = -4.0
    np.testing.assert_array_equal(v1.to_numpy(), want1)
    np.testing.assert_array_equal(v2.to_numpy(), want2)


def test_matrix_field_element_and_its_grad(fields):
    m = fields[3]
    m[1][0, 1] = 5.0
    m[1][1, 0] -= 2.0
    m.grad[2][1, 1] = 9.0
    want = np.zeros((3, 2, 2))
    want[1, 0, 1], want[1, 1, 0] = 5.0, -2.0
    np.testing.assert_array_equal(m.to_numpy(), want)
    assert m.grad.to_numpy()[2, 1, 1] == 9.0
    with pytest.raises(IndexError, match="takes 2 indices"):
        m[1][1][0] = 6.0  # taichi refuses this form too (a row read would be a detached copy)


def test_swizzle_and_fill_write_through(fields):
    _, v1, *_ = fields
    v1[0].y = 4.0
    v1[1].xz = [1.0, 2.0]
    v1[2].fill(3.0)
    np.testing.assert_array_equal(v1.to_numpy()[:3], [[0, 4, 0], [1, 0, 2], [3, 3, 3]])


def test_offsets_and_interleaved_layouts(fields):
    *_, off, a, b = fields
    off[-2][1] = 1.5
    off[1][0] -= 1.0
    np.testing.assert_array_equal(off.to_numpy(), [[0, 1.5], [0, 0], [0, 0], [-1.0, 0]])
    b.fill(8.0)
    a[2][1] = 6.0
    a[3][0] += 1.0
    np.testing.assert_array_equal(a.to_numpy(), [[0, 0], [0, 0], [0, 6], [1, 0]])
    np.testing.assert_array_equal(b.to_numpy(), np.full(4, 8.0))  # the neighbour is untouched


def test_element_is_a_live_view_and_behaves_as_a_vector(fields):
    _, v1, *_ = fields
    e = v1[1]
    v1[1] = [1.0, 2.0, 2.0]
    assert e.norm() == pytest.approx(3.0)  # reads the field now
    np.testing.assert_array_equal(e * 2 + 1, [3.0, 5.0, 5.0])
    assert str(e) == str(np.array([1.0, 2.0, 2.0]))  # printed as taichi prints it
    copy = ti.Vector(e)  # an explicit copy is detached
    v1[1][0] = 10.0
    assert copy[0] == 1.0 and e[0] == 10.0
    v1[0] = e  # assigning one element to another copies values
    np.testing.assert_array_equal(v1.to_numpy()[0], [10.0, 2.0, 2.0])


def test_element_as_kernel_argument(fields):
    _, v1, *_ = fields
    v1[2] = [1.0, 2.0, 3.0]

    @ti.kernel
    def dot(a: ti.types.vector(3, ti.f64)) -> ti.f64:
        return a.dot(a)

    assert dot(v1[2]) == 14.0
