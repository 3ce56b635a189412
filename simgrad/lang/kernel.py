"""@ti.kernel and @ti.func: parameter handling, instantiation per template arguments, compilation, launch."""

from __future__ import annotations

import inspect
import pickle
import threading
import time

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError, caller_loc
from simgrad.frontend.source import get_source
from simgrad.ir import context
from simgrad.ir.nodes import Kernel as IRKernel
from simgrad.ir.ops import Op
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix
from simgrad.lang.program import Program, get_program
from simgrad.lang.types import MatrixType, NdarrayType, is_template

# Compiling touches process-wide state (the frontend's context stack, statement ids, the program's trees);
# a second thread asking for the same instantiation waits and then finds it in the cache.
COMPILE_LOCK = threading.RLock()


class Param:
    """One kernel parameter as declared by its annotation."""

    def __init__(self, name: str, ann, kernel_name: str):
        self.name = name
        self.ann = ann
        if is_template(ann):
            self.kind = "template"
        elif isinstance(ann, NdarrayType) or ann is NdarrayType or ann is np.ndarray:
            self.kind = "ndarray"
            self.ann = ann if isinstance(ann, NdarrayType) else NdarrayType()
        elif isinstance(ann, MatrixType):
            self.kind = "matrix"
        elif ann is inspect.Parameter.empty:
            raise SimgradTypeError(f"kernel {kernel_name}: parameter '{name}' needs a type annotation "
                                   "(e.g. ti.f32, ti.template(), ti.types.ndarray())")
        else:
            try:
                dt.from_any(ann)
            except TypeError:
                raise SimgradTypeError(f"kernel {kernel_name}: parameter '{name}' has an unsupported "
                                       f"annotation {ann!r}") from None
            self.kind = "scalar"


class SlotParam:
    """A parameter as one instantiation lays it out in the context buffer."""

    def __init__(self, name, kind, slot=0, dtype=None, count=1, ndim=0, ndim_total=0):
        self.name, self.kind, self.slot, self.dtype = name, kind, slot, dtype
        self.count, self.ndim, self.ndim_total = count, ndim, ndim_total


def _template_key(v, keep: list):
    if isinstance(v, (int, float, bool, str, type(None))):
        return (type(v), v)
    if isinstance(v, (tuple, list)):
        return (type(v), tuple(_template_key(x, keep) for x in v))
    if isinstance(v, np.ndarray) and v.size <= 16:
        return ("nd", v.dtype.str, v.shape, v.tobytes())
    keep.append(v)
    return ("id", id(v))


class Instance:
    """One compiled instantiation. Taken from the kernel cache, it has no IR: `ir` and `llvm_text` are
    rebuilt on first use (tests and Tape validation read them)."""

    def __init__(self, launcher, ir, llvm_text, ret_matrix, rebuild=None):
        self.launcher = launcher
        self.launch = launcher.launch
        self._ir = ir
        self._llvm_text = llvm_text
        self._rebuild = rebuild
        self.ret_matrix = ret_matrix

    @property
    def ir(self):
        if self._ir is None:
            self._ir, self._llvm_text, _ = self._rebuild()
        return self._ir

    @property
    def llvm_text(self) -> str:
        if self._llvm_text is None:
            self._ir, self._llvm_text, _ = self._rebuild()
        return self._llvm_text


