"""Taichi's exception classes (issue 23): each misuse raises a simgrad error that is also an instance of the class
Taichi 1.7.4 raises for it, and is located (the user's file and line in the message).

The class of each row was recorded by running the row's program under taichi 1.7.4, each in a fresh process:

    /work/tivenv/bin/python PROGRAM.py    # PROGRAM = "import taichi as ti\nti.init(arch=ti.cpu)\n" + the source

(field_before_init without the ti.init line). Taichi's own names: ti.TaichiSyntaxError, TaichiTypeError,
TaichiNameError, TaichiIndexError (the four are TaichiCompilationErrors), TaichiRuntimeError, TaichiAssertionError,
TaichiRuntimeTypeError (the last two are TaichiRuntimeErrors); a builtin name where Taichi raises a builtin.
Not in the table: `v[5]` of a 3-vector (taichi 1.7.4 raises nothing; simgrad a TaichiIndexError) and a kernel
method of a class without @ti.data_oriented (Taichi's TaichiSyntaxError; simgrad binds the object), a
2-vector for a 3-vector parameter (taichi leaks numpy's IndexError; simgrad a TaichiRuntimeTypeError)."""

import builtins
import runpy

import pytest

import simgrad as ti

# (name, the class taichi 1.7.4 raises, the program; its line marked `#!` is where the error is located)
CASES = [
    ("arg_str_for_int", "TaichiRuntimeTypeError", """
@ti.kernel
def k(a: ti.i32):
    pass
k("x")  #!
"""),
    ("arg_float_for_int", "TaichiRuntimeTypeError", """
@ti.kernel
def k(a: ti.i32):
    pass
k(1.5)  #!
"""),
    ("arg_none_for_float", "TaichiRuntimeTypeError", """
@ti.kernel
def k(a: ti.f32):
    pass
k(None)  #!
"""),
    ("too_many_args", "TaichiSyntaxError", """
@ti.kernel
def k(a: ti.i32):
    pass
k(1, 2)  #!
"""),
    ("too_few_args", "TaichiSyntaxError", """
@ti.kernel
def k(a: ti.i32, b: ti.i32):
    pass
k(1)  #!
"""),
    ("unknown_keyword", "TaichiSyntaxError", """
@ti.kernel
def k(a: ti.i32):
    pass
k(a=1, b=2)  #!
"""),
    ("undefined_name", "TaichiNameError", """
@ti.kernel
def k():
    a = undefined_thing + 1  #!
k()
"""),
    ("kernel_in_kernel", "TaichiSyntaxError", """
@ti.kernel
def inner():
    pass
@ti.kernel
def k():
    inner()  #!
k()
"""),
    ("return_without_annotation", "TaichiSyntaxError", """
@ti.kernel
def k():
    return 1  #!
k()
"""),
    ("field_too_few_indices", "TaichiIndexError", """
x = ti.field(ti.f32, shape=(2, 2))
@ti.kernel
def k():
    x[0] = 1.0  #!
k()
"""),
    ("try_in_kernel", "TaichiSyntaxError", """
@ti.kernel
def k():
    try:  #!
        pass
    except Exception:
        pass
k()
"""),
    ("lambda_in_kernel", "TaichiSyntaxError", """
@ti.kernel
def k():
    f = lambda v: v  #!
k()
"""),
    ("break_in_parallel_for", "TaichiSyntaxError", """
@ti.kernel
def k():
    for i in range(10):
        break  #!
k()
"""),
    ("for_else", "TaichiSyntaxError", """
@ti.kernel
def k():
    for i in range(10):  #!
        pass
    else:
        pass
k()
"""),
    ("static_non_constant", "TaichiCompilationError", """
@ti.kernel
def k(n: ti.i32):
    if ti.static(n > 1):  #!
        pass
k(2)
"""),
    ("vector_shape_mismatch", "TaichiTypeError", """
@ti.kernel
def k():
    a = ti.Vector([1.0, 2.0, 3.0]) + ti.Vector([1.0, 2.0])  #!
k()
"""),
    ("func_from_python_scope", "TaichiSyntaxError", """
@ti.func
def f():
    return 1
f()  #!
"""),
    ("bitand_on_floats", "TaichiTypeError", """
@ti.kernel
def k() -> ti.i32:
    a = 1.5
    b = a & 3  #!
    return 0
k()
"""),
    ("star_args_kernel", "TaichiSyntaxError", """
@ti.kernel
def k(*a):  #!
    pass
k(1)
"""),
    ("literal_overflow_i32", "TaichiTypeError", """
@ti.kernel
def k() -> ti.i32:
    a = ti.cast(0, ti.i32)
    a = 2 ** 40  #!
    return a
k()
"""),
    ("debug_assert_fails", "TaichiAssertionError", """
ti.init(arch=ti.cpu, debug=True)
@ti.kernel
def k(a: ti.i32):
    assert a > 1  #!
k(0)
"""),
    ("debug_out_of_bound", "TaichiAssertionError", """
ti.init(arch=ti.cpu, debug=True)
x = ti.field(ti.f32, shape=4)
@ti.kernel
def k(i: ti.i32):
    x[i] = 1.0  #!
k(9)
"""),
    ("struct_no_member", "TaichiCompilationError", """
S = ti.types.struct(a=ti.f32)
@ti.kernel
def k():
    s = S(a=1.0)
    b = s.c  #!
k()
"""),
    ("ndarray_wrong_ndim", "ValueError", """
import numpy as np
@ti.kernel
def k(a: ti.types.ndarray(dtype=ti.f32, ndim=2)):
    pass
k(np.zeros(3, dtype=np.float32))  #!
"""),
    ("ndarray_wrong_dtype", "ValueError", """
import numpy as np
@ti.kernel
def k(a: ti.types.ndarray(dtype=ti.f32, ndim=1)):
    pass
k(np.zeros(3, dtype=np.int32))  #!
"""),
    ("return_vector_for_scalar", "TaichiCompilationError", """
@ti.kernel
def k() -> ti.f32:
    return ti.Vector([1.0, 2.0])  #!
k()
"""),
    ("field_before_init", "TaichiRuntimeError", """
x = ti.field(ti.f32, shape=3)  #!
"""),
    ("destroyed_tree_twice", "TaichiRuntimeError", """
fb = ti.FieldsBuilder()
x = ti.field(ti.f32)
fb.dense(ti.i, 4).place(x)
t = fb.finalize()
t.destroy()
t.destroy()  #!
"""),
    ("local_shape_change", "TaichiTypeError", """
@ti.kernel
def k():
    a = ti.Vector([1.0, 2.0])
    a = ti.Vector([1.0, 2.0, 3.0])  #!
k()
"""),
    ("func_wrong_arg_count", "TaichiSyntaxError", """
@ti.func
def f(a):
    return a
@ti.kernel
def k() -> ti.i32:
    return f(1, 2)  #!
k()
"""),
    ("python_scope_index_count", "AssertionError", """
x = ti.field(ti.f32, shape=(2, 2))
x[0] = 1.0  #!
"""),
    ("template_arg_not_field_subscript", "TaichiCompilationError", """
@ti.kernel
def k(a: ti.template()):
    a[0] = 1  #!
k(3)
"""),
    ("ndarray_given_float", "TaichiRuntimeTypeError", """
@ti.kernel
def k(a: ti.types.ndarray()):
    pass
k(1.2)  #!
"""),
    ("struct_arg_mismatch", "TaichiRuntimeTypeError", """
sphere_type = ti.types.struct(center=ti.math.vec3, radius=float)
circle_type = ti.types.struct(center=ti.math.vec2, radius=float)
@ti.kernel
def k(sphere: sphere_type):
    pass
k(circle_type(center=ti.math.vec2([1, 2]), radius=2.33))  #!
"""),
    ("func_matrix_arg_wrong_shape", "TaichiSyntaxError", """
vec3 = ti.types.vector(3, ti.f32)
@ti.func
def f(a: vec3):
    a[0] = 100
@ti.kernel
def k():
    x = ti.Matrix([3, 4])
    f(x)  #!
k()
"""),
]


