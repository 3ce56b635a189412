"""Fields: global, typed, n-d arrays of scalars or small matrices living in an SNode tree.

Python-scope access goes straight to the tree's memory through numpy views (no kernel launch), so
`x[i, j]` from Python costs well under a microsecond."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import (
    FieldIndexTypeError,
    SimgradError,
    SimgradNotSupportedError,
    SimgradOutOfBoundError,
    SimgradOverflowError,
    SimgradTypeError,
    TaichiRuntimeError,
    caller_loc,
)
from simgrad.ir.fieldref import FieldRef
from simgrad.lang import scope_hooks
from simgrad.lang.matrix import Matrix
from simgrad.lang.program import sync_for_host

if TYPE_CHECKING:
    from simgrad.lang.snode import AccessTerm

# Where a dense field's elements are: (tree id, constant byte offset, access terms, shape)
Layout = tuple[int, int, tuple["AccessTerm", ...], tuple[int, ...]]


def _plain_index(key: tuple, shape) -> bool:
    """Integers, one per axis, each inside the shape: an index that needs none of _norm_index's and
    _check_bounds's work."""
    return len(key) == len(shape) and all(
        type(k) is int and 0 <= k < n for k, n in zip(key, shape))


def _norm_index(key, ndim: int, name: str = "") -> tuple:
    if key is None:
        key = ()
    elif not isinstance(key, tuple):
        key = (key,)
    if len(key) != ndim:
        raise SimgradOutOfBoundError(f"field {name} has {ndim} indices, got {len(key)} (Slicing is not supported "
                                     "on ti.field)", caller_loc())
    if any(isinstance(k, (bool, np.bool_)) for k in key):  # an int 0 or 1 to Taichi; a mask to numpy
        key = tuple(int(k) if isinstance(k, (bool, np.bool_)) else k for k in key)
    return key


class Field:
    """Common base: shape, dtype, gradient, numpy interop."""

    name: str
    dtype: dt.DataType
    grad: Field | None
    dual: Field | None
    _needs_grad: bool  # ti.field(needs_grad=...): placing the field places its gradient (lang/factories.py)
    is_primal = True  # False for gradients and duals
    is_dual = False

    @property
    def _name(self) -> str:
        return self.name

    def __reduce__(self):
        from simgrad.lang.pickling import refuse_pickle

        refuse_pickle(f"field {self.name}")

    def __iter__(self):
        raise SimgradNotSupportedError("Struct for is only available in Taichi scope: iterate over a field "
                                       "inside a kernel, or over range(n) / np.ndindex(*x.shape) here", caller_loc())

    def _components(self) -> list[ScalarField]:
        raise NotImplementedError

    def __str__(self) -> str:
        """`print(x)`: the values, as Taichi prints them (str of to_numpy()); while a kernel compiles, and for a
        field not placed or released, the repr (no materialisation from a message)."""
        from simgrad.errors import compiling

        if compiling() or self.released():
            return repr(self)
        if any(c.snode is None for c in self._components()):
            return "<Field: Definition of this field is incomplete>"
        return str(self.to_numpy())  # type: ignore[attr-defined]  # every concrete field has one

    def placeable(self) -> list[Field]:
        """The fields place() puts under a node for this one (a struct field: its members)."""
        return [self]

    @property
    def shape(self) -> tuple[int, ...]:
        return self._components()[0].shape

    @property
    def ndim(self) -> int:
        return len(self.shape)

    _auto_name = False

    def adopt_name(self, name: str) -> None:
        """Give an unnamed field the name of the variable the user refers to it by (for messages)."""
        if not self._auto_name:
            return
        self._auto_name = False
        self.name = name
        comps = self._components()
        if len(comps) > 1:
            for k, c in enumerate(comps):
                c.name = f"{name}[{k}]"
        elif comps[0] is not self:
            comps[0].name = name
        if self.grad is not None:
            self.grad._auto_name = True
            self.grad.adopt_name(name + ".grad")

    def _set_offset(self, offset):
        offset = (offset,) if isinstance(offset, int) else tuple(offset)
        for c in self._components():
            c.offset = offset
        if self.grad is not None:
            self.grad._set_offset(offset)

    def snode_tree(self):
        return self._components()[0].snode.tree

    def released(self) -> bool:
        """Whether the program this field was placed in was dropped by ti.reset() or a later ti.init(), or its
        SNode tree destroyed (tree.destroy())."""
        node = self._components()[0].snode
        return node is not None and node.tree is not None and (node.tree.program.released or node.tree.destroyed)

    def check_alive(self, loc=None) -> None:
        if not self.released():
            return
        if self._components()[0].snode.tree.destroyed:
            raise TaichiRuntimeError(f"field {self.name} belongs to an SNode tree that was destroyed "
                                     "(tree.destroy())", loc or caller_loc())
        raise SimgradError(f"field {self.name} belongs to a program that ti.reset() or a later ti.init() "
                           "released: create the fields again after ti.init()", loc or caller_loc())

    def _ensure(self) -> None:
        comps = self._components()
        for c in comps:
            if c.snode is None:
                raise _unplaced_error(c)
        self.check_alive()
        for c in comps:
            if c.view is None and c.gather is None:
                c.snode.tree.materialize()

    def parent(self, n: int = 1):
        """The n-th SNode above this field's place node (Taichi's x.parent(n) == x.snode.parent(n))."""
        return self._components()[0].snode.parent(n)

    @property
    def snode(self):
        return self._components()[0].snode

    def append(self, value):
        """`l.append(v)` in a kernel, for a 1-D field under a dynamic node (ti.append(l.parent(), [], v))."""
        from simgrad.lang.sparse import append

        return append(self.parent(), [], value)

    def length(self):
        """`l.length()` in a kernel, for a 1-D field under a dynamic node."""
        from simgrad.lang.sparse import length

        return length(self.parent(), [])

    def deactivate(self):
        """`l.deactivate()` in a kernel: empty a 1-D field's dynamic list."""
        from simgrad.lang.sparse import deactivate

        return deactivate(self.parent(), [])


