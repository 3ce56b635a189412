"""``ti.graph``: Taichi's compute graphs, replayed as one native call.

Taichi records kernel launches over symbolic arguments (``Arg``) and runs the recorded list with concrete
ndarrays and scalars bound by name; its point is AOT deployment, which simgrad has not. Here a compiled
graph is that list: ``run(args)`` checks the bound values against their ``Arg`` declarations and launches the
kernels in order. The first run with some values launches them from Python (compiling what is new) and then
captures the sequence (runtime/launch.py Sequence: each step's context packed once); later runs with the same
values (the same ndarrays, equal scalars) replay it in one native call, no Python per kernel. Under a Tape or
the forward mode, with the kernel profiler, on arch=cuda, or with a kernel that needs Python after its launch,
every run launches from Python. Textures have no simgrad counterpart: their kinds are located errors.
"""

from __future__ import annotations

import enum

from simgrad.errors import SimgradError, SimgradNotSupportedError, caller_loc
from simgrad.runtime.launch import Sequence, replay_key

__all__ = ["Arg", "ArgKind", "Format", "Graph", "GraphBuilder"]


class ArgKind(enum.Enum):
    SCALAR = 0
    NDARRAY = 1
    MATRIX = 2
    TEXTURE = 3
    RWTEXTURE = 4


# Taichi's texture formats (ti.Format), in its order: only so that a program naming one reaches Arg's checks, as
# Taichi's removed-argument errors come before anything about the texture itself (textures are not built)
Format = enum.IntEnum("Format", [
    "unknown", "r8", "rg8", "rgba8", "rgba8srgb", "bgra8", "bgra8srgb", "r8u", "rg8u", "rgba8u", "r8i", "rg8i",
    "rgba8i", "r16", "rg16", "rgb16", "rgba16", "r16u", "rg16u", "rgb16u", "rgba16u", "r16i", "rg16i", "rgb16i",
    "rgba16i", "r16f", "rg16f", "rgb16f", "rgba16f", "r32u", "rg32u", "rgb32u", "rgba32u", "r32i", "rg32i", "rgb32i",
    "rgba32i", "r32f", "rg32f", "rgb32f", "rgba32f", "depth16", "depth24stencil8", "depth32f"], start=0)

_POSITIONAL = ("tag", "name", "dtype", "ndim", "field_dim", "element_shape")


def _removed_arguments(tag, kwargs: dict) -> None:
    """Arguments Taichi 1.7.0 removed, refused with its messages (TaichiRuntimeError) before anything else."""
    from simgrad.errors import TaichiRuntimeError

    why = None
    if tag == ArgKind.SCALAR and "element_shape" in kwargs:
        why = ("The element_shape argument for scalar is deprecated in v1.6.0, and is removed in v1.7.0. "
               "Please remove them.")
    elif tag == ArgKind.NDARRAY and "element_shape" in kwargs:
        why = ("The element_shape argument for ndarray is deprecated in v1.6.0, and it is removed in v1.7.0. "
               "Please use vector or matrix data type instead.")
    elif tag in (ArgKind.TEXTURE, ArgKind.RWTEXTURE) and "shape" in kwargs:
        why = ("The shape argument for texture is deprecated in v1.6.0, and it is removed in v1.7.0. "
               "Please use ndim instead. (Note that you no longer need the exact texture size.)")
    elif tag == ArgKind.RWTEXTURE and ("channel_format" in kwargs or "num_channels" in kwargs):
        why = ("The channel_format and num_channels arguments for texture are deprecated in v1.6.0, "
               "and they are removed in v1.7.0. Please use fmt instead.")
    elif tag == ArgKind.TEXTURE and ("channel_format" in kwargs or "num_channels" in kwargs):
        why = ("The channel_format and num_channels arguments are no longer required for non-RW textures "
               "since v1.6.0, and they are removed in v1.7.0. Please remove them.")
    if why is not None:
        raise TaichiRuntimeError(why, caller_loc())


