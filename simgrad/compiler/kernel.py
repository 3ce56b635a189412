"""@ti.kernel: the object a decorated function becomes. It binds arguments, picks or compiles the
instantiation they need (compiler/driver.py) and launches it; Tape recording goes through lang/ad_hooks."""

from __future__ import annotations

import inspect
import os
import time

import numpy as np

from simgrad.autodiff.forward import adjoint_then_forward, make_forward
from simgrad.autodiff.validate import check_and_adjoint, check_in_place_and_adjoint
from simgrad.compiler import params
from simgrad.compiler.driver import COMPILE_LOCK, CompiledKernel, compile_kernel
from simgrad.compiler.params import TemplateParam, make_param
from simgrad.errors import (
    ArgumentCountError,
    ArgumentTypeError,
    ArgumentValueError,
    Loc,
    SimgradError,
    SimgradSyntaxError,
    SimgradTypeError,
    SimgradValueError,
    caller_loc,
)
from simgrad.lang import ad_hooks
from simgrad.lang.argpack import ArgPackType
from simgrad.lang.functions import KernelDef, binding_error, resolved_signature
from simgrad.lang.pickling import function_loc, refuse_pickle
from simgrad.lang.program import Program, get_program
from simgrad.runtime.args import FortranOrderArray

# mode -> (IR transform, symbol suffix) of a kernel's instantiations: "" the kernel; "grad" its adjoint;
# "fwd" it with forward-mode tangents (inside ti.ad.FwdMode); "gradfwd" its adjoint with tangents
# (kernel.grad inside FwdMode: Hessian-vector products); "grad_in_place" its adjoint run on the state before
# the kernel (in-place kernels: ti.ad.checkpoint, the Tape's rollback)
_MODES = {"": (None, ""), "grad": (check_and_adjoint, "_grad"), "fwd": (make_forward, "_fwd"),
          "gradfwd": (adjoint_then_forward, "_gradfwd"), "grad_in_place": (check_in_place_and_adjoint, "_grad")}


