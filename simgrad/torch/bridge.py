"""`@simgrad.torch.function`: a Python function over torch tensors that launches simgrad kernels (the tensors as
`ti.types.ndarray()` arguments) becomes one node of torch's autograd graph.

Calling it runs the function under a ti.ad.Tape (lang/tape.py: the same recorder, its in-place rollback and
access checks), with the inputs detached so kernels never touch the user's `.grad`. backward() replays the
recorded adjoints in reverse with every tensor argument paired with a fresh gradient buffer
(ti.ad.with_grad): the outputs' buffers hold the incoming gradients, the inputs' buffers are returned to
torch, which accumulates them (two calls in one graph, a tensor used twice). Buffers are made per storage,
so a view of an input passed to a kernel writes into the input's gradient.

What the bridge cannot differentiate is refused at the user's line instead of giving a silently wrong
gradient:
- torch operations inside the function that compute from an input (they run with autograd off): only
  views, metadata and `*_like` allocations of inputs are allowed; compute outside the function;
- a kernel writing into an input tensor (torch would not see the in-place change), refused before it runs;
- ti.ad.grad_replaced units and ti.ad.checkpoint (they replay launches themselves, unpaired);
- fields: the function may read fields (parameters: their gradients accumulate into `field.grad`, outside
  torch) and keep its own temporaries in fields (saved at the end of the call and restored for its
  backward, so a second call may overwrite them), but it may not read a field another pending call wrote
  (torch cannot order the two backwards through a field), nor carry values through a float field without a
  gradient (its adjoint would be zero)."""

from __future__ import annotations

import functools
import weakref

import torch
from torch.overrides import TorchFunctionMode

from simgrad.errors import GradientError, SimgradNotSupportedError, SimgradTypeError, caller_loc
from simgrad.ir.fieldref import ArrayRef, FieldRef
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.lang import ad_hooks
from simgrad.lang.tape import Tape
from simgrad.runtime.tensors import GradPair


def function(fn) -> Function:
    """`@simgrad.torch.function`: see the module's docstring."""
    return Function(fn)


class Function:
    """A Python function bridged into torch autograd; calling it returns its tensor (or tuple of tensors)."""

    def __init__(self, fn):
        self.fn = fn
        self.name = getattr(fn, "__name__", "function")
        functools.update_wrapper(self, fn)

    def __call__(self, *args, **kwargs):
        if any(isinstance(v, torch.Tensor) for v in kwargs.values()):
            raise SimgradTypeError(f"simgrad.torch.function {self.name}: pass tensors positionally (keyword "
                                   "arguments are passed through as constants)", caller_loc())
        positions = [k for k, a in enumerate(args) if isinstance(a, torch.Tensor)]
        tensors = [args[k] for k in positions]
        if not torch.is_grad_enabled() or not any(t.requires_grad for t in tensors):
            # no graph to join: a plain call, on detached tensors (kernels leave every .grad alone)
            return self.fn(*_replaced(args, positions, [t.detach() for t in tensors]), **kwargs)
        call = _Call(self, args, kwargs, positions)
        outs = _Node.apply(call, *tensors)
        return outs[0] if call.single else outs


def _replaced(args: tuple, positions: list, values: list) -> tuple:
    out = list(args)
    for k, v in zip(positions, values):
        out[k] = v
    return tuple(out)


class _Node(torch.autograd.Function):
    @staticmethod
    def forward(ctx, call, *tensors):
        outs = call.forward(tensors)
        ctx.call = call
        ctx.mark_non_differentiable(*[o for o in outs if not o.is_floating_point()])
        ctx.save_for_backward(*tensors)  # torch's version check: an input changed in place before backward
        return outs

    @staticmethod
    def backward(ctx, *grads):
        ctx.saved_tensors  # noqa: B018 (raises when an input was modified in place since forward)
        return (None, *ctx.call.backward(grads))


def _storage(t: torch.Tensor) -> int:
    return t.untyped_storage().data_ptr() if t.numel() else 0