class Kernel:
    def __init__(self, func) -> None:
        self.func = func
        self.name = func.__name__
        self.__name__, self.__qualname__, self.__module__ = func.__name__, func.__qualname__, func.__module__
        self.signature = inspect.signature(func)
        self.signature = _resolved_signature(func)
        self.params = [Param(n, p.annotation, self.name) for n, p in self.signature.parameters.items()]
        self._nparams = len(self.params)
        self._simple = all(p.kind in ("scalar", "matrix") for p in self.params)
        self._has_defaults = any(p.default is not inspect.Parameter.empty
                                 for p in self.signature.parameters.values())
        self._instances: dict = {}
        self._keep: list = []
        self._generation = -1
        self._simple_launch = None
        self._grad_instances: dict = {}
        self.grad = GradKernel(self)
        self.__doc__ = func.__doc__
        self.__wrapped__ = func

    def __call__(self, *args, **kwargs):
        if kwargs or (self._has_defaults and len(args) != self._nparams):
            args = self._bind(args, kwargs)
        from simgrad.lang import ad_hooks

        if ad_hooks.recorder is not None:
            ad_hooks.recorder(self, args)
        prog = get_program()
        if self._generation != prog.generation:
            self._reset(prog)
        launch = self._simple_launch
        if launch is None or len(args) != self._nparams:
            launch = self._launch_for(args)
        if prog.config.kernel_profiler:
            t0 = time.perf_counter()
            out = launch(*args)
            prog.profiler.add(self.name, time.perf_counter() - t0)
            return out
        return launch(*args)

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
        self._instances.clear()
        self._grad_instances.clear()
        self._keep.clear()
        self._simple_launch = None
        self._generation = prog.generation

    def _launch_for(self, args, grad: bool = False):
        return self._instance_for(args, grad).launch

    def instance(self, args) -> Instance:
        """The (compiled) forward instance these arguments launch."""
        return self._instance_for(args, grad=False)

    def _instance_for(self, args, grad: bool) -> Instance:
        if len(args) != self._nparams:
            names = ", ".join(p.name for p in self.params)
            raise SimgradTypeError(f"kernel {self.name} takes {self._nparams} argument(s) ({names}), "
                                   f"got {len(args)}")
        keep: list = []
        key = tuple(self._key_part(p, a, keep) for p, a in zip(self.params, args))
        cache = self._grad_instances if grad else self._instances
        inst = cache.get(key)
        if inst is None:
            with COMPILE_LOCK:  # the frontend and passes share state: one compile at a time
                inst = cache.get(key)
                if inst is None:
                    inst = self._compile_instance(args, grad, key, keep, cache)
        return inst

    def _compile_instance(self, args, grad: bool, key, keep: list, cache: dict) -> Instance:
        t0 = time.perf_counter()
        try:
            return self._compile_uncounted(args, grad, key, keep, cache)
        finally:
            get_program().compile_seconds += time.perf_counter() - t0

    def _compile_uncounted(self, args, grad: bool, key, keep: list, cache: dict) -> Instance:
        if grad:
            from simgrad.autodiff.validate import check_and_adjoint

            inst = self.instantiate(args, transform=check_and_adjoint, name_suffix="_grad")
        else:
            inst = self.instantiate(args)
            if self._simple:
                self._simple_launch = inst.launch
        cache[key] = inst
        self._keep.extend(keep)
        return inst

    def _key_part(self, p: Param, a, keep):
        if p.kind == "template":
            return _template_key(a, keep)
        if p.kind == "ndarray":
            if not hasattr(a, "dtype") or not hasattr(a, "shape"):
                raise SimgradTypeError(f"kernel {self.name}: argument '{p.name}' expects an ndarray, got "
                                       f"{type(a).__name__}")
            return (str(a.dtype), len(a.shape), p.ann.element_shape_of(tuple(a.shape)))
        return None

    # -- compilation -------------------------------------------------------------------------------
    def instantiate(self, args, transform=None, name_suffix=""):
        """Compile (or take from the kernel cache) the instantiation for `args` and build its launcher."""
        prog = get_program()
        prog.materialize_all()
        key, guard = self._cache_key(prog, args, transform, name_suffix)
        if key is not None:
            entry = _read_entry(prog, key)
            if entry is not None:
                meta, obj = entry
                launcher = _make_launcher(prog, meta, prog.link(obj, ["sg_kernel"]))
                light = tuple(np.empty((0,) * a.ndim, a.dtype) if isinstance(a, np.ndarray) else a for a in args)
                return Instance(launcher, None, None, meta["ret_matrix"],
                                rebuild=lambda: self._build(prog, light, transform, name_suffix))
        ir, text, meta = self._build(prog, args, transform, name_suffix, guard)
        obj = prog.jit.object_for(text)
        if key is not None and guard.reason is None:
            try:
                prog.jit.write_entry(key, pickle.dumps((meta, obj), protocol=pickle.HIGHEST_PROTOCOL))
            except (pickle.PicklingError, TypeError, AttributeError):
                pass  # metadata that does not pickle only costs us the cache
        launcher = _make_launcher(prog, meta, prog.link(obj, ["sg_kernel"]))
        return Instance(launcher, ir, text, meta["ret_matrix"])

    def _cache_key(self, prog: Program, args, transform, name_suffix):
        """(key, guard) of the kernel cache for this instantiation, or (None, None) when it is not cached."""
        from simgrad.debug import debug_level
        from simgrad.frontend.fingerprint import Guard, KeyBuilder, environment

        if not prog.jit.cache_enabled or debug_level() > 0:  # debug levels print what the compile does
            return None, None
        kb = KeyBuilder()
        config = tuple(sorted((k, repr(v)) for k, v in vars(prog.config).items()
                              if k not in ("offline_cache", "offline_cache_file_path")))
        step = None if transform is None else f"{transform.__module__}.{transform.__qualname__}"
        try:
            parts = (environment(), prog.jit.target_id(), config, dt.Defaults.fp.name, dt.Defaults.ip.name,
                     name_suffix, step, kb.function(self.func), kb.signature(self.signature),
                     tuple(self._param_fingerprint(kb, p, a) for p, a in zip(self.params, args)))
        except Exception:  # Unkeyable, or e.g. a function without source: compiling reports it (or never needs it)
            return None, None
        return kb.digest(parts), Guard(kb.covered)

    def _param_fingerprint(self, kb, p: Param, a):
        if p.kind == "template":
            return kb.value(a)
        if p.kind == "ndarray":
            return self._key_part(p, a, [])  # dtype and ndim; the annotation is in the signature
        return None

    def _build(self, prog: Program, args, transform, name_suffix, guard=None):
        """Frontend, passes and codegen: (IR, LLVM IR text, what the launcher needs)."""
        from simgrad.codegen.cpu import CpuCodegen
        from simgrad.frontend.lower import Compiler
        from simgrad.passes.manager import run_pipeline

        ir = IRKernel(self.name + name_suffix)
        comp = Compiler(ir, get_source(self.func), debug=prog.config.debug)
        comp.guard = guard
        trees = len(prog.trees)
        slots, ret_matrix = self._bind_params(comp, args)
        prog.materialize_all()
        comp.compile_body()
        prog.materialize_all()
        if guard is not None and len(prog.trees) != trees:
            guard.taint("fields were created while compiling")
        ir.ret_slot = slots[1]
        run_pipeline(ir, transform, debug=prog.config.debug)
        symbol = f"sg_{self.name}{name_suffix}_{id(ir):x}"
        cg = CpuCodegen(ir, symbol, debug=prog.config.debug, fast_math=prog.config.fast_math)
        text = cg.generate()
        # the disk cache is keyed by the IR text with the symbol name made stable
        stable = text.replace(symbol, "sg_kernel")
        uses_tape = getattr(ir, "uses_tape", False)
        meta = {"name": ir.name, "params": slots[0], "nslots": slots[1], "returns": list(ir.returns),
                "errors": cg.error_table, "ret_matrix": ret_matrix, "uses_tape": uses_tape,
                "tape_bound": getattr(ir, "tape_bound", None) if uses_tape else None}
        return ir, stable, meta

    def _bind_params(self, comp, args) -> tuple[tuple[list[SlotParam], int], tuple[int, int] | None]:
        from simgrad.lang.ndarray import ArrayArg

        b = comp.builder
        slot = 0
        out = []
        context.push(comp)
        try:
            for p, a in zip(self.params, args):
                if p.kind == "template":
                    comp.bind(p.name, a)
                    out.append(SlotParam(p.name, "template"))
                elif p.kind == "scalar":
                    t = dt.from_any(p.ann)
                    comp.bind(p.name, Expr(b.emit(Op.ARG, t, (), {"slot": slot})))
                    out.append(SlotParam(p.name, "scalar", slot, t))
                    slot += 1
                elif p.kind == "matrix":
                    mt: MatrixType = p.ann
                    t = mt.dtype
                    entries = [Expr(b.emit(Op.ARG, t, (), {"slot": slot + k})) for k in range(mt.num_entries)]
                    comp.bind(p.name, Matrix(n=mt.n, m=mt.m, _entries=entries))
                    out.append(SlotParam(p.name, "matrix", slot, t, count=mt.num_entries))
                    slot += mt.num_entries
                else:
                    ann: NdarrayType = p.ann
                    arr = a if hasattr(a, "dtype") else np.asarray(a)
                    t = dt.from_numpy(arr.dtype) if isinstance(arr, np.ndarray) else _torch_dtype(arr)
                    elem = ()
                    want: dt.DataType | None
                    if isinstance(ann.dtype, MatrixType):
                        elem = ann.dtype.shape
                        want = ann.dtype.dtype
                    else:
                        want = dt.from_any(ann.dtype) if ann.dtype is not None else None
                        elem = ann.element_shape_of(tuple(arr.shape))
                        if len(elem) > len(arr.shape) or tuple(arr.shape[len(arr.shape) - len(elem):]) != elem:
                            raise SimgradTypeError(f"kernel {self.name}: ndarray argument '{p.name}' of shape "
                                                   f"{tuple(arr.shape)} has no trailing element shape {elem}")
                    if want is not None and want is not t:
                        raise SimgradTypeError(f"kernel {self.name}: ndarray argument '{p.name}' must have "
                                               f"dtype {want}, got {t}")
                    total = len(arr.shape)
                    ndim = total - len(elem)
                    if ann.ndim is not None and ann.ndim != ndim:
                        raise SimgradTypeError(f"kernel {self.name}: ndarray argument '{p.name}' must have "
                                               f"{ann.ndim} dimension(s), got {ndim}")
                    arg = ArrayArg(p.name, slot, t, ndim, elem)
                    comp.bind(p.name, arg)
                    out.append(SlotParam(p.name, "ndarray", slot, t, ndim=ndim, ndim_total=total))
                    slot += arg.num_slots
            ret = self.signature.return_annotation
            ret_matrix = None
            if ret is not inspect.Signature.empty and ret is not None:
                if isinstance(ret, MatrixType):
                    comp.return_types = [ret.dtype] * ret.num_entries
                    ret_matrix = (ret.n, ret.m)
                elif isinstance(ret, (tuple, list)):
                    comp.return_types = [dt.from_any(r) for r in ret]
                else:
                    comp.return_types = [dt.from_any(ret)]
                comp.ir.returns = comp.return_types
        finally:
            context.pop()
        return (out, slot), ret_matrix


