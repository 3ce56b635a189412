"""Kernel parameters, one class per kind (scalar, vector/matrix, struct, ndarray, template, sparse matrix
builder). A kind owns everything that depends on it, so a new kind of argument is one class and a
`register`: the driver, the @ti.kernel object, the launcher and the Tape only call these methods.

- `accepts(ann)`: whether an annotation names this kind (the first registered kind that accepts it wins).
- `key(a, keep)`: what of the argument picks the instantiation, for the kernel's instance cache (`keyed`
  kinds only; objects whose identity the key uses go to `keep`, which lives as long as the cache);
  `fingerprint(a, kb)`: the same for the kernel cache on disk, which must describe the value, never use
  its identity (by default the key itself).
- `bind(a, slots)`: what the kernel body sees while it is compiled (ARG values, a Matrix of them, an
  ndarray view, the template value itself), and the Packing (runtime/args.py) that fills the context slots
  it took: what the generated launcher emits for it, and the ARG values the Tape's validation can read back
  (`slot_values`).

A kind whose argument travels as words the built-in packings already write reuses them (a member path picks
the value out of the argument: struct leaves do); one that needs another layout subclasses Packing, whose
`launch_code` writes the launcher's lines. A new argument *type* under an existing annotation (a torch tensor
or a device array under ti.types.ndarray()) is a registered subclass of that kind: its `key` and `bind` handle
the new type (a key of its own, so the instantiation and its packing are the new type's) and defer to
`super()` for every other value (tests/compiler/test_params.py does this for a raw pointer)."""

from __future__ import annotations

import inspect
from typing import ClassVar

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import AnnotationError, SimgradTypeError, SimgradValueError, caller_loc
from simgrad.frontend.arrays import ArrayArg, BuilderArg
from simgrad.frontend.fingerprint import KeyBuilder
from simgrad.frontend.refs import tensor_text
from simgrad.ir.builder import Builder
from simgrad.ir.ops import Op
from simgrad.lang.argpack import ArgPack, ArgPackType
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix
from simgrad.lang.struct import StructType
from simgrad.lang.types import MatrixType, NdarrayType, is_sparse_matrix_builder, is_template
from simgrad.runtime.args import (
    ArgPackPacking,
    ArrayPacking,
    BuilderPacking,
    MatrixPacking,
    Packing,
    ScalarPacking,
    StructPacking,
    TensorPacking,
)
from simgrad.runtime.tensors import GradPair, array_dtype, described, is_foreign, is_torch


class Slots:
    """The context slots of one instantiation's arguments, handed out in parameter order."""

    def __init__(self, builder: Builder):
        self.builder = builder
        self.count = 0

    def take(self, n: int) -> int:
        """The first of `n` consecutive fresh slots."""
        first = self.count
        self.count += n
        return first

    def arg(self, t: dt.DataType) -> tuple[Expr, int]:
        """A fresh slot read as a value of type `t` in the body: (the ARG value, its slot)."""
        slot = self.take(1)
        return Expr(self.builder.emit(Op.ARG, t, (), {"slot": slot})), slot


class Param:
    """One parameter of a @ti.kernel; a subclass per kind (see the module's docstring)."""

    keyed: ClassVar[bool] = False  # whether arguments pick the instantiation (else every call shares one)

    def __init__(self, name: str, ann, kernel_name: str):
        self.name, self.ann, self.kernel_name = name, ann, kernel_name

    @classmethod
    def accepts(cls, ann) -> bool:
        raise NotImplementedError

    def key(self, a, keep: list):
        return None

    def fingerprint(self, a, kb: KeyBuilder):
        return self.key(a, [])

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        raise NotImplementedError


class TemplateParam(Param):
    """`ti.template()`: the argument is a compile-time value (a field, a number, a function, an object)."""

    keyed = True

    @classmethod
    def accepts(cls, ann) -> bool:
        return is_template(ann)

    def key(self, a, keep: list):
        if hasattr(a, "_ndarray_data"):
            raise SimgradTypeError(f"kernel {self.kernel_name}: Ndarray shouldn't be passed in via `ti.template()` "
                                   f"(parameter '{self.name}'), please annotate your kernel using "
                                   "`ti.types.ndarray(...)` instead", caller_loc())
        return _template_key(a, keep)

    def fingerprint(self, a, kb: KeyBuilder):
        return kb.value(a)

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        return a, Packing(self.name)