class ScalarField(Field):
    def __init__(self, dtype, name: str = "field"):
        self.dtype = dt.from_any(dtype)
        self.name = name
        self.snode = None
        self.grad = None
        self.dual = None
        self.offset: tuple[int, ...] | None = None
        self._view: np.ndarray | None = None  # strided numpy view of the elements, when one exists
        self.gather: np.ndarray | None = None  # flat element indices, for layouts that are not strided
        self._flat: np.ndarray | None = None
        self.layout: Layout | None = None  # set when its tree is materialised
        self._shape: tuple[int, ...] | None = None
        self.is_primal = True
        self.is_dual = False
        self.sparse = False  # under a pointer/bitmasked/dynamic SNode: Python scope goes through kernels
        self.quant_type = None  # a ti.types.quant type (lang/quant.py); dtype is then its compute type

    def _components(self):
        return [self]

    def ref(self) -> FieldRef:
        """The IR's record of this field (the same object while name and layout stay, so analyses can key
        on its identity within a kernel)."""
        assert self.layout is not None, f"field {self.name} is not materialised"
        g, d = self.grad, getattr(self, "dual", None)
        grad = g.ref() if isinstance(g, ScalarField) and g.layout is not None else None
        dual = d.ref() if isinstance(d, ScalarField) and d.layout is not None else None
        key = (self.name, self.layout, self.offset, id(grad), id(dual))
        cached = getattr(self, "_ref", None)
        if cached is None or cached[0] != key:
            node = self._snode
            levels = node.levels() if node.has_sparse_path() else ()
            value_offset = node.offset_in_parent if levels else 0
            quant = None
            if self.quant_type is not None:
                from simgrad.lang.quant import slot_of

                quant = slot_of(self)
                if levels and node._parent.kind == "bit_struct":  # the cell's offset in its parent's cell
                    value_offset += node._parent.offset_in_parent
            ref = FieldRef(self.name, self.dtype, self.layout, self.offset, grad, owner=self, dual=dual,
                           levels=levels, value_offset=value_offset, quant=quant)
            self._ref = cached = (key, ref)
        return cached[1]

    # the field's memory for Python scope: reached only through these two, which first wait for the kernels an
    # asynchronous device still runs (lang/program.py sync_for_host), as Taichi's field access synchronizes
    @property
    def view(self) -> np.ndarray | None:
        sync_for_host()
        return self._view

    @view.setter
    def view(self, v: np.ndarray | None) -> None:
        self._view = v

    @property
    def flat(self) -> np.ndarray | None:
        sync_for_host()
        return self._flat

    @flat.setter
    def flat(self, v: np.ndarray | None) -> None:
        self._flat = v

    @property
    def snode(self):  # type: ignore[override]
        return self._snode

    @snode.setter
    def snode(self, node):
        self._snode = node

    @property
    def shape(self) -> tuple[int, ...]:
        if self._shape is None:
            if self._snode is None:
                raise _unplaced_error(self)
            self._shape = self._snode.access_terms()[2]
        return self._shape

    def _bind(self) -> None:
        """Called when the tree is materialised: build the numpy view of this field's elements."""
        node = self._snode
        const, terms, shape = node.access_terms()
        tree = node.tree
        self._shape = shape
        if node.has_sparse_path():  # no view: Python scope goes through kernels (lang/scope_hooks.py)
            self.layout = (tree.id, 0, (), shape)
            self.sparse = True
            return
        self.layout = (tree.id, const, terms, shape)
        if self.quant_type is not None:  # bits of a packed cell: Python scope goes through kernels too
            self.sparse = True
            return
        buf = tree.buffer
        isz = self.dtype.nbytes
        if all(t.divisor == 1 and t.modulus == 0 for t in terms) and len(terms) == len(shape):
            strides = [0] * len(shape)
            for t in terms:
                strides[t.axis] = t.stride
            self.view = np.ndarray(shape, self.dtype.np, buffer=buf, offset=const, strides=strides)
        else:
            offs = np.full(shape, const, dtype=np.int64)
            idx: np.ndarray | list = np.indices(shape, dtype=np.int64) if shape else []
            for t in terms:
                digit = idx[t.axis] // t.divisor
                if t.modulus:
                    digit = digit % t.modulus
                offs = offs + digit * t.stride
            self.flat = buf.view(self.dtype.np)
            self.gather = offs // isz

    # -- Python scope ------------------------------------------------------------------------
    def _shift(self, key):
        if self.offset:
            return tuple(k - o for k, o in zip(key, self.offset))
        return key

    def _unshift(self, key):
        """Back to the user's indices (kernels take those; the field's offset is theirs to subtract)."""
        if self.offset:
            return tuple(k + o for k, o in zip(key, self.offset))
        return key

    def _materialised(self) -> bool:
        """Its memory can be read directly: a strided view or a gather index (both dropped when its program is
        released or its tree destroyed; sparse and quant fields have neither)."""
        return self._view is not None or self.gather is not None

    def _direct(self, key) -> bool:
        """Whether `f[key]` needs none of the general index work: the memory is there, no offset, and the key is
        integers, one per axis, inside the shape (`f[i]`, `f[i, j]`: the common Python-scope access)."""
        if self.offset or not self._materialised():
            return False
        shape = self._shape
        assert shape is not None  # (known once materialised)
        if type(key) is int:
            return len(shape) == 1 and 0 <= key < shape[0]
        return type(key) is tuple and _plain_index(key, shape)

    def __getitem__(self, key):
        view = self.view
        if view is None and self.gather is None:
            self._ensure()
            view = self._view
        source = view if view is not None else self.gather
        if source is not None and not self.offset and (type(key) is tuple or type(key) is int):
            # `f[i]`, `f[i, j]`: numpy's item() checks the indices' types and upper bounds (0.3 us instead of 1.0);
            # what it refuses (or a negative index) takes the general path below
            index = key if type(key) is tuple else (key,)
            try:
                if len(index) == source.ndim and min(index) >= 0:
                    v = view.item(index) if view is not None else self._flat.item(self.gather.item(index))
                    return int(v) if self.dtype is dt.u1 else v
            except (TypeError, IndexError, ValueError):
                pass
        key = self._shift(_norm_index(key, len(self.shape), self.name))
        _check_bounds(key, self.shape, self.name)
        if self.sparse:
            return scope_hooks.sparse.get(self, self._unshift(key))
        if view is not None:
            v = view[key].item()
        else:
            flat, gather = self._indirect()
            v = flat[gather[key]].item()
        return int(v) if self.dtype is dt.u1 else v  # Taichi reads a u1 as an int, 0 or 1

    def __setitem__(self, key, value):
        view = self.view
        if view is None and self.gather is None:
            self._ensure()
            view = self._view
        if self._direct(key):
            _check_value(value, self.dtype, self.name)
            if view is not None:
                view[key] = value
            else:
                self._flat[self.gather[key]] = value
            return
        key = self._shift(_norm_index(key, len(self.shape), self.name))
        _check_bounds(key, self.shape, self.name)
        if self.quant_type is not None:  # kept to its bits whatever the value, as in kernels and Taichi
            return scope_hooks.sparse.set(self, self._unshift(key), _wrapped(value, self.dtype))
        _check_value(value, self.dtype, self.name)
        if self.sparse:
            return scope_hooks.sparse.set(self, self._unshift(key), value)
        if view is not None:
            view[key] = value
        else:
            flat, gather = self._indirect()
            flat[gather[key]] = value

    def to_numpy(self, dtype=None) -> np.ndarray:
        self._ensure()
        if self.sparse:
            out = scope_hooks.sparse.to_numpy(self)
            return out.astype(dtype) if dtype is not None else out
        if self.view is not None:
            out = np.array(self.view)
        else:
            flat, gather = self._indirect()
            out = flat[gather]
        return out.astype(dtype) if dtype is not None else out

    def from_numpy(self, arr) -> None:
        self._ensure()
        arr = np.asarray(arr)
        if arr.shape != self.shape:
            raise ValueError(f"from_numpy: field {self.name} has shape {self.shape}, array has {arr.shape}")
        if self.sparse:
            return scope_hooks.sparse.from_numpy(self, arr)
        if self.view is not None:
            self.view[...] = arr
        else:
            flat, gather = self._indirect()
            flat[gather] = arr

    def fill(self, value) -> None:
        if _in_kernel():
            return _kernel_fill(self, value)
        self._ensure()
        _check_value(value, self.dtype, self.name)
        if self.sparse:
            return scope_hooks.sparse.fill(self, value)
        if self.view is not None:
            self.view[...] = value
        else:
            flat, gather = self._indirect()
            flat[gather] = value

    def _indirect(self) -> tuple[np.ndarray, np.ndarray]:
        """(flat buffer, element index array) of a layout without a strided numpy view."""
        assert self.flat is not None and self.gather is not None, f"field {self.name} is not materialised"
        return self.flat, self.gather

    def copy_from(self, other: ScalarField) -> None:
        _check_copy_source(self, other)
        self.from_numpy(other.to_numpy())

    def to_torch(self, device=None):
        import torch

        return torch.from_numpy(self.to_numpy()).to(device) if device else torch.from_numpy(self.to_numpy())

    def from_torch(self, t) -> None:
        self.from_numpy(t.detach().cpu().numpy())

    def __repr__(self) -> str:
        return f"<ScalarField {self.name} {self.dtype} shape={self.shape if self._snode else '?'}>"