def _make_launcher(prog: Program, meta: dict, entries: dict):
    """The launcher of one instantiation, from the metadata its compilation recorded (or the cache kept)."""
    from simgrad.runtime.launch import Launcher

    launcher = Launcher(meta["name"], meta["params"], entries["sg_kernel"], meta["nslots"], meta["returns"],
                        meta["errors"], prog, meta["ret_matrix"])
    if meta["uses_tape"]:
        # the size proven by the bounds when they are static, else ti.init(ad_stack_size=...)
        bound = meta["tape_bound"]
        launcher.attach_tape(max(bound, 1) if bound is not None else prog.tape_capacity)
    ret_matrix = meta["ret_matrix"]
    if ret_matrix is not None:
        inner = launcher.launch
        n, m = ret_matrix

        def launch(*a):
            vals = inner(*a)
            return Matrix(list(vals)) if m == 0 else Matrix([list(vals[r * m:(r + 1) * m]) for r in range(n)])

        launcher.launch = launch
    return launcher


def _read_entry(prog: Program, key: str):
    """(metadata, object) stored under `key`, or None (absent or unreadable: then it is compiled again)."""
    data = prog.jit.read_entry(key)
    if data is None:
        return None
    try:
        return pickle.loads(data)
    except Exception:  # a truncated or foreign file is a miss, never an error
        return None