def _template_key(v, keep: list):
    if isinstance(v, (int, float, bool, str, type(None))):
        return (type(v), v)
    if isinstance(v, (tuple, list)):
        return (type(v), tuple(_template_key(x, keep) for x in v))
    if isinstance(v, np.ndarray) and v.size <= 16:
        return ("nd", v.dtype.str, v.shape, v.tobytes())
    if isinstance(v, Matrix) and all(isinstance(e, (int, float, bool)) for e in v.entries):
        # by value, as its entries are compiled in: a new equal vector per call finds the same instance
        return ("mat", v.n, v.m, tuple((type(e), e) for e in v.entries))
    keep.append(v)
    return ("id", id(v))


class ScalarParam(Param):
    """A ti.f32, ti.i32, ... (or float/int) parameter: one slot, an ARG value in the body."""

    @classmethod
    def accepts(cls, ann) -> bool:
        if ann is inspect.Parameter.empty:
            return False
        try:
            dt.from_any(ann)
        except (TypeError, ValueError):  # numpy's dtype() raises ValueError for objects with a `.dtype`
            return False
        return True

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        t = dt.from_any(self.ann)
        value, slot = slots.arg(t)
        return value, ScalarPacking(self.name, slot, t)


class MatrixParam(Param):
    """A ti.types.vector/matrix parameter: one slot per entry, a Matrix of ARG values in the body."""

    @classmethod
    def accepts(cls, ann) -> bool:
        return isinstance(ann, MatrixType)

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        return _bind_matrix(self.name, self.ann, slots, ())


def _bind_matrix(name: str, mt: MatrixType, slots: Slots, path: tuple) -> tuple[Matrix, MatrixPacking]:
    slot = slots.take(mt.num_entries)
    entries = [Expr(slots.builder.emit(Op.ARG, mt.dtype, (), {"slot": slot + k})) for k in range(mt.num_entries)]
    return Matrix(n=mt.n, m=mt.m, _entries=entries), MatrixPacking(name, slot, mt.dtype, mt.num_entries, path)


class StructParam(Param):
    """A ti.types.struct / @ti.dataclass parameter: its leaves (scalars and matrices, nested structs
    flattened), each in its own slots; the body sees the struct rebuilt from them."""

    @classmethod
    def accepts(cls, ann) -> bool:
        return isinstance(ann, StructType)

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        values: list = []
        leaves: list[Packing] = []
        for path, lt in self.ann.leaves():
            value: object
            packing: Packing
            if isinstance(lt, MatrixType):
                value, packing = _bind_matrix(self.name, lt, slots, path)
            else:
                value, slot = slots.arg(lt)
                packing = ScalarPacking(self.name, slot, lt, path)
            values.append(value)
            leaves.append(packing)
        return self.ann.from_leaves(values), StructPacking(self.name, leaves)


class BuilderParam(Param):
    """`ti.types.sparse_matrix_builder()`: a ti.linalg.SparseMatrixBuilder's triplet arrays, by reference
    (frontend/arrays.py BuilderArg); one instantiation per value type."""

    keyed = True

    @classmethod
    def accepts(cls, ann) -> bool:
        return is_sparse_matrix_builder(ann)

    def key(self, a, keep: list):
        triplets = getattr(a, "_triplets", None)
        if triplets is None:
            raise SimgradTypeError(f"kernel {self.kernel_name}: argument '{self.name}' is annotated "
                                   "ti.types.sparse_matrix_builder() and expects a ti.linalg.SparseMatrixBuilder, "
                                   f"got {type(a).__name__}", caller_loc())
        return ("builder", triplets.dtype.name)

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        barg = BuilderArg(self.name, slots.count, a._triplets.dtype)
        slots.take(barg.num_slots)
        return barg, BuilderPacking(self.name, barg.slot, barg.dtype)


# numpy dtype -> its name, as keys hold it (str(dtype) costs microseconds per launch)
_DTYPE_NAMES: dict = {}


