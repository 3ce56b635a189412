"""The compile driver: one instantiation of a @ti.kernel, from its arguments to a CompiledKernel.

kernel cache key (frontend/fingerprint.py) -> on a hit, the cached object and launcher metadata; on a miss,
frontend (parameters bound to context slots, body lowered) -> passes (and the autodiff transform for .grad)
-> codegen -> object (runtime/jit.py, cached on disk) -> launcher (runtime/launch.py)."""

from __future__ import annotations

import inspect
import pickle
import threading
from typing import Any, Protocol

import numpy as np

from simgrad import dtypes as dt
from simgrad.autodiff.validate import in_place_targets
from simgrad.debug import debug_level
from simgrad.errors import SimgradTypeError, SimgradValueError, caller_loc
from simgrad.frontend.arrays import ArrayArg, BuilderArg
from simgrad.frontend.fingerprint import Guard, KeyBuilder, environment
from simgrad.frontend.lower import KernelLowering
from simgrad.frontend.refs import tensor_text
from simgrad.frontend.source import get_source
from simgrad.ir import context
from simgrad.ir.nodes import Kernel as IRKernel
from simgrad.ir.ops import Op
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix
from simgrad.lang.program import Program
from simgrad.lang.struct import StructType
from simgrad.lang.types import MatrixType, NdarrayType, is_sparse_matrix_builder, is_template
from simgrad.passes.manager import run_pipeline
from simgrad.runtime.launch import Launcher

# Compiling touches process-wide state (the frontend's context stack, statement ids, the program's trees);
# a second thread asking for the same instantiation waits and then finds it in the cache.
COMPILE_LOCK = threading.RLock()


class Param:
    """One kernel parameter as declared by its annotation."""

    def __init__(self, name: str, ann, kernel_name: str, first: bool = False):
        self.name = name
        self.ann = ann
        if first and name == "self" and ann is inspect.Parameter.empty:
            self.kind = "template"  # a kernel method of a @ti.data_oriented class: the object is compile-time
        elif is_template(ann):
            self.kind = "template"
        elif isinstance(ann, NdarrayType) or ann is NdarrayType or ann is np.ndarray:
            self.kind = "ndarray"
            self.ann = ann if isinstance(ann, NdarrayType) else NdarrayType()
        elif isinstance(ann, MatrixType):
            self.kind = "matrix"
        elif is_sparse_matrix_builder(ann):
            self.kind = "builder"  # a ti.linalg.SparseMatrixBuilder: its triplet arrays, by reference
        elif isinstance(ann, StructType):
            self.kind = "struct"  # passed as its leaves, one slot (or matrix of slots) each
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

    def ndarray_key(self, a, kernel_name: str) -> tuple:
        """What of an ndarray argument an instantiation depends on: dtype, dimensions, element shape."""
        if not hasattr(a, "dtype") or not hasattr(a, "shape"):
            raise SimgradTypeError(f"kernel {kernel_name}: argument '{self.name}' expects an ndarray, got "
                                   f"{type(a).__name__}")
        arr = getattr(a, "_ndarray", a)  # a ti.ndarray object: its numpy data
        return (str(arr.dtype), len(arr.shape), self.element_shape(a), self.with_grad(a, kernel_name))

    def builder_key(self, a, kernel_name: str) -> tuple:
        """What of a sparse matrix builder argument an instantiation depends on: its value type."""
        triplets = getattr(a, "_triplets", None)
        if triplets is None:
            raise SimgradTypeError(f"kernel {kernel_name}: argument '{self.name}' is annotated "
                                   "ti.types.sparse_matrix_builder() and expects a ti.linalg.SparseMatrixBuilder, "
                                   f"got {type(a).__name__}", caller_loc())
        return ("builder", triplets.dtype.name)

    def with_grad(self, a, kernel_name: str) -> bool:
        """Whether kernels see the gradient of ndarray argument `a`: the annotation's needs_grad, else whether
        it has one (a ti.ndarray with needs_grad=True, a torch tensor that requires grad)."""
        has = getattr(a, "grad", None) is not None if hasattr(a, "_ndarray") else \
            bool(getattr(a, "requires_grad", False))
        want = self.ann.needs_grad
        if want and not has:
            raise SimgradTypeError(f"kernel {kernel_name}: ndarray argument '{self.name}' is annotated "
                                   "needs_grad=True but has no gradient (create it with ti.ndarray(..., "
                                   "needs_grad=True), or pass a tensor that requires grad)")
        return has if want is None else bool(want)

    def element_shape(self, a) -> tuple:
        """The element shape of argument `a`: the annotation's, else a ti.ndarray object's own."""
        arr = getattr(a, "_ndarray", a)
        ann = self.ann
        if isinstance(ann.dtype, MatrixType) and (ann.dtype.n is None or ann.dtype.m is None):
            # ti.types.vector() / matrix(): the element shape is the argument's own, of that rank
            rank = 1 if ann.dtype.m == 0 else 2
            elem = tuple(getattr(a, "element_shape", ()) or ())
            if len(elem) != rank:
                raise SimgradValueError(f"Invalid value for argument {self.name}: a "
                                        f"{'vector' if rank == 1 else 'matrix'} ndarray is required, got "
                                        f"element shape {elem}")
            return elem
        if isinstance(ann.dtype, MatrixType):
            return ann.dtype.shape
        elem = ann.element_shape_of(tuple(arr.shape))
        if not elem and ann.dtype is None and not ann.element_dim:
            elem = getattr(a, "element_shape", ())
        return elem


