"""The compile driver: one instantiation of a @ti.kernel, from its arguments to a CompiledKernel.

kernel cache key (frontend/fingerprint.py) -> on a hit, the cached object and launcher metadata; on a miss,
frontend (parameters bound to context slots, body lowered) -> passes (and the autodiff transform for .grad)
-> codegen -> object (runtime/jit.py, cached on disk) -> launcher (runtime/launch.py)."""

from __future__ import annotations

import inspect
import os
import pickle
import threading
import typing
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from simgrad import dtypes as dt
from simgrad.autodiff.validate import in_place_targets
from simgrad.compiler.params import Param, Slots
from simgrad.debug import debug_level
from simgrad.frontend.fingerprint import Guard, KeyBuilder, environment
from simgrad.frontend.lower import KernelLowering
from simgrad.frontend.source import get_source
from simgrad.ir import context, numeric
from simgrad.ir.nodes import Kernel as IRKernel
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.lang.matrix import Matrix
from simgrad.lang.program import Program
from simgrad.lang.struct import StructType
from simgrad.lang.types import MatrixType
from simgrad.passes.manager import run_pipeline
from simgrad.runtime import fpenv
from simgrad.runtime.args import Packing
from simgrad.runtime.launch import Launcher

if TYPE_CHECKING:
    from simgrad.codegen.llvm import KernelCodegen

# Compiling touches process-wide state (the frontend's context stack, statement ids, the program's trees);
# a second thread asking for the same instantiation waits and then finds it in the cache.
COMPILE_LOCK = threading.RLock()


class KernelSource(Protocol):
    """What the driver reads of a @ti.kernel (compiler/kernel.py Kernel)."""

    name: str
    func: Any
    signature: inspect.Signature
    params: list[Param]


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
            launcher = _make_launcher(prog, meta, obj)
            light = tuple(np.empty((0,) * a.ndim, a.dtype) if isinstance(a, np.ndarray) else a for a in args)
            return CompiledKernel(launcher, None, None, meta["ret_matrix"],
                                  rebuild=lambda: _build(kernel, prog, light, transform, name_suffix),
                                  in_place=meta.get("in_place", False))
    ir, text, meta = _build(kernel, prog, args, transform, name_suffix, guard)
    obj = _object(prog, text, meta)
    if key is not None and guard is not None and guard.reason is None:
        try:
            prog.jit.write_entry(key, pickle.dumps((meta, obj), protocol=pickle.HIGHEST_PROTOCOL))
        except (pickle.PicklingError, TypeError, AttributeError):
            pass  # metadata that does not pickle only costs us the cache
    launcher = _make_launcher(prog, meta, obj)
    return CompiledKernel(launcher, ir, text, meta["ret_matrix"], in_place=meta["in_place"])




def _object(prog: Program, text: str, meta: dict) -> bytes:
    """What the kernel runs as: native code (the CPU, the simulated GPU) or PTX for the device's compute
    capability."""
    if not prog.on_gpu or prog.gpu_sim:
        return prog.jit.object_for(text)
    from simgrad.codegen import nvptx

    major, minor = prog.device.compute_capability
    return nvptx.compile_ptx(text, {s for s, _, _ in meta["launches"]}, f"sm_{major}{minor}").encode()


def _target_id(prog: Program) -> tuple:
    """What compiled code depends on besides the kernel: the host target, and the GPU's compute capability."""
    if prog.on_gpu and not prog.gpu_sim:
        return (*prog.jit.target_id(), "cuda", prog.device.compute_capability)
    return prog.jit.target_id()


def ptx_check_enabled() -> bool:
    return os.environ.get("SIMGRAD_PTX_CHECK", "") not in ("", "0")


def _ptx_check(ir: IRKernel, symbol: str, tape_entries: int, prog: Program) -> None:
    """SIMGRAD_PTX_CHECK=1: lower the kernel to PTX and assemble it with ptxas (sm_80, sm_90); an error raises."""
    from simgrad.codegen import nvptx

    ptx, _ = nvptx.kernel_ptx(ir, symbol, tape_entries=tape_entries, debug=prog.config.debug,
                              fast_math=prog.config.fast_math, flush=prog.config.flush_denormals)
    nvptx.ptxas_check(ptx)