class NdarrayParam(Param):
    """`ti.types.ndarray(...)` (or np.ndarray): a numpy array or ti.ndarray by reference (TensorParam below
    takes torch tensors and DLPack arrays);
    its dtype, dimensions, element shape and whether the kernel sees its gradient pick the instantiation."""

    keyed = True

    def __init__(self, name: str, ann, kernel_name: str):
        super().__init__(name, ann if isinstance(ann, NdarrayType) else NdarrayType(), kernel_name)
        # a numpy array's key is a function of its dtype and shape (it has no gradient): kept per (dtype, shape),
        # as working out the element shape and checking it against the annotation costs ~2 us a launch
        self._numpy_keys: dict = {}

    @classmethod
    def accepts(cls, ann) -> bool:
        return isinstance(ann, NdarrayType) or ann is NdarrayType or ann is np.ndarray

    def key(self, a, keep: list):
        if type(a) is np.ndarray:
            known = self._numpy_keys.get((a.dtype, a.shape))
            if known is None:
                known = self._key(a)
                if len(self._numpy_keys) >= 64:
                    self._numpy_keys.clear()
                self._numpy_keys[(a.dtype, a.shape)] = known
            return known
        return self._key(a)

    def _key(self, a):
        if not hasattr(a, "dtype") or not hasattr(a, "shape"):
            raise SimgradTypeError(f"kernel {self.kernel_name}: argument '{self.name}' expects an ndarray, got "
                                   f"{type(a).__name__} (Invalid type for argument {self.name}, got {a})")
        arr = getattr(a, "_ndarray_data", a)  # a ti.ndarray object: its numpy data
        name = _DTYPE_NAMES.get(arr.dtype)
        if name is None:
            name = _DTYPE_NAMES[arr.dtype] = str(arr.dtype)
        return (name, len(arr.shape), self.element_shape(a), self.with_grad(a))

    def with_grad(self, a) -> bool:
        """Whether kernels see the gradient of argument `a`: the annotation's needs_grad, else whether it has
        one (a ti.ndarray with needs_grad=True, a torch tensor that requires grad)."""
        has = getattr(a, "grad", None) is not None if hasattr(a, "_ndarray_data") else \
            bool(getattr(a, "requires_grad", False))
        want = self.ann.needs_grad
        if want and not has:
            raise SimgradTypeError(f"kernel {self.kernel_name}: ndarray argument '{self.name}' is annotated "
                                   "needs_grad=True but has no gradient (create it with ti.ndarray(..., "
                                   "needs_grad=True), or pass a tensor that requires grad)")
        return has if want is None else bool(want)

    def element_shape(self, a) -> tuple:
        """The element shape of argument `a`: the annotation's, else a ti.ndarray object's own."""
        arr = getattr(a, "_ndarray_data", a)
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
            if isinstance(a, np.ndarray):  # the key holds the annotation's shape: check the array's here
                self._check_external(a)
            return ann.dtype.shape
        elem = ann.element_shape_of(tuple(arr.shape))
        if not elem and ann.dtype is None and not ann.element_dim:
            elem = getattr(a, "element_shape", ())
        return elem

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        arg = self._array_arg(a, slots)
        return arg, ArrayPacking(self.name, arg.slot, arg.dtype, arg.ndim, arg.ndim + len(arg.element_shape),
                                 arg.grad_slot)

    def _check_external(self, a: np.ndarray) -> None:
        """A numpy argument against the annotation, in Taichi's words for external arrays (ValueError, and
        TypeError: compiler/kernel.py makes it an ArgumentValueError)."""
        ann, name, shape = self.ann, self.name, tuple(a.shape)
        where = f"kernel {self.kernel_name}: Invalid value for argument {name} - "
        if isinstance(ann.dtype, MatrixType):
            edim = 1 if ann.dtype.m == 0 else 2
            if ann.ndim is not None and len(shape) != edim + ann.ndim:
                raise SimgradTypeError(f"{where}required array has ndim={ann.ndim} element_dim={edim}, array with "
                                        f"{len(shape)} dimensions is provided")
            if len(shape) < edim:
                raise SimgradTypeError(f"{where}required element_dim={edim}, array with {len(shape)} dimensions "
                                        "is provided")
            want = ann.dtype.shape
            if ann.dtype.n is not None and None not in want and shape[len(shape) - edim:] != tuple(want):
                raise SimgradTypeError(f"{where}required element_shape={tuple(want)}, array with element shape of "
                                        f"{shape[len(shape) - edim:]} is provided")
        elif ann.dtype is not None:
            want_t, t = dt.from_any(ann.dtype), dt.from_numpy(a.dtype)
            if want_t is not t:
                raise SimgradTypeError(f"{where}required array has dtype={want_t}, array with dtype={t} is "
                                        "provided")
            if ann.ndim is not None and len(shape) != ann.ndim:
                raise SimgradTypeError(f"{where}required array has ndim={ann.ndim}, array with {len(shape)} "
                                        "dimensions is provided")

    def _array_arg(self, a, slots: Slots, grad: bool | None = None) -> ArrayArg:
        """The compiler's view of the argument, its dtype, dimensions and element shape checked (Taichi's
        messages: "Invalid value for argument a - required ...", "Expect element type ... but get ...")."""
        ann: NdarrayType = self.ann
        kernel_name, name = self.kernel_name, self.name
        if isinstance(a, np.ndarray):
            self._check_external(a)
        arr = getattr(a, "_ndarray_data", a) if hasattr(a, "dtype") else np.asarray(a)
        t = dt.from_numpy(arr.dtype) if isinstance(arr, np.ndarray) else array_dtype(arr)
        want: dt.DataType | None
        elem = self.element_shape(a)
        own = tuple(getattr(a, "element_shape", ()) or ()) if hasattr(a, "_ndarray_data") else None
        if isinstance(ann.dtype, MatrixType):
            want = ann.dtype.dtype if ann.dtype._dtype is not None or ann.dtype.n is not None else None
            if isinstance(a, np.ndarray):  # Taichi checks only the element shape of an external array
                want = None
        else:
            want = dt.from_any(ann.dtype) if ann.dtype is not None else None
        if want is not None and not isinstance(ann.dtype, MatrixType) and own:
            raise SimgradTypeError(f"kernel {kernel_name}: Expect element type {want} for argument {name}, but "
                                   f"get {tensor_text(own, t)}")
        if (own is not None and own != elem) or len(elem) > len(arr.shape) \
                or tuple(arr.shape[len(arr.shape) - len(elem):]) != elem:
            # never reinterpret the memory: a (2, 3) matrix element is not a 2-vector followed by more
            given = tensor_text(own, t) if own is not None else f"an array of shape {tuple(arr.shape)}"
            raise SimgradValueError(f"kernel {kernel_name}: Invalid value for argument {name} - required element "
                                    f"type: {_element_type_text(ann, elem, want or t)}, but {given} is provided")
        if want is not None and want is not t:
            raise SimgradTypeError(f"kernel {kernel_name}: Expect element type {want} for argument {name}, but get "
                                   f"{tensor_text(own if own is not None else elem, t)}")
        ndim = len(arr.shape) - len(elem)
        if ann.ndim is not None and ann.ndim != ndim:
            raise SimgradValueError(f"kernel {kernel_name}: Invalid value for argument {name} - required "
                                    f"ndim={ann.ndim}, but {ndim}d ndarray with shape {tuple(arr.shape)} is "
                                    "provided")
        grad = t.is_float and (self.with_grad(a) if grad is None else grad)
        arg = ArrayArg(name, slots.count, t, ndim, elem, ann.boundary, grad=grad)
        slots.take(arg.num_slots)
        return arg