class KernelSource(Protocol):
    """What the driver reads of a @ti.kernel (compiler/kernel.py Kernel)."""

    name: str
    func: Any
    signature: inspect.Signature
    params: list[Param]


class SlotParam:
    """A parameter as one instantiation lays it out in the context buffer."""

    def __init__(self, name, kind, slot=0, dtype=None, count=1, ndim=0, ndim_total=0, of=None, path=(),
                 grad_slot=-1):
        self.name, self.kind, self.slot, self.dtype = name, kind, slot, dtype
        self.grad_slot = grad_slot  # an ndarray's gradient base pointer, -1 when the kernel does not see one
        self.count, self.ndim, self.ndim_total = count, ndim, ndim_total
        # a leaf of struct parameter `of`: its value is `of.path[0].path[1]...`
        self.of, self.path = of, path


class CompiledKernel:
    """One compiled instantiation: its launcher (`launch(*args)` runs it), the return shape, and the IR and
    LLVM IR it was made from. Taken from the kernel cache, it has no IR: `ir` and `llvm_text` are rebuilt on
    first use (tests and Tape validation read them)."""

    def __init__(self, launcher: Launcher, ir: IRKernel | None, llvm_text: str | None,
                 ret_matrix: tuple[int, int] | StructType | None, rebuild=None, in_place: bool = False):
        self.launcher = launcher
        self.launch = launcher.launch
        self._ir = ir
        self._llvm_text = llvm_text
        self._rebuild = rebuild
        self.ret_matrix = ret_matrix
        self.in_place = in_place  # reads fields it overwrites (autodiff/validate.py in_place_targets)

    @property
    def ir(self) -> IRKernel:
        if self._ir is None:
            self._ir, self._llvm_text, _ = self._rebuild()
        return self._ir

    @property
    def llvm_text(self) -> str:
        if self._llvm_text is None:
            self._ir, self._llvm_text, _ = self._rebuild()
        return self._llvm_text



