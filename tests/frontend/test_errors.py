"""User errors: each names the kernel/parameter or the construct, with the file, line and source text."""

import numpy as np
import pytest

import simgrad as ti

FILE = "test_errors.py"


def test_wrong_argument_count_names_kernel_and_parameters():
    @ti.kernel
    def add_two(a: ti.i32, b: ti.f32) -> ti.f32:
        return a + b

    # Taichi's texts (its tests match them), a TaichiSyntaxError and a TypeError
    with pytest.raises(ti.TaichiSyntaxError, match=r"kernel add_two: Parameter `b : f32` missing"):
        add_two(1)
    with pytest.raises(TypeError, match=r"add_two: Too many arguments. Expected \(a : i32, b : f32\), "
                                        r"got \(1, 2.0, 3\)"):
        add_two(1, 2.0, 3)
    with pytest.raises(TypeError, match=r"add_two"):
        add_two(1, c=3)
    assert add_two(1, 2.0) == 3.0  # still usable afterwards


def test_wrong_argument_type_names_kernel_and_parameter():
    @ti.kernel
    def scale(factor: ti.f32, v: ti.math.vec2, arr: ti.types.ndarray()):
        pass

    with pytest.raises(TypeError, match=r"kernel scale: argument 'factor' expects a f32 scalar, got str"):
        scale("two", [1.0, 2.0], np.zeros(2))
    with pytest.raises(TypeError, match=r"kernel scale: argument 'v' expects 2 entries, got 3"):
        scale(1.0, [1.0, 2.0, 3.0], np.zeros(2))
    with pytest.raises(TypeError, match=r"kernel scale: argument 'arr' expects an ndarray, got list"):
        scale(1.0, [1.0, 2.0], [1.0, 2.0])


def test_string_for_ndarray_parameter_names_kernel_and_parameter():
    @ti.kernel
    def scale(arr: ti.types.ndarray()):
        pass

    with pytest.raises(TypeError, match=r"kernel scale: .*'arr'"):
        scale("not an array")


def test_missing_annotation_names_parameter():
    with pytest.raises(TypeError, match=r"kernel no_ann: parameter 'x' needs a type annotation"):
        @ti.kernel
        def no_ann(x):
            pass

        no_ann(1)


def _raises_located(kernel, *args, match, line_text, exc=SyntaxError):
    with pytest.raises(exc, match=match) as info:
        kernel(*args)
    text = str(info.value)
    assert FILE in text, text
    assert line_text in text, text
    return text


def test_unsupported_try():
    @ti.kernel
    def k():
        try:
            pass
        except Exception:
            pass

    _raises_located(k, match='Unsupported node "Try"', line_text="try:")


def test_unsupported_with():
    @ti.kernel
    def k():
        with open("x"):
            pass

    _raises_located(k, match='Unsupported node "With"', line_text='with open("x"):')


def test_unsupported_lambda():
    @ti.kernel
    def k() -> ti.i32:
        f = lambda v: v + 1  # noqa: E731
        return f(1)

    _raises_located(k, match="lambda is not supported", line_text="f = lambda v: v + 1")


def test_unsupported_class_definition():
    @ti.kernel
    def k():
        class Local:
            pass

    _raises_located(k, match='Unsupported node "ClassDef"', line_text="class Local:")


def test_unsupported_construct_caret_points_at_the_line():
    @ti.kernel
    def k():
        x = 1
        del x

    text = _raises_located(k, match='Unsupported node "Delete"', line_text="del x")
    lines = text.splitlines()
    src = next(i for i, s in enumerate(lines) if s.strip() == "del x")
    assert lines[src + 1].strip() == "^"


def test_undefined_name():
    @ti.kernel
    def k() -> ti.f32:
        return undefined_thing * 2  # noqa: F821

    _raises_located(k, match="Name \"undefined_thing\" is not defined", line_text="return undefined_thing * 2",
                    exc=NameError)


def test_break_in_outermost_parallel_loop():
    x = ti.field(ti.i32, shape=4)

    @ti.kernel
    def k():
        for i in x:
            if i > 2:
                break

    _raises_located(k, match=r"Cannot break in the outermost loop",
                    line_text="break")


def test_return_inside_runtime_if_is_rejected():
    @ti.kernel
    def k(a: ti.i32) -> ti.i32:
        if a > 0:
            return 1
        return 0

    _raises_located(k, 1, match="Return inside non-static if/for is not supported", line_text="return 1")


def test_assigning_an_argument_inside_a_loop_is_rejected():
    """A kernel argument reassigned in a nested block would only shadow it there (the loop condition
    would still read the argument: an endless loop); Taichi rejects it too (arguments are immutable)."""

    @ti.kernel
    def k(i: ti.i32) -> ti.i32:
        while i < 10:
            i += 2
        return i

    _raises_located(k, 0, match=r'Kernel argument "i" is immutable in the kernel', line_text="i += 2")

    @ti.kernel
    def also(i: ti.i32) -> ti.i32:
        i = i * 2  # in the argument's own scope too (Taichi's rule; simgrad used to take a new local here)
        return i

    _raises_located(also, 0, match=r'Kernel argument "i" is immutable in the kernel', line_text="i = i * 2")

    @ti.func
    def f(i: ti.i32) -> ti.i32:
        i = i * 2  # a ti.func's parameter is a local, as in Taichi
        return i

    @ti.kernel
    def ok(i: ti.i32) -> ti.i32:
        return f(i)

    assert ok(5) == 10