def _torch_dtype(t):
    import torch

    m = {torch.float32: dt.f32, torch.float64: dt.f64, torch.int32: dt.i32, torch.int64: dt.i64,
         torch.int8: dt.i8, torch.int16: dt.i16, torch.uint8: dt.u8, torch.float16: dt.f16}
    return m[t.dtype]


class GradKernel:
    """`kernel.grad(*args)`: launches the adjoint of the kernel (built once per instantiation)."""

    def __init__(self, kernel: Kernel):
        self.kernel = kernel
        self.name = kernel.name + ".grad"

    def __call__(self, *args, **kwargs):
        k = self.kernel
        if kwargs or (k._has_defaults and len(args) != k._nparams):
            args = k._bind(args, kwargs)
        prog = get_program()
        if k._generation != prog.generation:
            k._reset(prog)
        launch = k._launch_for(args, grad=True)
        if prog.config.kernel_profiler:
            t0 = time.perf_counter()
            launch(*args)
            prog.profiler.add(self.name, time.perf_counter() - t0)
            return None
        launch(*args)
        return None


def _resolved_signature(func) -> inspect.Signature:
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
                raise SimgradTypeError(f"{func.__name__}: cannot evaluate annotation {a!r}: {e}") from None
        return a

    params = [p.replace(annotation=ev(p.annotation)) for p in sig.parameters.values()]
    return sig.replace(parameters=params, return_annotation=ev(sig.return_annotation))


class Func:
    """@ti.func: inlined into the kernels that call it."""

    def __init__(self, func):
        self.func = func
        self.name = func.__name__
        self.signature = _resolved_signature(func)
        self.__wrapped__ = func
        self.__doc__ = func.__doc__

    def __call__(self, *args, **kwargs):
        comp = context.current()
        if comp is None:
            raise SimgradTypeError(f"ti.func {self.name} can only be called from a kernel or another ti.func")
        from simgrad.frontend.calls import inline

        return inline(comp, self, list(args), kwargs, comp.frame.src.tree)


def kernel(func=None, **kw):
    if func is None:
        return lambda f: Kernel(f)
    return Kernel(func)


def func(fn=None, **kw):
    if fn is None:
        return lambda f: Func(f)
    return Func(fn)


def pyfunc(fn):
    return Func(fn)


def unexpected_keywords(sig: inspect.Signature, kwargs) -> str:
    """Python's bind reports a missing parameter before an unknown keyword (`k(b=1)` for `k(a)` says
    "missing 'a'"); the unknown keyword is the real mistake, so it is reported first."""
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values()):
        return ""
    names = [p.name for p in sig.parameters.values() if p.kind is not inspect.Parameter.POSITIONAL_ONLY]
    bad = [k for k in kwargs if k not in names]
    if not bad:
        return ""
    return (f"got an unexpected keyword argument '{bad[0]}' (its parameters are: "
            f"{', '.join(sig.parameters)})")