def compile_kernel(kernel: KernelSource, prog: Program, args: tuple, transform=None,
                   name_suffix: str = "") -> CompiledKernel:
    """Compile (or take from the kernel cache) the instantiation of `kernel` for `args`; `transform` (the
    adjoint for .grad) runs on the IR between the passes."""
    prog.materialize_all()
    key, guard = _cache_key(kernel, prog, args, transform, name_suffix)
    if key is not None:
        entry = _read_entry(prog, key)
        if entry is not None:
            meta, obj = entry
            launcher = _make_launcher(prog, meta, prog.link(obj, ["sg_kernel"]))
            light = tuple(np.empty((0,) * a.ndim, a.dtype) if isinstance(a, np.ndarray) else a for a in args)
            return CompiledKernel(launcher, None, None, meta["ret_matrix"],
                                  rebuild=lambda: _build(kernel, prog, light, transform, name_suffix),
                                  in_place=meta.get("in_place", False))
    ir, text, meta = _build(kernel, prog, args, transform, name_suffix, guard)
    obj = prog.jit.object_for(text)
    if key is not None and guard is not None and guard.reason is None:
        try:
            prog.jit.write_entry(key, pickle.dumps((meta, obj), protocol=pickle.HIGHEST_PROTOCOL))
        except (pickle.PicklingError, TypeError, AttributeError):
            pass  # metadata that does not pickle only costs us the cache
    launcher = _make_launcher(prog, meta, prog.link(obj, ["sg_kernel"]))
    return CompiledKernel(launcher, ir, text, meta["ret_matrix"], in_place=meta["in_place"])


def _cache_key(kernel: KernelSource, prog: Program, args, transform, name_suffix):
    """(key, guard) of the kernel cache for this instantiation, or (None, None) when it is not cached."""
    if not prog.jit.cache_enabled or debug_level() > 0:  # debug levels print what the compile does
        return None, None
    kb = KeyBuilder()
    config = tuple(sorted((k, repr(v)) for k, v in vars(prog.config).items()
                          if k not in ("offline_cache", "offline_cache_file_path")))
    step = None if transform is None else f"{transform.__module__}.{transform.__qualname__}"
    try:
        parts = (environment(), prog.jit.target_id(), config, dt.Defaults.fp.name, dt.Defaults.ip.name,
                 name_suffix, step, kb.function(kernel.func), kb.signature(kernel.signature),
                 tuple(_param_fingerprint(kernel, kb, p, a) for p, a in zip(kernel.params, args)))
    except Exception:  # Unkeyable, or e.g. a function without source: compiling reports it (or never needs it)
        return None, None
    return kb.digest(parts), Guard(kb.covered)


def _param_fingerprint(kernel: KernelSource, kb: KeyBuilder, p: Param, a):
    if p.kind == "template":
        return kb.value(a)
    if p.kind == "ndarray":
        return p.ndarray_key(a, kernel.name)  # dtype and ndim; the annotation is in the signature
    if p.kind == "builder":
        return p.builder_key(a, kernel.name)
    return None


def _build(kernel: KernelSource, prog: Program, args, transform, name_suffix, guard=None):
    """Frontend, passes and codegen: (IR, LLVM IR text, what the launcher needs)."""
    ir = IRKernel(kernel.name + name_suffix)
    comp = KernelLowering(ir, get_source(kernel.func), debug=prog.config.debug)
    comp.guard = guard
    trees = len(prog.trees)
    slots, ret_matrix = _bind_params(kernel, comp, args)
    prog.materialize_all()
    comp.compile_body()
    prog.materialize_all()
    if guard is not None and len(prog.trees) != trees:
        guard.taint("fields were created while compiling")
    ir.ret_slot = slots[1]
    run_pipeline(ir, transform, debug=prog.config.debug)
    symbol = f"sg_{kernel.name}{name_suffix}_{id(ir):x}"
    from simgrad.codegen.cpu import CpuCodegen  # the one target today; loaded when first needed

    cg = CpuCodegen(ir, symbol, debug=prog.config.debug, fast_math=prog.config.fast_math)
    text = cg.generate()
    # the disk cache is keyed by the IR text with the symbol name made stable
    stable = text.replace(symbol, "sg_kernel")
    uses_tape = ir.uses_tape
    meta = {"name": ir.name, "params": slots[0], "nslots": slots[1], "returns": list(ir.returns),
            "errors": cg.error_table, "ret_matrix": ret_matrix, "uses_tape": uses_tape,
            "private_slots": cg.private_slots,
            # the forward reads fields it overwrites: a Tape keeps their values from before each launch
            "in_place": transform is None and bool(in_place_targets(ir)),
            "tape_bound": ir.tape_bound if uses_tape else None}
    return ir, stable, meta