def _check_copy_source(dst: Field, src) -> None:
    if not isinstance(src, Field):
        raise SimgradTypeError(f"copy_from: field {dst.name} copies from another field, got "
                               f"{type(src).__name__} (use from_numpy for arrays)", caller_loc())


def _unplaced_error(c: ScalarField) -> SimgradError:
    """Using a field that is not placed: while a kernel compiles, Taichi's TaichiCompilationError."""
    from simgrad.errors import TaichiCompilationError, compiling

    return (TaichiCompilationError if compiling() else SimgradError)(_unplaced_message(c), caller_loc())


def _unplaced_message(c: ScalarField) -> str:
    if c.is_dual:
        return (f"field {c.name[:-5]} has no dual: {c.name} exists only when the field is created with "
                f"needs_dual=True (or placed and followed by ti.root.lazy_dual())")
    if not c.is_primal:
        primal = c.name[:-5] if c.name.endswith(".grad") else c.name
        return (f"Gradient {c.name} has not been placed, check whether `needs_grad=True`: field {primal} has no "
                f"gradient: {c.name} exists only when the field is created with "
                f"needs_grad=True (or placed and followed by ti.root.lazy_grad())")
    return f"field {c.name} is not placed in any SNode tree (call ti.root...place())"


def _check_bounds(key, shape, name):
    """Negative indices are out of bounds as in kernels (and with an offset they would silently alias)."""
    for k, n in zip(key, shape):
        if not isinstance(k, (int, np.integer)):
            raise FieldIndexTypeError(f"field {name} is indexed with {k!r} ({type(k).__name__}); Python-scope "
                                      f"indices must be integers (Detected illegal element of type: "
                                      f"{type(k).__name__}. Please be aware that slicing a ti.field is not "
                                      f"supported so far.)", caller_loc())
        if not 0 <= k < n:  # an IndexError, and the assertion failure Taichi's debug mode reports
            raise SimgradOutOfBoundError(f"index {k} out of bounds for field {name} of shape {shape}", caller_loc())


