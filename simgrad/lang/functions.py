"""@ti.func, and what the stages below the compiler know of a @ti.kernel.

A ti.func is inlined where it is called: calling one inside a kernel asks the compiler on the context
stack (ir/context.py) to inline it, so lang needs no frontend. The @ti.kernel object itself compiles and
launches, which is the compiler stage's (compiler/kernel.py); lang only defines its base, KernelDef, so the
frontend can refuse a kernel called from a kernel."""

from __future__ import annotations

import inspect

from simgrad.errors import AnnotationError, SimgradSyntaxError, caller_loc
from simgrad.ir import context


class KernelDef:
    """A @ti.kernel as lower stages see it: a name and the Python function it was made from."""

    name: str
    func: object


class Func:
    """@ti.func: inlined into the kernels that call it."""

    real = False  # @ti.real_func

    def __init__(self, func):
        self.func = func
        self.name = func.__name__
        self.signature = resolved_signature(func)
        self.__wrapped__ = func
        self.__doc__ = func.__doc__

    def __call__(self, *args, **kwargs):
        comp = context.current()
        if comp is None:
            raise SimgradSyntaxError(f"ti.func {self.name} can only be called from a kernel or another ti.func "
                                     "(Taichi functions cannot be called from Python-scope)", caller_loc())
        return comp.call_func(self, list(args), kwargs)  # the frontend's compiler inlines it

    def __get__(self, obj, owner=None):
        """`self.f(x)` on a @ti.data_oriented object: the func with the object as its first argument."""
        return self if obj is None else BoundFunc(self, obj)


class BoundFunc:
    """A ti.func method of an object: calling it inlines the func with the object as `self`."""

    def __init__(self, func: Func, obj):
        self.func, self.obj = func, obj
        self.name = func.name

    def __call__(self, *args, **kwargs):
        return self.func(self.obj, *args, **kwargs)


def data_oriented(cls):
    """@ti.data_oriented: a class whose methods may be kernels and funcs (`self` is a compile-time value,
    like a ti.template() argument). Kernels and funcs bind to instances by themselves; the decorator only
    marks the class, as Taichi's does, so that passing such an object as a template argument reads well."""
    cls._data_oriented = True
    if not any(k in vars(cls) for k in ("__reduce__", "__reduce_ex__", "__getstate__")):
        cls.__reduce__ = _refuse_data_oriented  # its fields and kernels are this process's: build it in the worker
    return cls


def _refuse_data_oriented(self):
    from simgrad.lang.pickling import function_loc, refuse_pickle

    init = getattr(type(self), "__init__", None)
    refuse_pickle(f"data_oriented object {type(self).__qualname__}", function_loc(init))


def func(fn=None, **kw):
    if fn is None:
        return lambda f: Func(f)
    return Func(fn)


def real_func(fn):
    """@ti.real_func: inlined like a ti.func (a recursive one is refused with a located error), with Taichi's
    rules for real functions: every parameter annotated, the return value annotated, loops serial."""
    import inspect

    for k, (name, p) in enumerate(inspect.signature(fn).parameters.items()):
        if k == 0 and name == "self":  # a method of a @ti.data_oriented class (its object is compile-time)
            continue
        if p.annotation is inspect.Parameter.empty:
            raise SimgradSyntaxError(f"Argument {name} of real function {fn.__name__} must be type annotated",
                                     caller_loc())
    f = Func(fn)
    f.real = True
    return f


def pyfunc(fn):
    return Func(fn)


def resolved_signature(func) -> inspect.Signature:
    """The signature with string annotations (`from __future__ import annotations`) evaluated."""
    sig = inspect.signature(func)
    if not any(isinstance(p.annotation, str) for p in sig.parameters.values()) and \
            not isinstance(sig.return_annotation, str):
        return sig
    scope = dict(func.__globals__)
    if func.__closure__:
        for name, cell in zip(func.__code__.co_freevars, func.__closure__):
            try:
                scope[name] = cell.cell_contents
            except ValueError:
                pass

    def ev(a):
        if isinstance(a, str):
            try:
                return eval(a, scope)  # noqa: S307 - the user's own annotation text
            except Exception as e:
                raise AnnotationError(f"{func.__name__}: cannot evaluate annotation {a!r}: {e}") from None
        return a

    params = [p.replace(annotation=ev(p.annotation)) for p in sig.parameters.values()]
    return sig.replace(parameters=params, return_annotation=ev(sig.return_annotation))


def binding_error(sig: inspect.Signature, args, kwargs) -> str:
    """Why `args`/`kwargs` do not bind to `sig`, in Taichi's words (its tests match them: "Too many arguments",
    "Parameter `a : i32` missing", "Unexpected argument 'c'", "Multiple values for argument 'a'"); "" when
    they bind. An unknown keyword is reported first (Python would say a parameter is missing)."""
    unknown = unexpected_keywords(sig, kwargs)
    if unknown:
        return unknown
    params = [p for p in sig.parameters.values() if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(args) > len(params) and not any(p.kind is p.VAR_POSITIONAL for p in sig.parameters.values()):
        expected = ", ".join(_param_text(p) for p in params)
        return f"Too many arguments. Expected ({expected}), got ({', '.join(map(_arg_text, args))})."
    for p in params[:len(args)]:
        if p.name in kwargs:
            return f"Multiple values for argument '{p.name}'."
    for p in params[len(args):]:
        if p.name not in kwargs and p.default is inspect.Parameter.empty:
            return f"Parameter `{_param_text(p)}` missing."
    try:
        sig.bind(*args, **kwargs)
    except TypeError as e:
        return str(e)
    return ""


def _param_text(p: inspect.Parameter) -> str:
    if p.annotation is inspect.Parameter.empty:
        return p.name
    return f"{p.name} : {p.annotation}"


def _arg_text(a) -> str:
    text = repr(a)
    return text if len(text) <= 40 else type(a).__name__


def unexpected_keywords(sig: inspect.Signature, kwargs) -> str:
    """Python's bind reports a missing parameter before an unknown keyword (`k(b=1)` for `k(a)` says
    "missing 'a'"); the unknown keyword is the real mistake, so it is reported first."""
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values()):
        return ""
    names = [p.name for p in sig.parameters.values() if p.kind is not inspect.Parameter.POSITIONAL_ONLY]
    bad = [k for k in kwargs if k not in names]
    if not bad:
        return ""
    return f"Unexpected argument '{bad[0]}' (its parameters are: {', '.join(sig.parameters)})."