class Arg:
    """A named placeholder for a kernel argument: ``Arg(ArgKind.NDARRAY, "x", dtype=ti.math.vec2, ndim=1)``."""

    def __init__(self, *args, **kwargs):
        if len(args) > len(_POSITIONAL):
            raise SimgradError(f"ti.graph.Arg: unexpected {len(args)}th positional argument", caller_loc())
        kwargs.update(zip(_POSITIONAL, args))
        tag, name = kwargs.pop("tag", None), kwargs.pop("name", None)
        if not isinstance(tag, ArgKind):
            raise SimgradError(f"ti.graph.Arg: tag must be a ti.graph.ArgKind, got {tag!r}", caller_loc())
        _removed_arguments(tag, kwargs)
        if tag in (ArgKind.TEXTURE, ArgKind.RWTEXTURE):
            raise SimgradNotSupportedError("ti.graph.Arg: textures are a GPU rendering feature simgrad does not have",
                                           caller_loc())
        if not isinstance(name, str):
            raise SimgradError(f"ti.graph.Arg: name must be a string, got {name!r}", caller_loc())
        if "field_dim" in kwargs:  # Taichi's deprecated spelling of ndim
            kwargs["ndim"] = kwargs.pop("field_dim")
        allowed = {ArgKind.SCALAR: {"dtype"}, ArgKind.MATRIX: {"dtype"}, ArgKind.NDARRAY: {"dtype", "ndim"}}[tag]
        extra = sorted(set(kwargs) - allowed)
        if extra:
            raise SimgradError(f"ti.graph.Arg({tag.name}): unexpected arguments {extra}", caller_loc())
        dtype = kwargs.get("dtype")
        shape = tuple(getattr(dtype, "shape", ()) or ())  # vector / matrix element types
        if tag == ArgKind.SCALAR and shape:
            raise SimgradError(f"ti.graph.Arg: a SCALAR needs a scalar type, got {dtype}", caller_loc())
        if tag == ArgKind.MATRIX and not shape:
            raise SimgradError(f"ti.graph.Arg: a MATRIX needs a vector or matrix type, got {dtype}", caller_loc())
        self.tag, self.name, self.dtype = tag, name, dtype
        self.ndim = int(kwargs.get("ndim", 0))
        self.element_shape = shape

    def check(self, value, loc):
        """Raise a located error where ``value`` cannot stand for this argument."""
        if self.tag != ArgKind.NDARRAY:
            return
        arr_shape = getattr(value, "shape", None)
        if arr_shape is None or not hasattr(value, "element_shape"):
            raise SimgradError(f"graph argument {self.name!r}: expected a ti.ndarray, got {type(value).__name__}", loc)
        if len(arr_shape) != self.ndim:
            raise SimgradError(f"graph argument {self.name!r}: expected {self.ndim} dimensions, got an ndarray of "
                               f"shape {tuple(arr_shape)}", loc)
        if tuple(value.element_shape) != self.element_shape:
            raise SimgradError(f"graph argument {self.name!r}: expected elements of shape {self.element_shape}, got "
                               f"{tuple(value.element_shape)}", loc)

    def __repr__(self):
        return f"Arg({self.tag.name}, {self.name!r})"


class Sequential:
    """An ordered list of launches that a builder appends, possibly several times."""

    def __init__(self):
        self.launches: list = []

    def dispatch(self, kernel_fn, *args):
        self.launches.append((kernel_fn, args))


class GraphBuilder:
    def __init__(self):
        self._nodes: list = []  # (kernel, args) launches and Sequentials, in order

    def dispatch(self, kernel_fn, *args):
        self._nodes.append((kernel_fn, args))

    def create_sequential(self):
        return Sequential()

    def append(self, node):
        if not isinstance(node, Sequential):
            raise SimgradError("GraphBuilder.append takes what create_sequential() made", caller_loc())
        self._nodes.append(node)

    def compile(self):
        launches = []
        for node in self._nodes:
            launches += node.launches if isinstance(node, Sequential) else [node]
        return Graph(launches)


class Graph:
    """What ``GraphBuilder.compile()`` gives: ``run({name: value})`` launches the kernels in order."""

    def __init__(self, launches):
        self.launches = list(launches)
        self.args = {a.name: a for _, args in self.launches for a in args if isinstance(a, Arg)}
        self._names = sorted(self.args)
        self._captured = None  # (generation, key, Sequence, the bound values kept alive) of the last capture

    def run(self, args):
        from simgrad.lang.program import get_program

        key = tuple((name, replay_key(args[name])) for name in self._names if name in args)
        generation = get_program().generation
        if self._captured is not None and self._captured[:2] == (generation, key) and _capturable():
            self._captured[2].run()  # the values were checked when this capture was made
            return
        loc = caller_loc()
        missing = sorted(set(self.args) - set(args))
        if missing:
            raise SimgradError(f"graph run: no value for the arguments {missing}", loc)
        for name, arg in self.args.items():
            arg.check(args[name], loc)
        bound = [tuple(args[a.name] if isinstance(a, Arg) else a for a in kargs) for _, kargs in self.launches]
        for (kernel, _), values in zip(self.launches, bound):
            kernel(*values)
        sequence = _capture([k for k, _ in self.launches], bound) if _capturable() else None
        self._captured = (generation, key, sequence, args) if sequence is not None else None


def _capturable() -> bool:
    from simgrad.lang import ad_hooks
    from simgrad.lang.program import get_program

    prog = get_program()
    return (ad_hooks.recorder is None and ad_hooks.forward_mode is None and not prog.config.kernel_profiler
            and not prog.on_gpu)


def _capture(kernels: list, bound: list):
    """The launches as a native Sequence, or None when a step cannot be replayed without Python."""
    steps = []
    for kernel, values in zip(kernels, bound):
        target = getattr(kernel, "kernel", kernel)  # a data_oriented object's kernel method
        if hasattr(kernel, "obj"):
            values = (kernel.obj, *values)
        instance = getattr(target, "instance", None)
        try:
            steps.append((instance(values).launcher if instance is not None else None, values))
        except SimgradError:  # e.g. arguments its defaults complete: it launches from Python
            return None
    return Sequence.packed(steps)
