"""Calls inside kernels: ti.func inlining, Python builtins with kernel meaning, print, plain Python."""

from __future__ import annotations

import ast
import builtins
import inspect

from simgrad import dtypes as dt
from simgrad.errors import ArgumentCountError, SimgradError, SimgradSyntaxError, SimgradTypeError
from simgrad.frontend.frames import Frame, RangeSpec
from simgrad.frontend.realfuncs import call_real, check_matrix_argument, specialisation
from simgrad.frontend.refs import LOCAL_REFS, MatrixRef, VarRef, tensor_text
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.field import Field, MatrixField, ScalarField
from simgrad.lang.loops import static as _static
from simgrad.lang.matrix import Matrix
from simgrad.lang.struct import Struct


def _builtin_int(x=0, *rest):
    return operators.cast(x, dt.Defaults.ip) if isinstance(x, (Expr, Matrix)) else int(x, *rest)


def _builtin_float(x=0.0):
    return operators.cast(x, dt.Defaults.fp) if isinstance(x, (Expr, Matrix)) else float(x)


def _builtin_len(x):
    if isinstance(x, Field):
        return x.shape[0]
    return len(x)


def _builtin_round(x, ndigits=None):
    if isinstance(x, (Expr, Matrix)):
        return operators.round(x)
    return round(x, ndigits) if ndigits is not None else round(x)


def _builtin_bool(x=False):
    return operators.ne(x, 0) if isinstance(x, Expr) else bool(x)


def _builtin_range(*args):
    return RangeSpec(*args)


def _reduce_bool(x, how: str):
    """all()/any() of a matrix of kernel values is the matrix's own .all()/.any() (as in Taichi); of a
    Python iterable, Python's."""
    if isinstance(x, Matrix):
        return x.all() if how == "all" else x.any()
    items = list(x)
    if any(isinstance(v, (Expr, Matrix)) for v in items):
        return Matrix(items).all() if how == "all" else Matrix(items).any()
    return builtins.all(items) if how == "all" else builtins.any(items)


_BUILTINS = {
    builtins.range: _builtin_range,
    builtins.int: _builtin_int,
    builtins.float: _builtin_float,
    builtins.abs: operators.abs,
    builtins.min: operators.min,
    builtins.max: operators.max,
    builtins.pow: operators.pow,
    builtins.len: _builtin_len,
    builtins.round: _builtin_round,
    builtins.bool: _builtin_bool,
    builtins.all: lambda x: _reduce_bool(x, "all"),
    builtins.any: lambda x: _reduce_bool(x, "any"),
}


def call(comp, node: ast.Call):
    target = _local_matrix_method(comp, node, "fill")
    if target is not None:  # `m.fill(v)` on a local matrix assigns it (a loaded copy would be dropped)
        if len(node.args) != 1 or node.keywords:
            raise SimgradTypeError("fill() takes one value", comp.loc(node))
        target.store(comp.eval(node.args[0]))
        return None
    fn = comp.eval(node.func)
    kind = getattr(fn, "atomic_kind", None)
    if kind is not None:
        return _atomic(comp, node, kind)
    by_ref = _template_params(fn)
    args = []
    kwargs = {}
    static = fn is _static
    comp.static_scope += static  # `in` / `is` are Python's on compile-time values there
    try:
        for k, a in enumerate(node.args):
            v = _by_reference(comp, a) if k in by_ref else comp.eval(a)
            if type(v).__name__ == "_Starred":
                args.extend(list(v.value.entries if isinstance(v.value, Matrix) else v.value))
            else:
                args.append(v)
        for kw in node.keywords:
            if kw.arg is None:
                kwargs.update(comp.eval(kw.value))
            else:
                kwargs[kw.arg] = _by_reference(comp, kw.value) if kw.arg in by_ref else comp.eval(kw.value)
    finally:
        comp.static_scope -= static
    if isinstance(getattr(fn, "__self__", None), str) and getattr(fn, "__name__", "") == "format":
        from simgrad.frontend.printing import str_format

        return str_format(fn.__self__, tuple(args), kwargs)
    if fn is builtins.print:
        from simgrad.frontend.printing import emit_print

        emit_print(comp, args, kwargs)
        return None
    try:
        hashable = fn in _BUILTINS
    except TypeError:
        hashable = False
    if hashable:
        return _BUILTINS[fn](*args, **kwargs)
    from simgrad.lang.functions import BoundFunc, Func, KernelDef

    if isinstance(fn, Func):
        return call_func(comp, fn, args, kwargs, node)
    if isinstance(fn, BoundFunc):  # a ti.func method of a data-oriented object
        return call_func(comp, fn.func, [fn.obj, *args], kwargs, node)
    if isinstance(fn, KernelDef):
        raise SimgradSyntaxError(f"kernel {fn.name} cannot be called from inside a kernel; make it a @ti.func",
                                 comp.loc(node))
    if not callable(fn):
        raise SimgradTypeError(f"'{type(fn).__name__}' object is not callable", comp.loc(node))
    if getattr(fn, "__func__", None) in _FILLS:  # emits IR from the field's (keyed) layout: cacheable
        from simgrad.frontend.loops import emit_fill

        return emit_fill(fn.__self__, *args, **kwargs)
    if comp.guard is not None:
        comp.guard.call(fn)
    return fn(*args, **kwargs)