def _element_type_text(ann: NdarrayType, elem: tuple, want) -> str:
    """The annotation's element type as Taichi names it: VectorType[2, i32], MatrixType[2,2, f32], f32."""
    mt = ann.dtype
    if isinstance(mt, MatrixType) and mt.n is not None:
        return f"VectorType[{mt.n}, {want}]" if mt.m == 0 else f"MatrixType[{mt.n},{mt.m}, {want}]"
    return tensor_text(elem, want)


class TensorParam(NdarrayParam):
    """A foreign array under `ti.types.ndarray(...)`: a torch tensor, any object with `__dlpack__`, or an
    explicit (value, gradient) pair (ti.ad.with_grad), by reference with no copy (runtime/tensors.py checks
    layout and device at each launch). Numpy arrays and ti.ndarray objects go the ndarray kind's way."""

    def key(self, a, keep: list):
        if not is_foreign(a):
            return super().key(a, keep)
        kind = "pair" if isinstance(a, GradPair) else "torch" if is_torch(a) else "dlpack"
        d = described(a)
        return (kind, array_dtype(d).name, len(d.shape), self.element_shape(d), self.with_grad(a))

    def with_grad(self, a) -> bool:
        if not is_foreign(a):
            return super().with_grad(a)
        has = isinstance(a, GradPair) or bool(getattr(a, "requires_grad", False))
        want = self.ann.needs_grad
        if want and not has:
            raise SimgradTypeError(f"kernel {self.kernel_name}: ndarray argument '{self.name}' is annotated "
                                   "needs_grad=True but has no gradient (pass a tensor that requires grad, or "
                                   "ti.ad.with_grad(value, grad))", caller_loc())
        return has if want is None else bool(want)

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        if not is_foreign(a):
            return super().bind(a, slots)
        arg = self._array_arg(described(a), slots, self.with_grad(a))
        return arg, TensorPacking(self.name, arg.slot, arg.dtype, arg.ndim, arg.ndim + len(arg.element_shape),
                                  arg.grad_slot, pair=isinstance(a, GradPair))


