"""simgrad: a differentiable, Taichi-compatible kernel language compiled to native code.

`import simgrad as ti` and write Taichi programs: kernels are parsed from Python source, lowered to our
IR, optimised, differentiated in the IR, and compiled with LLVM to multithreaded native code.
"""

from simgrad import dtypes as _dt
from simgrad.dtypes import f16, f32, f64, i8, i16, i32, i64, u1, u8, u16, u32, u64
from simgrad.errors import (
    GradientError,
    SimgradAssertionError,
    SimgradError,
    SimgradIndexError,
    SimgradNameError,
    SimgradNotSupportedError,
    SimgradRuntimeError,
    SimgradSyntaxError,
    SimgradTypeError,
    TaichiAssertionError,
    TaichiCompilationError,
    TaichiIndexError,
    TaichiNameError,
    TaichiRuntimeError,
    TaichiRuntimeTypeError,
    TaichiSyntaxError,
    TaichiTypeError,
)
from simgrad.lang.logging import CRITICAL, DEBUG, ERROR, INFO, TRACE, WARN, is_logging_effective, set_logging_level

from simgrad.lang import mathlib as math
from simgrad.lang.archs import (
    amdgpu,
    arm64,
    cpu,
    cuda,
    dx11,
    dx12,
    extension,
    gles,
    gpu,
    metal,
    opengl,
    vulkan,
    x64,
)

x86_64 = x64
from simgrad.lang.factories import FieldsBuilder, field, root
from simgrad.lang.field import Field, MatrixField, ScalarField, rescale_index
from simgrad.compiler.kernel import kernel
from simgrad.compiler import fill as _fill  # installs the compiled zeroing of large gradients
from simgrad.compiler import sparse_scope as _sparse_scope  # Python-scope access to sparse fields
from simgrad.lang.functions import data_oriented, func, pyfunc, real_func


from simgrad.lang.loops import (
    assume_in_range,
    block_local,
    cache_read_only,
    grouped,
    no_activate,
    stop_grad,
    loop_config,
    loop_unique,
    ndrange,
    static,
    static_assert,
    static_print,
)
from simgrad.lang.matrix import Matrix, Vector
from simgrad.lang.struct import Struct, StructField, dataclass
from simgrad.lang.ndarray import MatrixNdarray, Ndarray, ScalarNdarray, VectorNdarray, ndarray
from simgrad.lang.operators import (
    abs,
    bit_cast,
    bit_shr,
    cast,
    ceil,
    floor,
    frexp,
    global_thread_idx,
    logical_and,
    logical_not,
    logical_or,
    max,
    min,
    one,
    pow,
    randn,
    random,
    raw_div,
    raw_mod,
    round,
    select,
    zero,
)
from simgrad.lang.operators import math_functions as _math_functions

globals().update(_math_functions("ti"))  # the registry's math functions (ir/opdefs.py): ti.sin, ti.atan2, ...
from simgrad.lang.snode import SNode, i, ij, ijk, ijkl, ijl, ik, ikl, il, j, jk, jkl, jl, k, kl, l, axes
from simgrad.lang.types import Layout, ref, sparse_matrix_builder, template, types
from simgrad.lang.quant import BitpackedFields
from simgrad.lang.argpack import ArgPack, ArgPackType, argpack as _argpack
from simgrad.lang import impl as _impl

types.quant.impl = _impl  # ti.types.quant.impl is Taichi's ti.lang.impl
types.argpack = _argpack  # lang/types.py sits below lang/argpack.py
from simgrad.lang.atomics import (
    atomic_add,
    atomic_and,
    atomic_max,
    atomic_min,
    atomic_mul,
    atomic_or,
    atomic_sub,
    atomic_xor,
)
from simgrad.lang.linalg import eig, polar_decompose, solve, svd, sym_eig
from simgrad.lang.sparse import activate, append, deactivate, deactivate_all_snodes, get_addr, is_active, length
from simgrad.lang import profiler
from simgrad.lang.program import init, reset

int8, int16, int32, int64 = i8, i16, i32, i64
uint8, uint16, uint32, uint64 = u8, u16, u32, u64
float16, float32, float64 = f16, f32, f64
uint1 = u1


def sync():
    """Wait for the kernels launched so far (on the CPU they finish before their launch returns)."""
    from simgrad.lang.program import get_program

    get_program().sync()


def get_runtime():
    from simgrad.lang.program import get_program

    return get_program()


_NOT_SUPPORTED = {
    "aot": "Taichi's AOT deployment is not part of simgrad",
    **{n: "Taichi's mesh extension is not part of simgrad" for n in ("Mesh", "MeshInstance", "mesh_local",
                                                                     "mesh_patch_idx")},
    "Texture": "textures are a GPU rendering feature simgrad does not have",
    "simt": "warp/block intrinsics (ti.simt) are GPU-only and not built",
    "DeviceCapability": "device capabilities are a GPU-backend notion simgrad does not have",
}


def __getattr__(name):
    """Names loaded on first use; kept in the module after it, so that `ti.GUI.LEFT` in a frame loop is a
    plain attribute read (through this function it cost 0.6 us)."""
    value = _lazy(name)
    globals()[name] = value
    return value


def _lazy(name):
    if name in ("GUI", "rgb_to_hex", "hex_to_rgb", "ui"):
        import simgrad.gui as _gui

        return getattr(_gui, name)
    if name == "tools":  # PLYWriter, imshow, imwrite, imread, imresize, VideoManager
        import simgrad.gui.tools as _tools

        return _tools
    if name == "experimental":  # Taichi's: real_func, deprecated there in favour of ti.real_func
        import simgrad.experimental as _experimental

        return _experimental
    if name == "_logging":  # Taichi's logging module: set_logging_level, is_logging_effective, the level names
        import simgrad.lang.logging as _logging_module

        return _logging_module
    if name == "_lib":  # ti._lib.core.with_vulkan() and the other backend probes answer False
        import simgrad._lib as _lib_module

        return _lib_module
    if name == "sparse":  # Taichi's sparse-grid helper (grid, usage), kernels of the public language
        import simgrad.sparse as _sparse

        return _sparse
    if name == "Format":  # texture formats: named by ti.graph.Arg(..., fmt=...), refused there
        from simgrad.lang.graph import Format as _Format

        return _Format
    if name == "graph":  # compute graphs, replayed as kernel launches in order
        import simgrad.lang.graph as _graph

        return _graph
    if name == "algorithms":  # parallel_sort and PrefixSumExecutor, simgrad kernels
        import simgrad.algorithms as _algorithms

        return _algorithms
    if name == "linalg":  # sparse matrices and solvers: loaded (with scipy, lazily) when first used
        import simgrad.linalg as _linalg

        return _linalg
    if name == "torch":  # the torch autograd bridge: loaded on use, where torch is installed
        import simgrad.torch as _torch_bridge

        return _torch_bridge
    if name in ("ad", "Tape", "clear_all_gradients", "no_grad", "grad_replaced", "grad_for"):
        from simgrad.lang import ad as _ad

        return _ad if name == "ad" else getattr(_ad, name)
    if name in _NOT_SUPPORTED:
        from simgrad.errors import SimgradNotSupportedError, caller_loc

        raise SimgradNotSupportedError(f"ti.{name} is not supported by simgrad: {_NOT_SUPPORTED[name]}", caller_loc())
    raise AttributeError(f"module 'simgrad' has no attribute '{name}'")