class _Call:
    """One call of a bridged function: its tape, tensors, the fields it owns, and its backward."""

    def __init__(self, f: Function, args: tuple, kwargs: dict, positions: list):
        self.f, self.args, self.kwargs, self.positions = f, args, kwargs, positions
        self.single = False
        self.done = False  # whether its backward ran (then its fields are no longer pending)

    def forward(self, tensors) -> tuple:
        self.inputs = [t.detach() for t in tensors]
        self.tape = tape = _CallTape(self)
        watch = _Watch(self.f.name, {_storage(t) for t in self.inputs if t.is_floating_point()} - {0})
        with tape, watch:
            out = self.f.fn(*_replaced(self.args, self.positions, self.inputs), **self.kwargs)
        self.single = isinstance(out, torch.Tensor)
        outs = (out,) if self.single else out
        if not isinstance(outs, tuple) or not outs or not all(isinstance(o, torch.Tensor) for o in outs):
            raise SimgradTypeError(f"simgrad.torch.function {self.f.name} must return a tensor or a tuple of "
                                   f"tensors, got {type(out).__name__}", caller_loc())
        self.outputs = outs
        self.fields = tape.owned_fields()
        return tuple(o for o in outs)

    def backward(self, grads) -> list:
        tape = self.tape
        buffers: dict = {}  # storage -> gradient buffer (a flat tensor addressed like the storage)
        entries = [(fn, tuple(self._paired(a, buffers) for a in args)) for fn, args in tape.entries]
        for o, g in zip(self.outputs, grads):
            if g is not None and o.is_floating_point():
                self._grad_view(o, buffers).add_(g)
        now = [(f, f.to_numpy()) for f, _ in self.fields]
        try:
            for f, values in self.fields:  # the fields the call wrote, as it left them
                f.from_numpy(values)
                if f.grad is not None and getattr(f.grad, "snode", 1) is not None:
                    f.grad.fill(0)
            recorded = tape.entries
            tape.entries, tape.gradient_evaluated = entries, False
            outer, ad_hooks.recorder = ad_hooks.recorder, None
            try:
                tape.grad()
            finally:
                ad_hooks.recorder = outer
                tape.entries = recorded
        finally:
            for f, values in now:
                f.from_numpy(values)
        self.done = True
        out: list = []
        for t in self.inputs:
            if not (t.is_floating_point() and _storage(t) in buffers):
                out.append(None)
                continue
            # an input sharing memory with an earlier one (f(x, x), overlapping views) reports only what the
            # earlier ones have not: torch adds the gradients of both uses
            view = self._grad_view(t, buffers)
            out.append(view.clone())
            view.zero_()
        return out

    def _grad_view(self, t: torch.Tensor, buffers: dict) -> torch.Tensor:
        """The gradient of tensor `t`: its place in the buffer of its storage."""
        key = _storage(t)
        buf = buffers.get(key)
        if buf is None:
            n = t.untyped_storage().nbytes() // t.element_size()
            buf = buffers[key] = torch.zeros(n, dtype=t.dtype, device=t.device)
        elif buf.dtype != t.dtype:
            raise GradientError(f"simgrad.torch.function {self.f.name}: one storage is passed to kernels as "
                                f"{buf.dtype} and {t.dtype}; gradients cannot be paired")
        return buf.as_strided(t.shape, t.stride(), t.storage_offset())

    def _paired(self, a, buffers: dict):
        if isinstance(a, torch.Tensor) and a.is_floating_point() and a.numel():
            # detached: an output is part of the graph by now, and kernels must not give it a .grad
            return GradPair(a.detach(), self._grad_view(a, buffers))
        return a


# -- what the function may do with its inputs -----------------------------------------------------------
# what reads no values: properties (shape, dtype, device, requires_grad, grad), layout queries, allocations
_METADATA = {"__get__", "data_ptr", "is_contiguous", "dim", "size", "stride", "numel", "element_size",
             "untyped_storage", "storage_offset", "is_floating_point", "requires_grad_", "__len__", "detach"}
_READS_VALUES = {"numpy", "tolist", "item", "__float__", "__int__", "__index__", "__bool__", "__array__"}


def _flat(x):
    if isinstance(x, (list, tuple)):
        for v in x:
            yield from _flat(v)
    elif isinstance(x, dict):
        for v in x.values():
            yield from _flat(v)
    else:
        yield x


class _Watch(TorchFunctionMode):
    """While the function runs: torch operations that compute from an input's values are refused (autograd
    is off inside a node's forward, so their gradient would be lost)."""

    def __init__(self, name: str, storages: set):
        super().__init__()
        self.name, self.storages = name, storages

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        name = getattr(func, "__name__", "")
        if name in _METADATA or name.endswith("_like") or name.startswith("new_") or not self.storages:
            return out  # the launcher's own reads (shape, dtype, data_ptr) take this path
        if not any(isinstance(a, torch.Tensor) and a.numel() and _storage(a) in self.storages
                   for a in _flat((args, kwargs))):
            return out
        name = name or str(func)
        in_place = (name.endswith("_") and not name.endswith("__")) or name == "__setitem__" or \
            (name.startswith("__i") and name.endswith("__") and name not in ("__index__", "__int__"))
        bad = in_place or name in _READS_VALUES or any(
            isinstance(o, torch.Tensor) and o.numel() and _storage(o) not in self.storages for o in _flat(out))
        if bad:
            raise GradientError(f"simgrad.torch.function {self.name}: torch operation '{name}' on an input runs "
                                "inside the bridged function, where autograd is off: its gradient would be lost. "
                                "Do torch computations outside the function and pass the results in (views, "
                                "shapes and *_like allocations of inputs are fine)", caller_loc())
        return out