class ArgPackParam(Param):
    """A ti.types.argpack parameter (lang/argpack.py): each member is the parameter it would be on its own
    (scalar, matrix, struct, ndarray, nested argpack), named `pack.member`; the body sees an ArgPack of their
    values; the instantiation is keyed by the members' keys (an ndarray member's dtype and dimensions)."""

    keyed = True

    def __init__(self, name: str, ann, kernel_name: str):
        super().__init__(name, ann, kernel_name)
        self.members = {k: make_param(f"{name}.{k}", t, kernel_name) for k, t in ann.members.items()}

    @classmethod
    def accepts(cls, ann) -> bool:
        return isinstance(ann, ArgPackType)

    def _values(self, a) -> dict:
        if not isinstance(a, ArgPack) or a._type is not self.ann:
            raise SimgradTypeError(f"kernel {self.kernel_name}: argument '{self.name}' expects a value of "
                                   f"{self.ann!r}, got {type(a).__name__}", caller_loc())
        return {k: getattr(a, k) for k in self.members}

    def key(self, a, keep: list):
        return tuple(p.key(v, keep) if p.keyed else None for p, v in zip(self.members.values(),
                                                                         self._values(a).values()))

    def fingerprint(self, a, kb: KeyBuilder):
        return tuple(p.fingerprint(v, kb) if p.keyed else None for p, v in zip(self.members.values(),
                                                                               self._values(a).values()))

    def bind(self, a, slots: Slots) -> tuple[object, Packing]:
        values, packings = {}, []
        for (k, p), v in zip(self.members.items(), self._values(a).values()):
            values[k], packing = p.bind(v, slots)
            packings.append((k, packing))
        return ArgPack(self.ann, values), ArgPackPacking(self.name, packings)


# The kinds in the order they are tried; `register` puts a new one first.
KINDS: list[type[Param]] = [TemplateParam, ArgPackParam, TensorParam, NdarrayParam, MatrixParam, BuilderParam,
                            StructParam, ScalarParam]


def register(kind: type[Param]) -> type[Param]:
    """Make kernels defined from now on recognise `kind`'s annotations, before the built-in kinds (a class
    decorator; `KINDS.remove(kind)` undoes it)."""
    KINDS.insert(0, kind)
    return kind


def make_param(name: str, ann, kernel_name: str, first: bool = False) -> Param:
    """The parameter `name: ann` of kernel `kernel_name` (`first`: its first parameter)."""
    if first and name == "self" and ann is inspect.Parameter.empty:
        # a kernel method of a @ti.data_oriented class: the object is compile-time
        return TemplateParam(name, ann, kernel_name)
    for kind in KINDS:
        if kind.accepts(ann):
            return kind(name, ann, kernel_name)
    if ann is inspect.Parameter.empty:  # a TypeError, and Taichi's TaichiSyntaxError
        raise AnnotationError(f"kernel {kernel_name}: parameter '{name}' needs a type annotation "
                              "(e.g. ti.f32, ti.template(), ti.types.ndarray())")
    raise AnnotationError(f"kernel {kernel_name}: parameter '{name}' has an unsupported annotation {ann!r}")