_FILLS = (ScalarField.fill, MatrixField.fill)


def _local_matrix_method(comp, node: ast.Call, name: str):
    """The assignable matrix (a local, a field or ndarray element, a struct member) of a call
    `m.<name>(...)`, else None."""
    f = node.func
    if isinstance(f, ast.Attribute) and f.attr == name and isinstance(f.value, (ast.Name, ast.Subscript,
                                                                                   ast.Attribute)):
        v = comp.ref(f.value)
        if isinstance(v, MatrixRef):
            return v
    return None


def _template_params(fn) -> set:
    """Positions and names of a ti.func's ti.template() parameters (a local passed there is passed by
    reference, as in Taichi: `x = 1` in the callee assigns the caller's variable)."""
    from simgrad.lang.functions import BoundFunc, Func
    from simgrad.lang.types import by_reference

    shift = 0
    if isinstance(fn, BoundFunc):
        fn, shift = fn.func, 1
    if not isinstance(fn, Func):
        return set()
    out: set = set()
    for k, (name, p) in enumerate(fn.signature.parameters.items()):
        if by_reference(p.annotation):
            out.update((k - shift, name))
    return out


def _by_reference(comp, node: ast.expr):
    """A local variable itself when `node` names one, else its value."""
    if isinstance(node, ast.Name):
        v = comp.lookup(node.id, node)
        if isinstance(v, LOCAL_REFS):
            return v
    return comp.eval(node)


def _atomic(comp, node: ast.Call, kind: str):
    if len(node.args) != 2:
        raise SimgradSyntaxError(f"ti.atomic_{kind}(dest, value) takes two arguments", comp.loc(node))
    ref = comp.ref(node.args[0])
    if ref is None:
        raise SimgradSyntaxError(f"cannot use a non-writable target as the first operand of ti.atomic_{kind}: "
                                 "it must be a field element, an ndarray element or a local variable",
                                 comp.loc(node))
    return ref.atomic("atomic_mul" if kind == "mul" else kind, comp.eval(node.args[1]))


def _check_array_argument(name: str, ann, value, loc, real: bool = False) -> None:
    """An ndarray passed to a ti.func parameter annotated ti.types.ndarray(dtype, ndim): its element type and
    dimensions must be those (Taichi's TaichiCompilationError "Invalid value for argument a"); a real function
    takes only the kernel's own ndarray arguments (not one the kernel reads from Python's globals)."""
    from simgrad.frontend.arrays import ArrayArg
    from simgrad.lang.types import MatrixType, NdarrayType

    if not isinstance(ann, NdarrayType):
        return
    if not isinstance(value, ArrayArg):
        if real:
            raise SimgradTypeError(f"Expected ndarray in the kernel argument for argument {name}, got "
                                   f"{type(value).__name__} (pass the ndarray to the kernel)", loc)
        return
    have = tuple(value.element_shape)
    wrong = None
    if ann.ndim is not None and ann.ndim != value.ndim:
        wrong = f"ndim={ann.ndim}, got an array of ndim={value.ndim}"
    elif isinstance(ann.dtype, MatrixType) and ann.dtype.n is not None and tuple(ann.dtype.shape) != have:
        wrong = f"element shape {tuple(ann.dtype.shape)}, got {have}"
    elif ann.dtype is not None and not isinstance(ann.dtype, MatrixType) and (
            have or dt.from_any(ann.dtype) is not value.dtype):
        wrong = f"element type {dt.from_any(ann.dtype)}, got {tensor_text(have, value.dtype)}"
    if wrong:
        raise SimgradTypeError(f"Invalid value for argument {name} - required {wrong}", loc)


