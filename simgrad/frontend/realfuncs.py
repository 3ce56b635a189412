"""Recursive ti.real_func calls: a real function that calls itself (directly or through others) at run time
becomes an IR Function (ir/nodes.py), lowered once per specialisation and called with CALL.

A real function is inlined like a ti.func (its gradient then works, and LLVM sees one body); only a call that
would inline a specialisation already being inlined (the same function with the same compile-time arguments:
templates, ndarrays, Python values) cannot be: that specialisation is lowered into a Function of its own, its
run-time parameters (scalars, matrices) as PARAMs, and every call of it from then on is a CALL. Taichi compiles
every real function so; simgrad's first call of it stays inlined."""

from __future__ import annotations

import inspect

from simgrad import dtypes as dt
from simgrad.errors import SimgradSyntaxError
from simgrad.frontend.frames import Frame
from simgrad.frontend.refs import LOCAL_REFS
from simgrad.ir.builder import Builder
from simgrad.ir.nodes import Function
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix
from simgrad.lang.struct import Struct
from simgrad.lang.types import MatrixType, RefType, by_reference


def runtime_param(ann, value) -> bool:
    """Whether a real function's parameter is passed at run time (else it is a compile-time value, part of the
    specialisation), by the rule frontend/calls.py inline() binds parameters with."""
    return not (by_reference(ann) or not isinstance(value, (Expr, Matrix, Struct, int, float))
                or isinstance(value, bool))


def specialisation(fn, bound: inspect.BoundArguments):
    """A hashable key of `fn` with these compile-time arguments (None: not keyable, never a Function)."""
    parts: list = [id(fn)]
    for name, value in bound.arguments.items():
        ann = fn.signature.parameters[name].annotation
        if isinstance(ann, RefType):
            parts.append(("ref", name))
        elif runtime_param(ann, value):
            parts.append(("value", name))
        elif isinstance(value, LOCAL_REFS):
            return None  # a local passed to a template parameter: it is the caller's variable itself
        else:  # a field, an ndarray argument, a Python value: the object itself (numbers and strings by value)
            same = value if isinstance(value, (int, float, str)) else id(value)
            parts.append(("static", name, type(value), same))
    return tuple(parts)


def check_matrix_argument(name: str, ann: MatrixType, value, loc) -> None:
    """A matrix for a parameter annotated with a matrix type has its shape (Taichi's TaichiSyntaxError texts);
    it was reinterpreted silently."""
    if not isinstance(value, Matrix) or ann.n is None:
        return
    want, got = ann.shape, value.shape
    if len(want) != len(got):
        raise SimgradSyntaxError(f"Argument {name} of type {ann} is expected to be a Matrix with ndim {len(want)}, "
                                 f"but got {len(got)}.", loc)
    for axis, letter in enumerate("nm"[:len(want)]):
        if want[axis] != got[axis]:
            raise SimgradSyntaxError(f"Argument {name} of type {ann} is expected to be a Matrix with {letter} "
                                     f"{want[axis]}, but got {got[axis]}.", loc)


def _flat_type(ann, what: str, fn, loc) -> list[dt.DataType]:
    """The scalar types a run-time parameter or the result travels as (a matrix: its entries in order)."""
    if isinstance(ann, MatrixType) and ann.n is not None:
        return [ann.dtype] * ann.num_entries
    if isinstance(ann, dt.DataType):
        return [ann]
    if ann is int:
        return [dt.Defaults.ip]
    if ann is float:
        return [dt.Defaults.fp]
    raise SimgradSyntaxError(f"{what} of the recursive real function {fn.name} has type {ann!r}: a real function "
                             "that calls itself takes and returns scalars and matrices (simgrad)", loc)