def _cache_key(kernel: KernelSource, prog: Program, args, transform, name_suffix):
    """(key, guard) of the kernel cache for this instantiation, or (None, None) when it is not cached."""
    # debug levels print what the compile does; SIMGRAD_PTX_CHECK checks every kernel as it compiles
    if not prog.jit.cache_enabled or debug_level() > 0 or ptx_check_enabled():
        return None, None
    kb = KeyBuilder()
    config = tuple(sorted((k, repr(v)) for k, v in vars(prog.config).items()
                          if k not in ("offline_cache", "offline_cache_file_path")))
    step = None if transform is None else f"{transform.__module__}.{transform.__qualname__}"
    try:
        parts = (environment(), _target_id(prog), config, dt.Defaults.fp.name, dt.Defaults.ip.name,
                 name_suffix, step, kb.function(kernel.func), kb.signature(kernel.signature),
                 tuple(p.fingerprint(a, kb) for p, a in zip(kernel.params, args)))
    except Exception:  # Unkeyable, or e.g. a function without source: compiling reports it (or never needs it)
        return None, None
    return kb.digest(parts), Guard(kb.covered)


def flush_bits(prog: Program) -> frozenset[int]:
    """The float widths whose subnormal results the program's kernels flush to zero (runtime/fpenv.py): f32 and
    f64 on an x86-64 host (the simulated GPU too), f32 on a GPU (PTX has no .ftz for f64), none when the host
    cannot switch or ti.init(flush_denormals=False)."""
    if not prog.config.flush_denormals:
        return frozenset()
    if prog.on_gpu and not prog.gpu_sim:
        return frozenset({32})
    return frozenset({32, 64}) if fpenv.switchable() else frozenset()


def _build(kernel: KernelSource, prog: Program, args, transform, name_suffix, guard=None):
    """Frontend, passes and codegen: (IR, LLVM IR text, what the launcher needs), folding as the machine
    computes in the program's flush-to-zero mode."""
    bits = flush_bits(prog)
    with numeric.flushing(bits):
        return _build_in_mode(kernel, prog, args, transform, name_suffix, guard, flush=bool(bits))


def _build_in_mode(kernel: KernelSource, prog: Program, args, transform, name_suffix, guard, flush: bool):
    ir = IRKernel(kernel.name + name_suffix)
    comp = KernelLowering(ir, get_source(kernel.func), debug=prog.config.debug, parallel_listgen=prog.on_gpu)
    comp.guard = guard
    trees = len(prog.trees)
    slots, ret_matrix = _bind_params(kernel, comp, args)
    prog.materialize_all()
    comp.compile_body()
    prog.materialize_all()
    if guard is not None and len(prog.trees) != trees:
        guard.taint("fields were created while compiling")
    ir.ret_slot = slots[1]
    # SIMT lanes (passes/lanes.py): the CPU's forward kernels only (a GPU is SIMT already; adjoints keep theirs)
    lanes = prog.config.simt_lanes if transform is None and not prog.on_gpu and not prog.config.debug else 0
    # loop fission of scatters (passes/fission.py): the CPU's kernels, adjoints too
    fission = prog.config.fission_lanes if not prog.on_gpu and not prog.config.debug else 0
    run_pipeline(ir, transform, debug=prog.config.debug, fast_math=prog.config.fast_math,
                 cache_sums=bool(getattr(prog.config, "cache_loop_invariant_global_vars", True)), lanes=lanes,
                 vector_bits=prog.jit.vector_bits() if lanes < 0 or fission < 0 else 0, fission=fission,
                 versions=not prog.on_gpu and not prog.config.debug)
    symbol = f"sg_{kernel.name}{name_suffix}_{id(ir):x}"
    tape_entries = (max(ir.tape_bound, 1) if ir.tape_bound is not None else prog.tape_capacity) if ir.uses_tape \
        else 1
    cg: KernelCodegen
    if prog.on_gpu:  # arch=cuda: the GPU's PTX, or the same segments on the host for the simulated GPU
        from simgrad.codegen import nvptx

        cg = nvptx.GpuCodegen(ir, symbol, sim=prog.gpu_sim, tape_entries=tape_entries, debug=prog.config.debug,
                              fast_math=prog.config.fast_math, flush=flush)
    else:
        from simgrad.codegen.cpu import CpuCodegen  # loaded when first needed

        cg = CpuCodegen(ir, symbol, debug=prog.config.debug, fast_math=prog.config.fast_math,
                        flush=flush)
    text = cg.generate()
    if ptx_check_enabled():
        _ptx_check(ir, symbol, tape_entries, prog)
    # the disk cache is keyed by the IR text with the symbol name made stable
    stable = text.replace(symbol, "sg_kernel")
    uses_tape = ir.uses_tape
    meta = {"name": ir.name, "params": slots[0], "nslots": slots[1], "returns": list(ir.returns),
            "errors": cg.error_table, "ret_matrix": ret_matrix, "uses_tape": uses_tape,
            "private_slots": cg.private_slots, "scratch_slots": getattr(cg, "scratch_slots", 0),
            # the forward reads fields it overwrites: a Tape keeps their values from before each launch
            "in_place": transform is None and bool(in_place_targets(ir)),
            "tape_bound": ir.tape_bound if uses_tape else None,
            "tape_threads": getattr(cg, "tape_threads", 0),  # arch=cuda: per-thread regions of a deep tape
            "launches": [(ln.symbol.replace(symbol, "sg_kernel"), ln.grid, ln.block)
                         for ln in getattr(cg, "launches", ())],
            # a kernel that prints waits on arch=cuda, so its output comes before the next statement's (Taichi)
            "prints": prog.on_gpu and any(s.op is Op.PRINT for body in (ir.body, *(f.body for f in ir.functions))
                                          for s in walk(body))}
    return ir, stable, meta