class Kernel(KernelDef):
    """A @ti.kernel: binds arguments, keeps one CompiledKernel per instantiation (template values, ndarray
    dtypes and shapes) and launches it; `.grad` launches the adjoint."""

    def __init__(self, func) -> None:
        self.func = func
        self.name = func.__name__
        self.__name__, self.__qualname__, self.__module__ = func.__name__, func.__qualname__, func.__module__
        self.signature = resolved_signature(func)
        _check_parameter_kinds(func, self.signature)
        self.params = [_make_param(k, n, p.annotation, self.name)
                       for k, (n, p) in enumerate(self.signature.parameters.items())]
        self._nparams = len(self.params)
        if isinstance(self.signature.return_annotation, ArgPackType):  # as Taichi: packs only pass arguments
            code = func.__code__
            raise SimgradSyntaxError(f"kernel {self.name}: an argpack ({self.signature.return_annotation!r}) "
                                     "cannot be a return type", Loc(code.co_filename, code.co_firstlineno))
        # the parameters whose arguments pick the instantiation; without any, one instance serves every call
        self._keyed = [(k, p) for k, p in enumerate(self.params) if p.keyed]
        self._simple = not self._keyed
        self._has_defaults = any(p.default is not inspect.Parameter.empty
                                 for p in self.signature.parameters.values())
        self._keep: list = []
        self._generation = -1
        self._simple_launch = None
        self._simple_instance: CompiledKernel | None = None
        self._caches: dict[str, dict] = {mode: {} for mode in _MODES}  # mode -> instantiation key -> instance
        self.grad = GradKernel(self)
        self.__doc__ = func.__doc__
        self.__wrapped__ = func

    def __reduce__(self):
        refuse_pickle(f"kernel {self.name}", function_loc(self.func))

    def __call__(self, *args, **kwargs):
        if kwargs or (self._has_defaults and len(args) != self._nparams):
            args = self._bind(args, kwargs)
        if ad_hooks.recorder is not None:
            ad_hooks.recorder(self, args)
        prog = get_program()
        if self._generation != prog.generation:
            self._reset(prog)
        launch = self._simple_launch
        if launch is None or len(args) != self._nparams or ad_hooks.forward_mode is not None:
            launch = self._launch_for(args, "fwd" if ad_hooks.forward_mode is not None else "")
        try:
            if prog.config.kernel_profiler:
                return prog.profiled_launch(self.name, launch, args)
            return launch(*args)
        except FortranOrderArray:
            return _with_c_copies(launch, args)
        except SimgradTypeError as e:
            raise _argument_error(e, ArgumentTypeError) from None

    def __get__(self, obj, owner=None):
        """`obj.step()` for a kernel method: the kernel with the object as its first (template) argument."""
        return self if obj is None else BoundKernel(self, obj)

    def _bind(self, args, kwargs):
        wrong = binding_error(self.signature, args, kwargs)
        if wrong:
            raise ArgumentCountError(f"kernel {self.name}: {wrong}", caller_loc())
        b = self.signature.bind(*args, **kwargs)
        b.apply_defaults()
        return tuple(b.arguments.values())

    def _reset(self, prog: Program) -> None:
        for cache in self._caches.values():
            cache.clear()
        self._keep.clear()
        self._simple_launch = None
        self._simple_instance = None
        self._generation = prog.generation

    def _launch_for(self, args, mode: str = ""):
        """The launcher of the instance for `args` in `mode` (see _MODES)."""
        return self._instance_for(args, mode).launch

    def instance(self, args) -> CompiledKernel:
        """The (compiled) forward instance these arguments launch."""
        return self._instance_for(args, "")

    def _instance_for(self, args, mode: str) -> CompiledKernel:
        if len(args) != self._nparams:
            raise ArgumentCountError(f"kernel {self.name}: {binding_error(self.signature, args, {})}",
                                     caller_loc())
        keep: list = []
        try:
            key = tuple([p.key(args[k], keep) for k, p in self._keyed])
            cache = self._caches[mode]
            inst = cache.get(key)
            if inst is None:
                with COMPILE_LOCK:  # the frontend and passes share state: one compile at a time
                    inst = cache.get(key)
                    if inst is None:
                        inst = self._compile_instance(args, mode, key, keep, cache)
        except (SimgradTypeError, SimgradValueError) as e:
            if not _raised_in(e, _PARAMS_FILE):
                raise
            raise _argument_error(e, ArgumentValueError) from None
        return inst

    def _compile_instance(self, args, mode: str, key, keep: list, cache: dict) -> CompiledKernel:
        t0 = time.perf_counter()
        try:
            return self._compile_uncounted(args, mode, key, keep, cache)
        finally:
            prog = get_program()
            prog.compile_seconds += time.perf_counter() - t0
            prog.instantiations += 1

    def _compile_uncounted(self, args, mode: str, key, keep: list, cache: dict) -> CompiledKernel:
        transform, suffix = _MODES[mode]
        inst = compile_kernel(self, get_program(), args, transform=transform, name_suffix=suffix)
        if mode == "" and self._simple:
            self._simple_launch = inst.launch
            self._simple_instance = inst
        cache[key] = inst
        self._keep.extend(keep)
        return inst


class GradKernel:
    """`kernel.grad(*args)`: launches the adjoint of the kernel (built once per instantiation)."""

    def __init__(self, kernel: Kernel):
        self.kernel = kernel
        self.name = kernel.name + ".grad"

    def __reduce__(self):
        refuse_pickle(f"kernel {self.name}", function_loc(self.kernel.func))

    def launcher(self, args):
        """The adjoint's launcher for these (bound) arguments, compiled on first use: what a captured backward
        pass replays (lang/tape.py)."""
        k = self.kernel
        prog = get_program()
        if k._generation != prog.generation:
            k._reset(prog)
        return k._instance_for(args, "grad").launcher

    def in_place(self, *args) -> None:
        """The adjoint for ti.ad.checkpoint: launched on the state *before* the kernel ran, so reads of
        elements the kernel overwrites in place (owned) replay their old values."""
        k = self.kernel
        prog = get_program()
        if k._generation != prog.generation:
            k._reset(prog)
        k._launch_for(args, "grad_in_place")(*args)

    def __call__(self, *args, **kwargs):
        k = self.kernel
        if kwargs or (k._has_defaults and len(args) != k._nparams):
            args = k._bind(args, kwargs)
        prog = get_program()
        if k._generation != prog.generation:
            k._reset(prog)
        # inside ti.ad.FwdMode the adjoint runs with tangents: gradients' duals get Hessian-vector products
        launch = k._launch_for(args, "gradfwd" if ad_hooks.forward_mode is not None else "grad")
        try:
            if prog.config.kernel_profiler:
                prog.profiled_launch(self.name, launch, args)
                return None
            launch(*args)
        except SimgradTypeError as e:
            raise _argument_error(e, ArgumentTypeError) from None
        return None