# -- fields the function touches ------------------------------------------------------------------------
_LAST_WRITER: dict = {}  # id(field component) -> (weakref to the _Call that wrote it last, function name)


def _field_accesses(kernel, args):
    """(fields read, fields written) by one recorded launch, in IR order: lists of (FieldRef, loc); and the
    arguments it writes into ({argument index: location of a write})."""
    instance = getattr(kernel, "instance", None)
    if instance is None:
        return [], [], {}
    inst = instance(args)
    cached = getattr(inst, "_bridge_accesses", None)  # one walk per instance, as the Tape's in-place fields
    if cached is not None:
        return cached
    reads: list = []
    writes: list = []
    arrays: dict = {}  # index of an argument the kernel writes into -> the location of a write
    slots = {p.slot: k for k, p in enumerate(inst.launcher.params) if hasattr(p, "grad_slot")}
    for s in walk(inst.ir.body):
        if s.op in (Op.GLOBAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.GLOBAL_PTR:
            t = s.operands[0].attrs["target"]
            if isinstance(t, ArrayRef) and t.slot in slots:
                arrays.setdefault(slots[t.slot], s.loc)
        if s.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.GLOBAL_PTR:
            t = s.operands[0].attrs["target"]
            if isinstance(t, FieldRef) and t.owner is not None:
                (reads if s.op is Op.GLOBAL_LOAD or s.op is Op.ATOMIC else writes).append((t, s.loc))
                if s.op is Op.ATOMIC:
                    writes.append((t, s.loc))
    inst._bridge_accesses = (reads, writes, arrays)
    return reads, writes, arrays


class _CallTape(Tape):
    """The call's Tape: before each launch is recorded (and run), what torch could not see is refused (see the
    module's docstring); it remembers the fields the call wrote."""

    def __init__(self, call: _Call):
        super().__init__(clear_gradients=False)
        self.call = call
        self.written: dict = {}  # id(field component) -> the component, as the call's launches write them
        self.inputs = {_storage(t) for t in call.inputs if t.numel()}

    def _record(self, kernel, args) -> None:
        self._check(kernel, args)
        super()._record(kernel, args)

    def insert(self, fn, args) -> None:
        raise SimgradNotSupportedError(f"simgrad.torch.function {self.call.f.name}: ti.ad.grad_replaced functions "
                                       "and ti.ad.checkpoint replay their launches themselves, where the bridge "
                                       "cannot give tensor arguments their gradient buffers; call them outside a "
                                       "bridged function (under a ti.ad.Tape)", caller_loc())

    def _check(self, kernel, args) -> None:
        call, written = self.call, self.written
        reads, writes, arrays = _field_accesses(kernel, args)
        for k, loc in arrays.items():
            a = args[k] if k < len(args) else None
            if isinstance(a, torch.Tensor) and a.numel() and _storage(a) in self.inputs:
                raise GradientError(f"simgrad.torch.function {call.f.name}: kernel {kernel.name} writes into an "
                                    f"input tensor (argument '{kernel.params[k].name}'): torch does not see that "
                                    "in-place change, and the gradient of what it overwrote would be wrong. "
                                    "Allocate outputs inside the function (torch.empty_like(x))", loc)
        for t, loc in reads:
            f = t.owner
            if id(f) in written:
                if t.dtype.is_float and t.grad is None:
                    raise GradientError(f"simgrad.torch.function {call.f.name}: field '{t.name}' carries values "
                                        f"between kernels (written, then read by {kernel.name}) but has no "
                                        "gradient, so gradients through it would be lost: create it with "
                                        "needs_grad=True, or use a tensor", loc)
                continue
            writer = _LAST_WRITER.get(id(f))
            other = writer[0]() if writer is not None else None
            if writer is not None and other is not None and other is not call and not other.done:
                raise GradientError(f"simgrad.torch.function {call.f.name}: kernel {kernel.name} reads field "
                                    f"'{t.name}', which a pending call of {writer[1]} wrote: torch cannot see that "
                                    "dependency, so the gradient through the field would be lost. Return the "
                                    "state as a tensor and pass it in (f.to_torch() / a ti.types.ndarray() "
                                    "argument)", loc)
        for t, _ in writes:
            written[id(t.owner)] = t.owner

    def owned_fields(self) -> list:
        """The fields the call wrote, with their values now (restored for its backward); they are the call's
        until its backward has run."""
        for key in self.written:
            _LAST_WRITER[key] = (weakref.ref(self.call), self.call.f.name)
        return [(f, f.to_numpy()) for f in self.written.values()]
