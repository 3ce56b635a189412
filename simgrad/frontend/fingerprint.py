"""The key of the kernel cache: a digest of everything one instantiation's generated code depends on.

It is computed before compiling, from the kernel's source and the Python values its names resolve to,
following every @ti.func those values reach: plain values by value, fields by layout (never contents),
simgrad/math/numpy objects by qualified name (their code is covered by the library and version parts
of the key). A value it cannot describe this way makes the instantiation unkeyable (no caching).

Names are collected from the source, so the key over-approximates what the frontend reads. A `Guard`
then checks, while the instantiation compiles, that the frontend touched nothing outside the key (a
name or a function the key did not see, a call into user Python code, a mutation of a Python object,
a compile-time print); when it did, the result is not stored.
"""

from __future__ import annotations

import ast
import builtins
import hashlib
import inspect
import os
import sys
import types

import numpy as np

from simgrad import dtypes as dt
from simgrad.frontend.source import get_source


class Unkeyable(Exception):
    """A value the key cannot describe; the instantiation is compiled without the cache."""


_PLAIN = (type(None), bool, int, float, complex, str, bytes)
_BUDGET = 1 << 20  # values (container elements, array bytes / 64) one key may describe
# builtins without side effects whose results depend only on their arguments (none calls back into
# a function it is given: map/filter/sorted(key=) could call an unchecked one)
_PURE_BUILTINS = frozenset(
    "abs all any ascii bin bool bytes callable chr complex dict divmod enumerate float format frozenset "
    "getattr hasattr hex int isinstance issubclass len list oct ord pow range repr reversed round "
    "set slice str sum tuple type zip".split())
_READ_ONLY_METHODS = frozenset(
    "index count get keys values items copy format join split rsplit strip lstrip rstrip startswith endswith "
    "upper lower replace find rfind".split())


def _trusted_module(name) -> bool:
    """Modules whose objects the key may name instead of describing (fixed by the library versions)."""
    if not isinstance(name, str):
        return False
    if name.startswith("numpy.random"):
        return False
    return name in ("simgrad", "math", "builtins", "numpy") or name.startswith(("simgrad.", "numpy."))


# simgrad modules whose functions may run at compile time: they emit IR or compute on their arguments,
# and change no Python-scope state (fields, trees, the program are in other modules)
_PURE_LIBRARY = frozenset(("simgrad.dtypes", "simgrad.lang.operators", "simgrad.lang.matrix", "simgrad.lang.mathlib",
                           "simgrad.lang.linalg", "simgrad.lang.loops", "simgrad.lang.types",
                           "simgrad.lang.atomics", "simgrad.lang.expr", "simgrad.frontend.arrays"))


def is_library_function(fn) -> bool:
    mod = getattr(fn, "__module__", None)
    return isinstance(mod, str) and (mod == "simgrad" or mod.startswith("simgrad."))


def _library_object(v):
    """(module, name) of a function, class or builtin defined by a trusted module, else None."""
    if isinstance(v, types.BuiltinFunctionType):  # math.sqrt, len; a bound builtin method has no module
        owner = getattr(v, "__self__", None)
        if isinstance(owner, types.ModuleType) and _trusted_module(owner.__name__):
            return owner.__name__, v.__name__
        return None
    numpy_callable = type(v).__module__ == "numpy" and callable(v)  # np.ufunc, np.sum's dispatcher
    if isinstance(v, (types.FunctionType, type)) or numpy_callable:
        mod = getattr(v, "__module__", None)
        if _trusted_module(mod):
            return mod, getattr(v, "__qualname__", None) or v.__name__
    return None


def trusted_callable(fn) -> bool:
    """Whether calling `fn` at compile time depends only on its (keyed) arguments and changes nothing."""
    from simgrad.lang.loops import static_print

    if fn is static_print:  # prints at compile time: a cached instantiation would not
        return False
    if isinstance(fn, types.BuiltinFunctionType):
        owner = getattr(fn, "__self__", None)
        if owner is builtins:
            return fn.__name__ in _PURE_BUILTINS
        if isinstance(owner, types.ModuleType):
            return owner.__name__ == "math"
        if type(owner) in (str, bytes, tuple, list, dict, set, frozenset):
            return fn.__name__ in _READ_ONLY_METHODS
        return False
    if isinstance(fn, type):
        if fn.__module__ == "builtins":
            return fn.__name__ in _PURE_BUILTINS
        return fn.__module__ in _PURE_LIBRARY or issubclass(fn, np.generic)  # np.float32(x)
    if isinstance(fn, types.MethodType):
        return getattr(fn.__func__, "__module__", None) in _PURE_LIBRARY
    if isinstance(fn, types.FunctionType):
        return fn.__module__ in _PURE_LIBRARY
    return type(fn).__module__ in _PURE_LIBRARY  # a callable simgrad object: ti.types.vector(3, ti.f32)(...)