class BoundKernel:
    """A kernel method of an object; `.grad` is the bound adjoint."""

    def __init__(self, kernel: Kernel, obj):
        self.kernel, self.obj = kernel, obj
        self.name = kernel.name
        self.__name__ = kernel.__name__
        self.grad = _BoundGrad(kernel.grad, obj)

    def __reduce__(self):
        refuse_pickle(f"kernel {self.name}", function_loc(self.kernel.func))

    def __call__(self, *args, **kwargs):
        if not getattr(type(self.obj), "_data_oriented", False) and not isinstance(self.obj, type):
            cls = type(self.obj).__name__  # Taichi's rule: kernel methods belong to @ti.data_oriented classes
            raise SimgradSyntaxError(f"Please decorate class {cls} with @ti.data_oriented (kernel {self.name} is "
                                     "one of its methods)", caller_loc())
        return self.kernel(self.obj, *args, **kwargs)


class _BoundGrad:
    def __init__(self, grad: GradKernel, obj):
        self.grad, self.obj = grad, obj

    def __reduce__(self):
        refuse_pickle(f"kernel {self.grad.name}", function_loc(self.grad.kernel.func))

    def __call__(self, *args, **kwargs):
        return self.grad(self.obj, *args, **kwargs)

    def in_place(self, *args) -> None:
        self.grad.in_place(self.obj, *args)


def _with_c_copies(launch, args):
    """Run `launch` with C-ordered copies of the Fortran-ordered numpy arguments, then copy them back (Taichi's
    handling of a transposed array: the kernel sees it as indexed, and its writes land in it)."""
    copies = [(a, np.ascontiguousarray(a)) if isinstance(a, np.ndarray) and not a.flags.c_contiguous
              and a.flags.f_contiguous else None for a in args]
    try:
        return launch(*[c[1] if c else a for a, c in zip(args, copies)])
    except SimgradTypeError as e:
        raise _argument_error(e, ArgumentTypeError) from None
    finally:
        for c in copies:
            if c is not None:
                np.copyto(c[0], c[1])


def _argument_error(e: SimgradError, cls: type[SimgradTypeError]) -> SimgradError:
    """An argument refused when it is passed (the launcher's packing, the parameter's key), as the class
    Taichi raises there: TaichiRuntimeTypeError for a scalar or vector, ValueError for an array (both
    still SimgradTypeErrors). Errors already of a more precise class pass unchanged."""
    if type(e) is SimgradTypeError:
        out: SimgradError = cls(e.message, e.loc or caller_loc())
    elif type(e) is SimgradValueError and e.loc is None:
        out = SimgradValueError(e.message, caller_loc())
    else:
        return e
    out.__traceback__ = e.__traceback__
    return out


# an argument's checks live in the parameter kinds (compiler/params.py: key and bind)
_PARAMS_FILE = os.path.abspath(params.__file__)


def _raised_in(e: BaseException, filename: str) -> bool:
    """Whether the innermost frame of e's traceback is in `filename`."""
    tb = e.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    return os.path.abspath(tb.tb_frame.f_code.co_filename) == filename


def _check_parameter_kinds(func, signature: inspect.Signature) -> None:
    """*args / **kwargs / keyword-only parameters: Taichi refuses them with a TaichiSyntaxError."""
    for p in signature.parameters.values():
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD, p.KEYWORD_ONLY):
            what = {p.VAR_POSITIONAL: "variable positional parameters (i.e., *args)",
                    p.VAR_KEYWORD: "variable keyword parameters (i.e., **kwargs)",
                    p.KEYWORD_ONLY: "keyword-only parameters"}[p.kind]
            raise SimgradSyntaxError(f"Taichi kernels do not support {what}: kernel {func.__name__}, "
                                     f"parameter '{p.name}'", _def_loc(func))


def _def_loc(func) -> Loc | None:
    """The `def` line of a (decorated) function."""
    code = getattr(func, "__code__", None)
    if code is None:
        return None
    import linecache

    line = code.co_firstlineno
    for k in range(line, line + 50):
        text = linecache.getline(code.co_filename, k).lstrip()
        if text.startswith(("def ", "async def ")):
            return Loc(code.co_filename, k)
        if not text:
            break
    return Loc(code.co_filename, line)


def _make_param(k: int, name: str, ann, kernel_name: str):
    """A kernel parameter; the unannotated first parameter `cls` of a @classmethod kernel is, like `self`, the
    compile-time object (Taichi's docs: data_oriented_class.md)."""
    if k == 0 and name == "cls" and ann is inspect.Parameter.empty:
        return TemplateParam(name, ann, kernel_name)
    return make_param(name, ann, kernel_name, first=k == 0)


def kernel(func=None, **kw):
    if func is None:
        return lambda f: Kernel(f)
    return Kernel(func)