def _bind_params(kernel: KernelSource, comp: KernelLowering, args) -> tuple[tuple[list[SlotParam], int],
                                                                      tuple[int, int] | StructType | None]:
    """Each parameter becomes what the body sees (an ARG value, a Matrix of them, an ndarray view, the
    template value itself) and its place in the context buffer."""
    b = comp.builder
    slot = 0
    out = []
    context.push(comp)
    try:
        for p, a in zip(kernel.params, args):
            if p.kind == "template":
                comp.bind(p.name, a)
                out.append(SlotParam(p.name, "template"))
            elif p.kind == "scalar":
                t = dt.from_any(p.ann)
                if t is dt.u1:  # a ti.u1 (bool) argument travels as an i32, 0 or 1
                    t = dt.i32
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
            elif p.kind == "struct":
                out.append(SlotParam(p.name, "struct"))
                leaves: list = []
                for path, lt in p.ann.leaves():
                    leaf = f"{p.name}__{'__'.join(path)}"
                    if isinstance(lt, MatrixType):
                        entries = [Expr(b.emit(Op.ARG, lt.dtype, (), {"slot": slot + k}))
                                   for k in range(lt.num_entries)]
                        leaves.append(Matrix(n=lt.n, m=lt.m, _entries=entries))
                        out.append(SlotParam(leaf, "matrix", slot, lt.dtype, count=lt.num_entries, of=p.name,
                                             path=path))
                        slot += lt.num_entries
                    else:
                        leaves.append(Expr(b.emit(Op.ARG, lt, (), {"slot": slot})))
                        out.append(SlotParam(leaf, "scalar", slot, lt, of=p.name, path=path))
                        slot += 1
                comp.bind(p.name, p.ann.from_leaves(leaves))
            elif p.kind == "builder":
                barg = BuilderArg(p.name, slot, a._triplets.dtype)
                comp.bind(p.name, barg)
                out.append(SlotParam(p.name, "builder", slot, barg.dtype))
                slot += barg.num_slots
            else:
                arg = _array_arg(kernel.name, p, a, slot)
                comp.bind(p.name, arg)
                out.append(SlotParam(p.name, "ndarray", slot, arg.dtype, ndim=arg.ndim,
                                     ndim_total=arg.ndim + len(arg.element_shape), grad_slot=arg.grad_slot))
                slot += arg.num_slots
        ret = kernel.signature.return_annotation
        ret_matrix: tuple[int, int] | StructType | None = None
        if ret is not inspect.Signature.empty and ret is not None:
            if isinstance(ret, MatrixType):
                comp.return_types = [ret.dtype] * ret.num_entries
                ret_matrix = (ret.n, ret.m)
            elif isinstance(ret, StructType):
                comp.return_types = [x for _, lt in ret.leaves() for x in
                                     ([lt.dtype] * lt.num_entries if isinstance(lt, MatrixType) else [lt])]
                ret_matrix = ret  # the launcher rebuilds the struct from the returned leaves
            elif isinstance(ret, (tuple, list)):
                comp.return_types = [dt.from_any(r) for r in ret]
            else:
                comp.return_types = [dt.from_any(ret)]
            comp.ir.returns = comp.return_types
    finally:
        context.pop()
    return (out, slot), ret_matrix