def _wrapped(value, dtype: dt.DataType):
    """An integer value converted to an integer type the way a kernel's cast does (wrapping)."""
    if dtype.is_float or isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        return value
    return np.array(int(value) & ((1 << dtype.bits) - 1), dtype=np.uint64).astype(dtype.np).item()


def _check_value(value, dtype: dt.DataType, name: str) -> None:
    """An integer that does not fit an integer field is refused, not wrapped (numpy would raise its own
    OverflowError for a Python int, and wrap a numpy one silently)."""
    if dtype.is_float or dtype is dt.u1 or isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        return  # a u1 takes any integer as its truth value (as Taichi)
    info = np.iinfo(dtype.np)
    if not info.min <= int(value) <= info.max:
        raise SimgradOverflowError(f"value {int(value)} does not fit field {name} of type {dtype} "
                                   f"(range [{info.min}, {info.max}])", caller_loc())


class MatrixField(Field):
    """A field of n x m matrices (m == 0: n-vectors), stored as n*m scalar component fields."""

    def __init__(self, n: int, m: int, dtype, name: str = "field", ndim: int | None = None):
        self.n, self.ncols = n, m  # ncols 0: a vector field
        self.dtype = dt.from_any(dtype)
        self.name = name
        self.comps = [ScalarField(self.dtype, f"{name}[{c}]") for c in range(n * max(m, 1))]
        self.grad = None
        self.dual = None

    @property
    def m(self) -> int:
        """Columns as Taichi counts them: 1 for a vector field."""
        return max(self.ncols, 1)

    @property
    def is_vector(self) -> bool:
        return self.ncols == 0

    @property
    def entry_shape(self) -> tuple[int, ...]:
        return (self.n,) if self.ncols == 0 else (self.n, self.ncols)

    def _components(self):
        return self.comps

    def get_scalar_field(self, *indices: int) -> ScalarField:
        """The scalar field of one entry (`v.get_scalar_field(i)`, `m.get_scalar_field(i, j)`), to place the
        entries of a vector/matrix field separately (SoA)."""
        want = 1 if self.ncols == 0 else 2
        if len(indices) != want or not all(isinstance(k, (int, np.integer)) for k in indices):
            raise SimgradError(f"get_scalar_field of {self.name} takes {want} integer index(es), got {indices!r}",
                               caller_loc())
        r = int(indices[0])
        c = int(indices[1]) if want == 2 else 0
        if not (0 <= r < self.n and 0 <= c < max(self.ncols, 1)):
            raise SimgradError(f"get_scalar_field{indices!r} is outside the {self.entry_shape} entries of "
                               f"{self.name}", caller_loc())
        return self.comps[r * max(self.ncols, 1) + c]

    def _stacked(self, arrays: list[np.ndarray]) -> np.ndarray:
        a = np.stack(arrays, axis=-1)
        return a.reshape(a.shape[:-1] + self.entry_shape)

    def _packed_view(self) -> np.ndarray | None:
        """One strided view of every entry when the components sit next to each other in each cell (AoS, as
        `place(v)` lays a vector out): copying it reads memory once instead of once per component."""
        for c in self.comps:
            c._ensure()
        views: list[np.ndarray] = [c.view for c in self.comps if c.view is not None]
        if len(views) != len(self.comps) or len({v.strides for v in views}) != 1:
            return None
        size = self.dtype.np.itemsize
        base = views[0].__array_interface__["data"][0]
        if any(v.__array_interface__["data"][0] != base + k * size for k, v in enumerate(views)):
            return None
        v0 = views[0]
        packed = np.lib.stride_tricks.as_strided(v0, shape=v0.shape + (len(views),), strides=v0.strides + (size,),
                                                 writeable=True)
        return packed.reshape(v0.shape + self.entry_shape) if len(self.entry_shape) == 1 else \
            np.lib.stride_tricks.as_strided(v0, shape=v0.shape + self.entry_shape,
                                            strides=v0.strides + (self.entry_shape[1] * size, size), writeable=True)

    def to_numpy(self, dtype=None, keep_dims=False) -> np.ndarray:
        packed = self._packed_view()
        out = np.array(packed) if packed is not None else self._stacked([c.to_numpy() for c in self.comps])
        if keep_dims and len(self.entry_shape) == 1:  # a vector as the (n, 1) column Taichi keeps
            out = out.reshape(out.shape + (1,))
        return out.astype(dtype) if dtype is not None else out

    def from_numpy(self, arr) -> None:
        arr = np.asarray(arr)
        want = self.shape + self.entry_shape
        if len(self.entry_shape) == 1 and arr.shape in (self.shape + self.entry_shape + (1,),
                                                       self.shape + (1,) + self.entry_shape):
            arr = arr.reshape(want)  # a vector given as a column or a row (Taichi takes both)
        if arr.shape != want:
            raise ValueError(f"from_numpy: field {self.name} has shape {want}, array has {arr.shape}")
        packed = self._packed_view()
        if packed is not None:
            packed[...] = arr
            return
        flat = arr.reshape(self.shape + (-1,))
        for c, comp in enumerate(self.comps):
            comp.from_numpy(flat[..., c])

    def fill(self, value) -> None:
        if _in_kernel():
            return _kernel_fill(self, value)
        entries = self._entries(value)
        if len(np.unique(entries.view(f"u{entries.itemsize}"))) == 1:  # one value, bit for bit (0.0 is not -0.0)
            packed = self._packed_view()
            if packed is not None and packed.flags.c_contiguous:  # the cells hold nothing else: one pass
                packed.reshape(-1)[...] = entries[0]
                return
        for comp, v in zip(self.comps, entries):
            comp.fill(v)

    def _entries(self, value) -> np.ndarray:
        """`value` (a scalar, nested list, Matrix or array) broadcast to one entry per component."""
        raw = _as_array(value)
        if not self.dtype.is_float:
            for v in np.asarray(raw, dtype=object).reshape(-1):
                _check_value(v, self.dtype, self.name)
        return np.broadcast_to(np.asarray(raw, dtype=self.dtype.np), self.entry_shape).reshape(-1)

    def copy_from(self, other: MatrixField) -> None:
        _check_copy_source(self, other)
        self.from_numpy(other.to_numpy())

    def __getitem__(self, key):
        self._check_key(key)
        return FieldElement(self, key)

    def _check_key(self, key) -> None:
        """Index errors name this field, not its first component."""
        if self.comps[0].view is None:
            self._ensure()
        key = self.comps[0]._shift(_norm_index(key, len(self.shape), self.name))
        _check_bounds(key, self.shape, self.name)

    def __setitem__(self, key, value):
        self._check_key(key)
        for comp, v in zip(self.comps, self._entries(value)):
            comp[key] = v

    def to_torch(self, device=None):
        import torch

        t = torch.from_numpy(self.to_numpy())
        return t.to(device) if device else t

    def from_torch(self, t) -> None:
        self.from_numpy(t.detach().cpu().numpy())

    def __repr__(self) -> str:
        return f"<MatrixField {self.name} {self.entry_shape} {self.dtype}>"