def test_loop_over_runtime_value_is_rejected():
    @ti.kernel
    def k(a: ti.i32):
        for _ in a:
            pass

    _raises_located(k, 1, match=r"cannot loop over a run-time i32 value; use range\(\)",
                    line_text="for _ in a:")


def test_wrong_number_of_field_indices():
    x = ti.field(ti.f32, shape=(2, 3))

    @ti.kernel
    def k():
        x[1] = 0

    _raises_located(k, match=r"2 dimension\(s\) but is indexed with 1", line_text="x[1] = 0", exc=IndexError)


def test_float_field_index_is_rejected():
    x = ti.field(ti.f32, shape=4)

    @ti.kernel
    def k(a: ti.f32):
        x[a] = 1

    _raises_located(k, 1.0, match="field indices must be integers", line_text="x[a] = 1", exc=TypeError)


def test_kernel_called_from_kernel_is_rejected():
    @ti.kernel
    def inner():
        pass

    @ti.kernel
    def outer():
        inner()

    _raises_located(outer, match="cannot be called from inside a kernel", line_text="inner()")


def test_func_called_from_python_scope_is_rejected():
    @ti.func
    def f():
        return 1

    with pytest.raises(ti.TaichiSyntaxError, match="ti.func f can only be called from a kernel"):  # as Taichi
        f()


def test_error_inside_func_points_into_the_func():
    @ti.func
    def helper(v):
        return v + not_defined_either  # noqa: F821

    @ti.kernel
    def k() -> ti.i32:
        return helper(1)

    _raises_located(k, match="not_defined_either", line_text="return v + not_defined_either", exc=NameError)


def test_errors_leave_the_kernel_usable_for_other_arguments():
    @ti.kernel
    def k(x: ti.template()) -> ti.i32:
        return x[0] * 2

    with pytest.raises(TypeError, match="not subscriptable"):
        k(3)  # an int is not subscriptable: a compile error
    f = ti.field(ti.i32, shape=1)
    f[0] = 21
    assert k(f) == 42


@pytest.fixture
def debug():
    ti.init(arch=ti.cpu, debug=True)


def test_debug_out_of_bounds_field_index(debug):
    x = ti.field(ti.f32, shape=(4, 5))

    @ti.kernel
    def k(i: ti.i32, j: ti.i32):
        x[i, j] = 1.0

    k(3, 4)
    with pytest.raises(IndexError, match=r"index 5 is out of bounds in dimension 1") as info:
        k(0, 5)
    assert FILE in str(info.value) and "x[i, j] = 1.0" in str(info.value)
    with pytest.raises(IndexError, match=r"index -1 is out of bounds in dimension 0"):
        k(-1, 0)
    k(1, 1)  # the interpreter and the kernel survive
    assert x[1, 1] == 1.0 and x[3, 4] == 1.0


def test_debug_out_of_bounds_reports_the_users_index_with_offsets(debug):
    x = ti.field(ti.i32, shape=4, offset=-2)  # valid indices -2..1
    v = ti.Vector.field(2, ti.f32, shape=3)

    @ti.kernel
    def k(i: ti.i32) -> ti.f32:
        return x[i] + v[i + 2][1]

    assert k(-2) == 0 and k(0) == 0
    with pytest.raises(IndexError, match=r"index -3 is out of bounds in dimension 0 of x \(shape \(4,\) with "
                                         r"offset \(-2,\)\)"):
        k(-3)
    with pytest.raises(IndexError, match=r"index 3 is out of bounds in dimension 0 of v"):
        k(1)


def test_debug_out_of_bounds_in_parallel_loop(debug):
    x = ti.field(ti.i32, shape=10)

    @ti.kernel
    def k(n: ti.i32):
        for i in range(n):
            x[i] = i

    with pytest.raises(IndexError, match="out of bounds") as info:
        k(11)
    assert "x[i] = i" in str(info.value)
    k(10)
    np.testing.assert_array_equal(x.to_numpy(), np.arange(10))


def test_debug_out_of_bounds_ndarray_index(debug):
    @ti.kernel
    def k(a: ti.types.ndarray(), i: ti.i32) -> ti.f32:
        return a[i]

    a = np.arange(3, dtype=np.float32)
    assert k(a, 2) == 2.0
    with pytest.raises(IndexError, match="out of bounds") as info:
        k(a, 3)
    assert FILE in str(info.value) and "return a[i]" in str(info.value)
    assert k(a, 1) == 1.0