def call_real(comp, fn, bound: inspect.BoundArguments, key, node):
    """The CALL of `fn`'s Function for `key` (lowered now when this is its first call), and its result."""
    loc = comp.loc(node)
    if key not in comp.real_functions:
        _define(comp, fn, bound, key, loc)
    func, result_ann = comp.real_functions[key]
    operands = []
    for name, value in bound.arguments.items():
        ann = fn.signature.parameters[name].annotation
        if not runtime_param(ann, value):
            continue
        if isinstance(ann, MatrixType):
            check_matrix_argument(name, ann, value, loc)
            entries = ann.make(value).entries
        else:
            entries = [value]
        operands += [entries]
    flat = [e for es in operands for e in es]
    args = [operators.cast_expr(operators.to_expr(v, t), t).stmt for v, t in zip(flat, func.params)]
    call = comp.builder.emit(Op.CALL, None, args, {"func": func})
    results = [Expr(comp.builder.emit(Op.CALL_RESULT, t, (call,), {"index": k})) for k, t in enumerate(func.returns)]
    if not results:
        return None
    if isinstance(result_ann, MatrixType):
        return Matrix(n=result_ann.n, m=result_ann.m, _entries=results)
    return results[0]


def _define(comp, fn, bound: inspect.BoundArguments, key, loc) -> None:
    """Lower `fn`'s body for these compile-time arguments into a new Function of the kernel, recorded in
    comp.real_functions[key] with its result's annotation (before the body: its own calls find it there)."""
    from simgrad.frontend.source import get_source

    src = get_source(fn.func)
    params: list[dt.DataType] = []
    for name, value in bound.arguments.items():
        ann = fn.signature.parameters[name].annotation
        if isinstance(ann, RefType):
            raise SimgradSyntaxError(f"parameter {name} of the recursive real function {fn.name} is a ti.ref: a real "
                                     "function that calls itself takes its arguments by value (simgrad)", loc)
        if runtime_param(ann, value):
            params += _flat_type(ann, f"parameter {name}", fn, loc)
    func = Function(f"{fn.name}_{len(comp.ir.functions)}", params, [], loc)
    comp.ir.functions.append(func)
    saved = (comp.builder, comp.frames, comp.loop_stack, comp.depth, comp.next_loop_config, comp.static_scope)
    comp.builder = Builder(func.body)
    comp.builder.loc = loc
    frame = Frame(src, False)
    frame.real = True
    frame.real_key = key
    comp.frames, comp.loop_stack, comp.depth, comp.next_loop_config, comp.static_scope = [frame], [], 0, None, 0
    try:
        ret_ann = fn.signature.return_annotation
        if src.tree.returns is None:
            ret_ann = None
        elif isinstance(ret_ann, str) or ret_ann is inspect.Signature.empty:
            ret_ann = comp.eval(src.tree.returns)
        func.returns = _flat_type(ret_ann, "the result", fn, loc) if ret_ann is not None else []
        comp.real_functions[key] = (func, ret_ann)
        index = 0
        for name, value in bound.arguments.items():
            ann = fn.signature.parameters[name].annotation
            if not runtime_param(ann, value):
                frame.scopes[0][name] = value
                continue
            n = len(_flat_type(ann, f"parameter {name}", fn, loc))
            entries = [Expr(comp.builder.emit(Op.PARAM, func.params[index + k], (), {"index": index + k}))
                       for k in range(n)]
            index += n
            if isinstance(ann, MatrixType):
                frame.scopes[0][name] = comp.new_var(Matrix(n=ann.n, m=ann.m, _entries=entries), ann.dtype)
            else:
                frame.scopes[0][name] = comp.new_var(entries[0], func.params[index - 1])
        frame.entry_block = func.body
        frame.entry_index = len(func.body.stmts)
        comp.visit_block(src.tree.body)
        rv = frame.ret_var.load() if frame.ret_var is not None else frame.return_value
        if func.returns and rv is None:
            raise SimgradSyntaxError(f"Function has a return type but does not have a return statement "
                                     f"(ti.real_func {fn.name})", loc)
        if rv is not None and not func.returns:
            raise SimgradSyntaxError(f"the return value must be annotated: real function {fn.name} returns a value "
                                     "(add -> ti.f32 or another type)", loc)
        values = [] if rv is None else (list(ret_ann.make(rv).entries) if isinstance(ret_ann, MatrixType) else [rv])
        outs = [operators.cast_expr(operators.to_expr(v, t), t).stmt for v, t in zip(values, func.returns)]
        comp.builder.emit(Op.FUNC_RETURN, None, outs)
    finally:
        comp.builder, comp.frames, comp.loop_stack, comp.depth, comp.next_loop_config, comp.static_scope = saved