def _as_array(value):
    if hasattr(value, "to_numpy"):
        return value.to_numpy()
    return value


def _in_kernel() -> bool:
    from simgrad.ir import context

    return context.in_kernel()


def _kernel_fill(field: Field, value) -> None:
    """`x.fill(v)` inside a kernel: a loop over every element at each launch (v may be a run-time value),
    emitted by the compiler on the context stack."""
    from simgrad.ir import context

    context.current().emit_fill(field, value)


class FieldElement(Matrix):
    """`f[i]` of a vector/matrix field in Python scope, as Taichi has it: a live view of the element.
    Reading it reads the field now; element and swizzle assignment (`v[None][0] -= lr * g`, `m[i][r, c] = x`,
    `v[None].y = 1`) write through to the field, so no write is silently dropped."""

    __slots__ = ("_field", "_key")

    def __init__(self, field, key):
        object.__setattr__(self, "_field", field)
        object.__setattr__(self, "_key", key)
        object.__setattr__(self, "n", field.n)
        object.__setattr__(self, "m", field.ncols)

    @property  # type: ignore[override]
    def entries(self):
        return [c[self._key] for c in self._field.comps]

    def _one_index(self, key) -> None:
        if self.m and not isinstance(key, (tuple, slice)):
            raise IndexError(f"an element of the matrix field {self._field.name} takes 2 indices "
                             f"([r, c]), got 1", )

    def __getitem__(self, key):
        self._one_index(key)
        return Matrix.__getitem__(self, key)

    def __setitem__(self, key, value):
        self._one_index(key)
        idx = self._flat_index(key)
        if idx is None:
            raise IndexError(f"{key!r} is not an element index of the field {self._field.name}")
        self._field.comps[idx][self._key] = value

    def __setattr__(self, name, value):
        idx = self._swizzle(name)
        vals = [value] if len(idx) == 1 else list(value)
        if len(vals) != len(idx):
            raise ValueError(f"swizzle '{name}' takes {len(idx)} values, got {len(vals)}")
        for i, v in zip(idx, vals):
            self._field.comps[i][self._key] = v

    def fill(self, v) -> None:
        for c in self._field.comps:
            c[self._key] = v


def rescale_index(a, b, I):  # noqa: E741
    """The index I of field (or SNode) `a` scaled to `b`'s shape, axis by axis (a coarser `b` divides, a
    finer one multiplies), as Taichi's ti.rescale_index for multigrid and block-sparse codes."""
    shape_a, shape_b = tuple(a.shape), tuple(b.shape)
    entries = list(I) if isinstance(I, (list, tuple)) else list(I.entries)
    out = list(entries)
    for k in range(min(len(entries), len(shape_a), len(shape_b))):
        if shape_a[k] > shape_b[k]:
            out[k] = entries[k] // (shape_a[k] // shape_b[k])
        elif shape_a[k] < shape_b[k]:
            out[k] = entries[k] * (shape_b[k] // shape_a[k])
    return Matrix(out)