class KeyBuilder:
    """Describes values and functions as nested tuples of plain values; `digest` hashes the result."""

    def __init__(self) -> None:
        self.covered: dict = {}  # Python function -> the global/closure/builtin names its key describes
        self._order: dict = {}  # Python function -> its index, for recursion between ti.funcs
        self._budget = _BUDGET

    def digest(self, parts) -> str:
        return hashlib.sha256(repr(parts).encode()).hexdigest()[:40]

    def _spend(self, n: int) -> None:
        self._budget -= n
        if self._budget < 0:
            raise Unkeyable("too many values to describe")

    # -- functions -------------------------------------------------------------------------------
    def function(self, fn) -> tuple:
        """A kernel's or ti.func's source and the values its free names resolve to (as the frontend
        resolves them: closure, then globals, then builtins)."""
        if fn in self._order:
            return ("func-ref", self._order[fn])
        self._order[fn] = len(self._order)
        src = get_source(fn)
        local = set(fn.__code__.co_varnames)  # found in the frontend's scopes; the Guard checks it
        names = [n for n in _names(src) if n not in local]
        self.covered[fn] = set(names)
        resolved: list[tuple] = []
        for name in names:
            if name in src.closure:
                v = src.closure[name]
            elif name in src.globals:
                v = src.globals[name]
            elif hasattr(builtins, name):
                v = getattr(builtins, name)
            else:
                resolved.append((name,))
                continue
            _adopt_name(v, name)
            resolved.append((name, self.value(v)))
        return ("function", src.file, src.start, src.text, tuple(resolved))

    def signature(self, sig: inspect.Signature) -> tuple:
        """Annotations and defaults, which Python evaluated when the function was defined."""
        params = tuple((p.name, p.kind.value, self.value(p.annotation), self.value(p.default))
                       for p in sig.parameters.values())
        return params, self.value(sig.return_annotation)

    # -- values ----------------------------------------------------------------------------------
    def value(self, v, depth: int = 0):
        if depth > 64:
            raise Unkeyable("value nested too deeply")
        self._spend(1)
        t = type(v)
        if t in _PLAIN:
            return (t.__name__, repr(v))
        if t is tuple or t is list:
            return (t.__name__, tuple(self.value(x, depth + 1) for x in v))
        if t is dict:
            return ("dict", tuple((self.value(k, depth + 1), self.value(x, depth + 1)) for k, x in v.items()))
        if t is set or t is frozenset:
            return (t.__name__, tuple(sorted(repr(self.value(x, depth + 1)) for x in v)))
        if t is range or t is slice:
            return (t.__name__, v.start, v.stop, v.step)
        if v is inspect.Parameter.empty:
            return ("empty",)
        if isinstance(v, types.ModuleType):
            if _trusted_module(v.__name__):
                return ("module", v.__name__)
            raise Unkeyable(f"module {v.__name__}")
        if isinstance(v, np.ndarray):
            if v.dtype.hasobject:
                raise Unkeyable("object array")
            self._spend(v.nbytes // 64)
            return ("ndarray", v.dtype.str, v.shape, hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest())
        if isinstance(v, np.generic):
            return ("npscalar", v.dtype.str, repr(v.item()))
        lib = _library_object(v)
        if lib is not None:
            return ("lib",) + lib
        return self._simgrad_object(v, depth)

    def _simgrad_object(self, v, depth: int):
        from simgrad.lang.archs import Arch
        from simgrad.lang.field import Field
        from simgrad.lang.functions import Func
        from simgrad.lang.loops import ndrange
        from simgrad.lang.matrix import Matrix
        from simgrad.lang.snode import Axis, SNode
        from simgrad.lang.types import MatrixType, NdarrayType, Template, _Types, is_sparse_matrix_builder

        if isinstance(v, dt.DataType):
            return ("dtype", v.name)
        if isinstance(v, Field):
            return self.field(v)
        if isinstance(v, Func):
            if is_library_function(v.func):
                return ("libfunc", v.func.__module__, v.func.__qualname__)
            return ("func", self.function(v.func), self.signature(v.signature))
        if isinstance(v, Matrix):
            return ("matrix", v.n, v.m, tuple(self.value(e, depth + 1) for e in v.entries))
        if isinstance(v, MatrixType):
            return ("matrixtype", v.n, v.m, self.value(v._dtype, depth + 1))
        if isinstance(v, NdarrayType):
            return ("ndarraytype", self.value(v.dtype, depth + 1), v.ndim)
        if isinstance(v, Template):
            return ("template",)
        if is_sparse_matrix_builder(v):
            return ("sparse_matrix_builder",)
        if isinstance(v, Axis):
            return ("axis", v.index)
        if isinstance(v, SNode):
            if v.tree is None or v.tree.program.released:
                raise Unkeyable("an SNode of no live program")
            v.tree.materialize()  # the layout, pools included, is what gets compiled in
            return ("snode", v.tree.id, _path(v))
        if isinstance(v, ndrange):
            return ("ndrange", self.value(v.bounds, depth + 1))
        if isinstance(v, Arch):
            return ("arch", v.name)
        if isinstance(v, _Types):
            return ("ti.types",)
        raise Unkeyable(f"a {type(v).__module__}.{type(v).__qualname__} object")

    def field(self, f) -> tuple:
        """A field by where it lives and how it is laid out: its contents are not compiled in."""
        if f.released():
            raise LookupError("a field of a released program is never keyed: compiling reports it")
        comps = tuple(_component(c) for c in f._components())
        grad = self.field(f.grad) if f.grad is not None else None
        dual = self.field(f.dual) if getattr(f, "dual", None) is not None else None
        return ("field", type(f).__name__, f.name, f.dtype.name, getattr(f, "n", 0), getattr(f, "m", 0),
                getattr(f, "_needs_grad", None), comps, grad, dual)


def _path(node) -> tuple:
    """An SNode's path as compiled code sees it: kinds, sizes, offsets, and a sparse node's pool, mask and
    block (pool ids follow the order sparse nodes were materialised in, so they must be in the key)."""
    return tuple((n.kind, n.axes, n.sizes, n.offset_in_parent, n.cell_size, n.pool, n.mask_offset, n.block_size,
                  n.chunk_size) for n in node.path())


def _component(c) -> tuple:
    node = c.snode
    path = _path(node) if node else None
    tree = node.tree.id if node is not None and node.tree is not None else None
    quant = repr(c.quant_type) if getattr(c, "quant_type", None) is not None else None
    if quant is not None and node is not None and node._parent is not None and node._parent.bitpack is not None:
        quant += repr([(repr(m[1]), m[2], m[3]) for m in node._parent.bitpack.members])  # the packing compiled in
    return (c.name, c.dtype.name, c.offset, c.layout, tree, path, c.is_primal, quant)


def _adopt_name(v, name: str) -> None:
    """What the frontend does when it meets an unnamed field by this name: done here, before the key
    is taken, so that a cached instantiation names the field as a compiled one would."""
    from simgrad.lang.field import Field

    if isinstance(v, Field) and v._auto_name:
        v.adopt_name(name)


def _names(src) -> list[str]:
    """The names a function's source reads or binds, in source order."""
    if src.names is None:
        out: dict[str, None] = {}

        def visit(node):
            if isinstance(node, ast.Name):
                out.setdefault(node.id, None)
            for child in ast.iter_child_nodes(node):
                visit(child)

        visit(src.tree)
        src.names = list(out)
    return src.names


_environment: tuple | None = None


def source_files(root: str) -> list[str]:
    """simgrad's sources under `root`, in a fixed order: Python modules and the LLVM IR of runtime/ll, which
    generated code contains too."""
    out = []
    for d, dirs, files in os.walk(root):
        dirs[:] = sorted(x for x in dirs if x != "__pycache__")
        out += [os.path.join(d, name) for name in sorted(files) if name.endswith((".py", ".ll"))]
    return out


def environment() -> tuple:
    """The versions the generated code depends on: simgrad's own sources, Python, numpy, llvmlite."""
    global _environment
    if _environment is None:
        import llvmlite

        h = hashlib.sha256()
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        for path in source_files(root):
            h.update(os.path.relpath(path, root).encode() + b"\0")
            with open(path, "rb") as fh:
                h.update(fh.read())
            h.update(b"\0")
        _environment = (h.hexdigest(), sys.version, np.__version__, llvmlite.__version__)
    return _environment


class Guard:
    """Watches one keyed compilation: `reason` is set when the frontend reads outside the key."""

    def __init__(self, covered: dict):
        self.covered = covered
        self.reason: str | None = None

    def name(self, fn, name: str) -> None:
        """The frontend resolved `name` through `fn`'s closure, globals or builtins."""
        names = self.covered.get(fn)
        if names is None:
            if not is_library_function(fn):
                self.taint(f"{getattr(fn, '__qualname__', fn)} is not described by the key")
        elif name not in names:
            self.taint(f"name '{name}' of {fn.__qualname__} is not described by the key")

    def call(self, fn) -> None:
        if not trusted_callable(fn):
            self.taint(f"compile-time call of {getattr(fn, '__qualname__', type(fn).__name__)}")

    def taint(self, reason: str) -> None:
        if self.reason is None:
            self.reason = reason