def call_func(comp, fn, args, kwargs, node):
    """A ti.func call: inlined; a real function's too, unless the same specialisation is being inlined
    already (run-time recursion): then a CALL of its Function (frontend/realfuncs.py)."""
    from simgrad.lang.functions import binding_error

    sig = fn.signature
    wrong = binding_error(sig, args, kwargs)
    if wrong:
        raise ArgumentCountError(f"calling ti.func {fn.name}: {wrong}", comp.loc(node))
    bound = sig.bind(*args, **kwargs)
    bound.apply_defaults()
    key = None
    if getattr(fn, "real", False):
        key = specialisation(fn, bound)
        if key is not None and (key in comp.real_functions or any(f.real_key == key for f in comp.frames)):
            return call_real(comp, fn, bound, key, node)
    return inline(comp, fn, bound, node, key)


def inline(comp, fn, bound, node, real_key=None):
    """Inline a ti.func (its arguments bound): parameters are fresh locals (pass by value) except ti.template()
    ones."""
    from simgrad.frontend.source import get_source
    from simgrad.lang.types import MatrixType, by_reference

    if len(comp.frames) > comp.MAX_INLINE_DEPTH:
        raise SimgradSyntaxError(f"ti.func {fn.name} recurses too deeply (recursion is not supported)",
                                 comp.loc(node))
    sig = fn.signature
    frame = Frame(get_source(fn.func), False)
    frame.real = getattr(fn, "real", False)
    frame.real_key = real_key
    for name, value in bound.arguments.items():
        ann = sig.parameters[name].annotation
        _check_array_argument(name, ann, value, comp.loc(node), getattr(fn, "real", False))
        if by_reference(ann) or not isinstance(value, (Expr, Matrix, Struct, int, float)) or isinstance(value, bool):
            frame.scopes[0][name] = value
        elif isinstance(value, Struct):  # by value, as matrices: `s.b *= 2` in the callee's loop assigns a local
            frame.scopes[0][name] = comp.new_var(value)
        elif isinstance(ann, MatrixType):
            check_matrix_argument(name, ann, value, comp.loc(node))
            frame.scopes[0][name] = comp.new_var(ann.make(value), ann.dtype)
        elif ann is not inspect.Parameter.empty and _is_scalar_type(ann):
            frame.scopes[0][name] = comp.new_var(value, ann)
        else:
            frame.scopes[0][name] = comp.new_var(value)
    frame.entry_block = comp.builder.block  # where its early-return locals are declared
    frame.entry_index = len(comp.builder.block.stmts)
    frame.loop_base = len(comp.loop_stack)
    comp.frames.append(frame)
    ann = None
    try:
        comp.visit_block(frame.src.tree.body)
        if frame.src.tree.returns is not None:  # in the callee's scope: its closure may define the type
            ann = sig.return_annotation
            if isinstance(ann, str) or ann is inspect.Signature.empty:
                ann = comp.eval(frame.src.tree.returns)
    except SimgradError:
        raise
    finally:
        comp.frames.pop()
    rv = frame.ret_var.load() if frame.ret_var is not None else frame.return_value
    if frame.real and ann is None and rv is not None:
        raise SimgradSyntaxError(f"the return value must be annotated: real function {fn.name} returns a value "
                                 "(add -> ti.f32 or another type)", comp.loc(node))
    if ann is not None and rv is None and not frame.has_returned and frame.ret_var is None:
        raise SimgradSyntaxError(f"Function has a return type but does not have a return statement "
                                 f"(ti.func {fn.name})", comp.loc(node))
    if ann is not None and rv is not None:
        if _is_scalar_type(ann) and isinstance(rv, (Expr, int, float)):
            rv = operators.cast(rv, ann)
    return rv


def _is_scalar_type(ann) -> bool:
    return isinstance(ann, dt.DataType) or ann in (int, float)


__all__ = ["call", "call_func", "inline", "VarRef", "MatrixRef", "Op"]
