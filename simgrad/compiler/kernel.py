"""@ti.kernel: the object a decorated function becomes. It binds arguments, picks or compiles the
instantiation they need (compiler/driver.py) and launches it; Tape recording goes through lang/ad_hooks."""

from __future__ import annotations

import inspect
import time

from simgrad.autodiff.forward import adjoint_then_forward, make_forward
from simgrad.autodiff.validate import check_and_adjoint, check_in_place_and_adjoint
from simgrad.compiler.driver import COMPILE_LOCK, CompiledKernel, compile_kernel
from simgrad.compiler.params import make_param
from simgrad.errors import Loc, SimgradSyntaxError, SimgradTypeError, caller_loc
from simgrad.lang import ad_hooks
from simgrad.lang.argpack import ArgPackType
from simgrad.lang.functions import KernelDef, resolved_signature, unexpected_keywords
from simgrad.lang.program import Program, get_program

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
        self.params = [make_param(n, p.annotation, self.name, first=k == 0)
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
        if prog.config.kernel_profiler:
            t0 = time.perf_counter()
            out = launch(*args)
            prog.profiler.add(self.name, time.perf_counter() - t0)
            return out
        return launch(*args)

    def __get__(self, obj, owner=None):
        """`obj.step()` for a kernel method: the kernel with the object as its first (template) argument."""
        return self if obj is None else BoundKernel(self, obj)

    def _bind(self, args, kwargs):
        unknown = unexpected_keywords(self.signature, kwargs)
        if unknown:
            raise SimgradTypeError(f"kernel {self.name}: {unknown}", caller_loc())
        try:
            b = self.signature.bind(*args, **kwargs)
        except TypeError as e:
            raise SimgradTypeError(f"kernel {self.name}: {e}") from None
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
            names = ", ".join(p.name for p in self.params)
            raise SimgradTypeError(f"kernel {self.name} takes {self._nparams} argument(s) ({names}), "
                                   f"got {len(args)}")
        keep: list = []
        key = tuple([p.key(args[k], keep) for k, p in self._keyed])
        cache = self._caches[mode]
        inst = cache.get(key)
        if inst is None:
            with COMPILE_LOCK:  # the frontend and passes share state: one compile at a time
                inst = cache.get(key)
                if inst is None:
                    inst = self._compile_instance(args, mode, key, keep, cache)
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
        if prog.config.kernel_profiler:
            t0 = time.perf_counter()
            launch(*args)
            prog.profiler.add(self.name, time.perf_counter() - t0)
            return None
        launch(*args)
        return None


class BoundKernel:
    """A kernel method of an object; `.grad` is the bound adjoint."""

    def __init__(self, kernel: Kernel, obj):
        self.kernel, self.obj = kernel, obj
        self.name = kernel.name
        self.__name__ = kernel.__name__
        self.grad = _BoundGrad(kernel.grad, obj)

    def __call__(self, *args, **kwargs):
        return self.kernel(self.obj, *args, **kwargs)


class _BoundGrad:
    def __init__(self, grad: GradKernel, obj):
        self.grad, self.obj = grad, obj

    def __call__(self, *args, **kwargs):
        return self.grad(self.obj, *args, **kwargs)

    def in_place(self, *args) -> None:
        self.grad.in_place(self.obj, *args)


def kernel(func=None, **kw):
    if func is None:
        return lambda f: Kernel(f)
    return Kernel(func)