def _bind_params(kernel: KernelSource, comp: KernelLowering, args) -> tuple[tuple[list[Packing], int],
                                                                      tuple[int, int] | StructType | None]:
    """Each parameter's kind binds its argument (compiler/params.py): what the body sees under the parameter's
    name, and the Packing that fills the context slots it took."""
    slots = Slots(comp.builder)
    out = []
    context.push(comp)
    try:
        for p, a in zip(kernel.params, args):
            value, packing = p.bind(a, slots)
            comp.bind(p.name, value)
            out.append(packing)
        ret = kernel.signature.return_annotation
        ret_matrix: tuple | StructType | None = None
        if typing.get_origin(ret) is tuple:  # tuple[f32, S] / typing.Tuple[f32, S]
            ret = typing.get_args(ret)
        if ret is not inspect.Signature.empty and ret is not None:
            if isinstance(ret, MatrixType):
                comp.return_types = [ret.dtype] * ret.num_entries
                ret_matrix = (ret.n, ret.m)
            elif isinstance(ret, StructType):
                comp.return_types = _flat_return_types(ret)
                comp.return_struct = ret
                ret_matrix = ret  # the launcher rebuilds the struct from the returned leaves
            elif isinstance(ret, (tuple, list)):
                comp.return_types = [t for r in ret for t in _flat_return_types(r)]
                if any(isinstance(r, (MatrixType, StructType)) for r in ret):
                    ret_matrix = ("tuple", tuple(ret))  # the launcher rebuilds each part
            else:
                comp.return_types = [dt.from_any(ret)]
            comp.ir.returns = comp.return_types
    finally:
        context.pop()
    return (out, slots.count), ret_matrix


def _flat_return_types(t) -> list:
    """The scalar types a returned value of type `t` travels as: a matrix by entry, a struct leaf by leaf."""
    if isinstance(t, MatrixType):
        return [t.dtype] * t.num_entries
    if isinstance(t, StructType):
        return [x for _, lt in t.leaves() for x in _flat_return_types(lt)]
    return [dt.from_any(t)]


def _make_launcher(prog: Program, meta: dict, obj: bytes) -> Launcher:
    """The launcher of one instantiation, from the metadata its compilation recorded (or the cache kept) and its
    code (linked into the program, or loaded on the device)."""
    launcher: Launcher
    if prog.on_gpu:
        from simgrad.runtime.gpu_launch import GpuLauncher

        names = [s for s, _, _ in meta["launches"]]
        fns = prog.device.load_module(prog.link(obj, names) if prog.gpu_sim else obj.decode(), names)
        launcher = GpuLauncher(prog.device, [(fns[s], grid, block) for s, grid, block in meta["launches"]],
                               meta["name"], meta["params"], meta["nslots"], meta["returns"], meta["errors"], prog,
                               meta["ret_matrix"], meta.get("scratch_slots", 0), meta.get("prints", False),
                               meta.get("tape_threads", 0))
    else:
        launcher = Launcher(meta["name"], meta["params"], prog.link(obj, ["sg_kernel"])["sg_kernel"], meta["nslots"],
                            meta["returns"], meta["errors"], prog, meta["ret_matrix"], meta.get("private_slots", 0),
                            meta.get("scratch_slots", 0))
    if meta["uses_tape"]:
        # the size proven by the bounds when they are static, else ti.init(ad_stack_size=...)
        bound = meta["tape_bound"]
        launcher.attach_tape(max(bound, 1) if bound is not None else prog.tape_capacity)
    ret_matrix = meta["ret_matrix"]
    if isinstance(ret_matrix, tuple) and ret_matrix[0] == "tuple":
        parts, inner_t = ret_matrix[1], launcher.launch

        def launch_tuple(*a):
            vals = iter(inner_t(*a))
            return tuple(_take_part(t, vals) for t in parts)

        launcher.launch = launch_tuple
        return launcher
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


def _take_part(t, vals):
    """One part of a returned tuple from the flat values: a scalar, a matrix or a struct."""
    if isinstance(t, StructType):
        return t.from_leaves([_take_leaf(lt, vals) for _, lt in t.leaves()])
    return _take_leaf(t, vals)


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
