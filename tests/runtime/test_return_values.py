"""Kernel return values come back in the shape the return annotation declares (runtime/launch.py)."""

import simgrad as ti


def test_one_entry_vector_return_is_a_vector():
    # the launcher used to read `ret_matrix` before it was set and returned a bare float: TypeError
    @ti.kernel
    def f() -> ti.types.vector(1, ti.f32):
        return ti.Vector([2.5])

    r = f()
    assert isinstance(r, ti.Matrix) and r.n == 1 and r[0] == 2.5


def test_one_entry_matrix_and_wider_returns():
    @ti.kernel
    def one() -> ti.types.matrix(1, 1, ti.f32):
        return ti.Matrix([[1.5]])

    @ti.kernel
    def three(a: ti.f32) -> ti.types.vector(3, ti.f32):
        return ti.Vector([a, 2 * a, 3 * a])

    @ti.kernel
    def scalar() -> ti.f32:
        return 4.0

    r = one()
    assert isinstance(r, ti.Matrix) and (r.n, r.m) == (1, 1) and r[0, 0] == 1.5
    assert three(1.0).to_numpy().tolist() == [1.0, 2.0, 3.0]
    assert scalar() == 4.0 and isinstance(scalar(), float)


def test_one_entry_vector_return_from_the_kernel_cache():
    @ti.kernel
    def f() -> ti.types.vector(1, ti.i32):
        return ti.Vector([7])

    assert f()[0] == 7
    ti.init(arch=ti.cpu)  # a new program: the launcher is rebuilt from the cached entry's metadata
    r = f()
    assert isinstance(r, ti.Matrix) and r[0] == 7