def test_debug_assert(debug):
    @ti.kernel
    def k(a: ti.i32):
        assert a > 0, "a must be positive"
        assert a < 100

    k(5)
    with pytest.raises(AssertionError, match="a must be positive") as info:
        k(-1)
    assert FILE in str(info.value)
    with pytest.raises(AssertionError, match="a < 100"):
        k(100)
    k(1)


def test_assert_is_skipped_without_debug():
    @ti.kernel
    def k(a: ti.i32) -> ti.i32:
        assert a > 0
        return a

    assert k(-1) == -1


def test_static_assert_and_compile_time_assert():
    @ti.kernel
    def k(n: ti.template()):
        ti.static_assert(n > 2, "n must exceed 2")

    k(3)
    with pytest.raises(Exception, match="n must exceed 2"):
        k(1)


def test_integer_division_by_zero_in_parallel_loop_does_not_crash():
    n = 1000
    a = ti.field(ti.i64, shape=n)

    @ti.kernel
    def k(d: ti.i64):
        for i in a:
            a[i] = (i + 1) // d + (i + 1) % d

    k(0)  # any value, but the process survives
    k(7)
    i = np.arange(1, n + 1)
    np.testing.assert_array_equal(a.to_numpy(), i // 7 + i % 7)


# -- Python-scope errors name the real cause -----------------------------------------------------------


def test_unknown_keyword_is_reported_before_missing_parameter():
    @ti.kernel
    def k(a: ti.i32) -> ti.i32:
        return a

    @ti.func
    def f(a):
        return a

    @ti.kernel
    def calls_func() -> ti.i32:
        return f(b=1)

    with pytest.raises(TypeError, match=r"kernel k: Unexpected argument 'b' \(its parameters are: a\)") as e:
        k(b=1)
    assert FILE in str(e.value) and "k(b=1)" in str(e.value)
    _raises_located(calls_func, match=r"ti.func f: Unexpected argument 'b'",
                    line_text="return f(b=1)", exc=TypeError)
    assert k(a=2) == 2


@pytest.mark.parametrize("shape", [(3, -2), -1, (2.5,)])
def test_bad_field_shape_is_refused_at_creation(shape):
    with pytest.raises(ValueError, match=r"field shape must be non-negative integers") as e:
        ti.field(ti.f32, shape=shape)
    assert FILE in str(e.value) and "ti.field(ti.f32, shape=shape)" in str(e.value)
    with pytest.raises(ValueError, match=r"field shape must be non-negative integers"):
        ti.Vector.field(2, ti.f32, shape=shape)
    x = ti.field(ti.f32, shape=3)  # the program is still usable
    x[2] = 1.0
    assert x[2] == 1.0


def test_gradient_of_field_without_needs_grad_says_so():
    x = ti.field(ti.f32, shape=4)

    @ti.kernel
    def k():
        for i in x:
            x.grad[i] = 1.0

    with pytest.raises(ti.SimgradError, match=r"field x has no gradient: .*needs_grad=True") as e:
        x.grad[0] = 1.0
    assert "x.grad[0] = 1.0" in str(e.value)
    _raises_located(k, match=r"field x has no gradient", line_text="x.grad[i] = 1.0", exc=ti.SimgradError)


def test_float_index_in_python_scope_names_field():
    x = ti.field(ti.f32, shape=4)
    v = ti.Vector.field(2, ti.f32, shape=(2, 2))
    with pytest.raises(IndexError, match=r"field x is indexed with 1.5 \(float\); Python-scope indices must "
                                         r"be integers") as e:
        x[1.5]
    assert "x[1.5]" in str(e.value)
    with pytest.raises(IndexError, match=r"field v is indexed with 0.5"):
        v[0.5, 1] = [1.0, 2.0]
    with pytest.raises(IndexError, match=r"index 7 out of bounds for field v of shape \(2, 2\)"):
        v[7, 0]


def test_python_scope_errors_name_the_users_variable():
    density = ti.field(ti.f32, shape=3)
    self_like = type("S", (), {})()
    self_like.vel = ti.Vector.field(2, ti.f32, shape=3)
    named = ti.field(ti.f32, shape=3, name="given")
    with pytest.raises(IndexError, match=r"field density of shape"):
        density[5]
    with pytest.raises(IndexError, match=r"field self_like.vel of shape"):
        self_like.vel[5]
    with pytest.raises(IndexError, match=r"field given of shape"):
        named[5]
    fields = [ti.field(ti.f32, shape=2) for _ in range(2)]  # no single variable: a generated name
    with pytest.raises(IndexError, match=r"field field\d+ of shape"):
        fields[0][5]


def test_negative_dense_size_is_refused():
    x = ti.field(ti.f32)
    with pytest.raises(ValueError, match=r"dense\(\): sizes must be non-negative integers, got \(4, -1\)") as e:
        ti.root.dense(ti.ij, (4, -1)).place(x)
    assert "ti.root.dense(ti.ij, (4, -1)).place(x)" in str(e.value)