def _array_arg(kernel_name: str, p: Param, a, slot: int) -> ArrayArg:
    """The compiler's view of an ndarray argument, its dtype, dimensions and element shape checked (Taichi's
    messages: "Invalid value for argument a - required ...", "Expect element type ... but get ...")."""
    ann: NdarrayType = p.ann
    arr = getattr(a, "_ndarray", a) if hasattr(a, "dtype") else np.asarray(a)
    t = dt.from_numpy(arr.dtype) if isinstance(arr, np.ndarray) else _torch_dtype(arr)
    want: dt.DataType | None
    elem = p.element_shape(a)
    own = tuple(getattr(a, "element_shape", ()) or ()) if hasattr(a, "_ndarray") else None
    if isinstance(ann.dtype, MatrixType):
        want = ann.dtype.dtype if ann.dtype._dtype is not None or ann.dtype.n is not None else None
    else:
        want = dt.from_any(ann.dtype) if ann.dtype is not None else None
    if want is not None and not isinstance(ann.dtype, MatrixType) and own:
        raise SimgradTypeError(f"kernel {kernel_name}: Expect element type {want} for argument {p.name}, but get "
                               f"{tensor_text(own, t)}")
    if (own is not None and own != elem) or len(elem) > len(arr.shape) \
            or tuple(arr.shape[len(arr.shape) - len(elem):]) != elem:
        # never reinterpret the memory: a (2, 3) matrix element is not a 2-vector followed by more
        given = tensor_text(own, t) if own is not None else f"an array of shape {tuple(arr.shape)}"
        raise SimgradValueError(f"kernel {kernel_name}: Invalid value for argument {p.name} - required element "
                                f"type: {_element_type_text(ann, elem, want or t)}, but {given} is provided")
    if want is not None and want is not t:
        raise SimgradTypeError(f"kernel {kernel_name}: Expect element type {want} for argument {p.name}, but get "
                               f"{tensor_text(own if own is not None else elem, t)}")
    ndim = len(arr.shape) - len(elem)
    if ann.ndim is not None and ann.ndim != ndim:
        raise SimgradValueError(f"kernel {kernel_name}: Invalid value for argument {p.name} - required "
                                f"ndim={ann.ndim}, but {ndim}d ndarray with shape {tuple(arr.shape)} is provided")
    return ArrayArg(p.name, slot, t, ndim, elem, ann.boundary, grad=t.is_float and p.with_grad(a, kernel_name))


def _element_type_text(ann: NdarrayType, elem: tuple, want) -> str:
    """The annotation's element type as Taichi names it: VectorType[2, i32], MatrixType[2,2, f32], f32."""
    mt = ann.dtype
    if isinstance(mt, MatrixType) and mt.n is not None:
        return f"VectorType[{mt.n}, {want}]" if mt.m == 0 else f"MatrixType[{mt.n},{mt.m}, {want}]"
    return tensor_text(elem, want)


def _make_launcher(prog: Program, meta: dict, entries: dict) -> Launcher:
    """The launcher of one instantiation, from the metadata its compilation recorded (or the cache kept)."""
    launcher = Launcher(meta["name"], meta["params"], entries["sg_kernel"], meta["nslots"], meta["returns"],
                        meta["errors"], prog, meta["ret_matrix"], meta.get("private_slots", 0))
    if meta["uses_tape"]:
        # the size proven by the bounds when they are static, else ti.init(ad_stack_size=...)
        bound = meta["tape_bound"]
        launcher.attach_tape(max(bound, 1) if bound is not None else prog.tape_capacity)
    ret_matrix = meta["ret_matrix"]
    if isinstance(ret_matrix, StructType):
        stype, inner = ret_matrix, launcher.launch

        def launch_struct(*a):
            vals = iter(inner(*a))
            leaves = [_take_leaf(lt, vals) for _, lt in stype.leaves()]
            return stype.from_leaves(leaves)

        launcher.launch = launch_struct
        return launcher
    if ret_matrix is not None:
        inner = launcher.launch
        n, m = ret_matrix

        def launch(*a):
            vals = inner(*a)
            return Matrix(list(vals)) if m == 0 else Matrix([list(vals[r * m:(r + 1) * m]) for r in range(n)])

        launcher.launch = launch
    return launcher


def _take_leaf(t, vals):
    if not isinstance(t, MatrixType):
        return next(vals)
    flat = [next(vals) for _ in range(t.num_entries)]
    return Matrix(flat) if t.m == 0 else Matrix([flat[r * t.m:(r + 1) * t.m] for r in range(t.n)])


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