def _taichi_class(name: str) -> type:
    return getattr(ti, name) if hasattr(ti, name) else getattr(builtins, name)


@pytest.mark.parametrize("name,expected,source", CASES, ids=[c[0] for c in CASES])
def test_taichi_exception_class(tmp_path, name, expected, source):
    prelude = "import simgrad as ti\n" + ("" if name == "field_before_init" else "ti.init(arch=ti.cpu)\n")
    text = prelude + source.strip("\n") + "\n"
    path = tmp_path / f"misuse_{name}.py"
    path.write_text(text)
    line = next(k + 1 for k, s in enumerate(text.splitlines()) if "#!" in s)
    if name == "field_before_init":
        ti.reset()
    with pytest.raises(ti.SimgradError) as info:
        runpy.run_path(str(path), run_name="__main__")
    assert isinstance(info.value, _taichi_class(expected)), (type(info.value).__mro__, expected)
    assert f'File "{path}", line {line}' in str(info.value), str(info.value)


def test_taichi_hierarchy():
    """The Taichi names are classes of their own with Taichi's bases (not aliases of simgrad's)."""
    assert issubclass(ti.TaichiSyntaxError, ti.TaichiCompilationError) and issubclass(ti.TaichiSyntaxError, SyntaxError)
    assert issubclass(ti.TaichiTypeError, ti.TaichiCompilationError) and issubclass(ti.TaichiTypeError, TypeError)
    assert issubclass(ti.TaichiNameError, NameError) and issubclass(ti.TaichiIndexError, IndexError)
    assert issubclass(ti.TaichiRuntimeTypeError, ti.TaichiRuntimeError)
    assert issubclass(ti.TaichiRuntimeTypeError, TypeError)
    assert issubclass(ti.TaichiAssertionError, ti.TaichiRuntimeError)
    assert issubclass(ti.TaichiAssertionError, AssertionError)
    assert not issubclass(ti.TaichiRuntimeError, ti.TaichiCompilationError)
    assert not issubclass(ti.TaichiTypeError, ti.TaichiRuntimeError)
    # simgrad's concrete classes stay the ones raised
    assert issubclass(ti.SimgradTypeError, ti.TaichiTypeError)
    assert issubclass(ti.SimgradSyntaxError, ti.TaichiSyntaxError)
