"""The global data access rules of differentiable kernels (DiffTaichi): once a field element has been
read, it must not be overwritten, or the adjoint (which replays the forward reads) sees a different
value and silently returns a wrong gradient.

At compile time, when a kernel's adjoint is built, a store to exactly the element the same kernel read
(same field, same index values in the IR) is an error. The run-time check (what the Tape fingerprints)
is lang-level: lang/tape.py.
"""

from __future__ import annotations

from simgrad.errors import GradientError, Loc
from simgrad.ir.fieldref import ArrayRef, FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, offset_form, walk
from simgrad.ir.ops import Op


def differentiable(target) -> bool:
    """A field with a placed gradient (what the Tape's run-time checks watch)."""
    return isinstance(target, FieldRef) and target.dtype.is_float and target.grad is not None


def _has_adjoint(target) -> bool:
    return isinstance(target, (FieldRef, ArrayRef)) and target.dtype.is_float and target.grad is not None


def user_name(target) -> str:
    return target.name.split("[")[0]


def _element(ptr: Stmt) -> tuple:
    """Which element a GLOBAL_PTR names: its target and index values (not the byte offset lowering adds)."""
    indices = ptr.operands[:-1] if ptr.attrs.get("lowered") else ptr.operands
    return id(ptr.attrs["target"]), tuple(id(o) for o in indices)


def _writes_global(s: Stmt) -> bool:
    """A store or atomic update of a field or ndarray element."""
    return s.op in (Op.GLOBAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.GLOBAL_PTR


def check_access_rules(kernel: Kernel) -> None:
    """Raise a located GradientError where the IR proves a read-then-overwrite of the same element."""
    read: dict[tuple, Loc | None] = {}
    for s in walk(kernel.body):
        if s.op not in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC) or s.operands[0].op is not Op.GLOBAL_PTR:
            continue
        ptr = s.operands[0]
        target = ptr.attrs["target"]
        if isinstance(target, ArrayRef) and target.shape_slot >= 0:
            raise GradientError(f"Cannot automatically differentiate through a grad tensor: kernel "
                                f"{kernel.name.removesuffix('_grad')} accesses '{target.name}'", s.loc)
        if not _has_adjoint(target):
            continue
        key = _element(ptr)
        if s.op is Op.GLOBAL_LOAD:
            read.setdefault(key, s.loc)
        elif key in read:  # a store, or an update (`x[i] += x[i] ** 2`) whose replayed read would be the new value
            where = read[key]
            name = kernel.name.removesuffix("_grad")
            raise GradientError(
                f"kernel {name} overwrites an element of {_kind(target)} '{user_name(target)}' that it read "
                f"(at line {where.line if where else '?'}); its adjoint would replay the read with the new "
                "value and give a wrong gradient. Write the result to another field or time step "
                "(e.g. x[t + 1] = f(x[t])).", s.loc)


def in_place_targets(kernel: Kernel) -> list:
    """The differentiable fields a forward kernel updates in place: it reads an element and writes (stores or
    atomically updates) that same element (`x[i] += x[i] ** 2`, `v[i] = v[i] * d + f[i]`). A Tape keeps their
    values from before the launch so that the adjoint can run on them (lang/tape.py). Reading one slice and
    writing another (`x[t + 1, i] = f(x[t, i])`) is not in place."""
    loaded: set = set()  # elements read so far, in program order
    out: dict = {}
    for s in walk(kernel.body):
        if s.op is Op.GLOBAL_LOAD and not s.attrs.get("own_store"):  # not passes/store_select.py's re-read
            loaded.add(_element(s.operands[0]))
        elif _writes_global(s) and _element(s.operands[0]) in loaded:  # read, then overwritten: in place
            target = s.operands[0].attrs["target"]
            if differentiable(target):
                out[id(target)] = target
    return list(out.values())


def written_targets(kernel: Kernel) -> list:
    """The differentiable fields a kernel stores to or updates (what a Tape saves before an in-place launch,
    so that every earlier adjoint, run after this one's, sees the values it read)."""
    out: dict = {}
    for s in walk(kernel.body):
        if _writes_global(s) and differentiable(s.operands[0].attrs["target"]):
            out[id(s.operands[0].attrs["target"])] = s.operands[0].attrs["target"]
    return list(out.values())


def check_owned_in_place(kernel: Kernel) -> None:
    """The rule for adjoints run on the state *before* their kernel (ti.ad.checkpoint): a kernel may read
    and overwrite the same element (`v[i] = v[i] * d + dt * f[i]`), because the adjoint never executes the
    forward's stores and so replays the read with the old value, and a store's adjoint takes the element's
    gradient before the read's adjoint adds to it. What it may not do is read an element of a field it
    stores to other than the one it stores (`u[i] = u[i - 1] + u[i + 1]`): another iteration may already
    have overwritten it, so the forward itself depends on the order of iterations."""
    stored: dict[int, list] = {}
    loads: list = []
    written: set = set()  # (field, element) stored so far, in program order
    for s in walk(kernel.body):
        if _writes_global(s):
            ptr = s.operands[0]
            stored.setdefault(id(ptr.attrs["target"]), []).append(ptr)
            written.add(_element(ptr))
        elif s.op is Op.GLOBAL_LOAD:
            loads.append(s)
            ptr = s.operands[0]
            if _element(ptr) in written and _has_adjoint(ptr.attrs["target"]):
                # the adjoint's replay drops stores, so it would read the old value here
                raise GradientError(
                    f"kernel {kernel.name.removesuffix('_grad')} reads an element of "
                    f"{_kind(ptr.attrs['target'])} '{user_name(ptr.attrs['target'])}' after overwriting it; keep "
                    "the new value in a local variable and use that (its adjoint replays reads, not writes)",
                    s.loc)
    for s in loads:
        ptr = s.operands[0]
        writes = stored.get(id(ptr.attrs["target"]))
        if not writes or not _has_adjoint(ptr.attrs["target"]):
            continue
        if any(_element(w) != _element(ptr) and not _other_slice(ptr, w) for w in writes):
            raise GradientError(
                f"kernel {kernel.name.removesuffix('_grad')} reads an element of {_kind(ptr.attrs['target'])} "
                f"'{user_name(ptr.attrs['target'])}' other than the one it overwrites; an in-place update is "
                "differentiable only when each iteration reads exactly the element it writes (owned). Write "
                "the new values to another field (or time step) instead.", s.loc)


def forward_stores(kernel: Kernel) -> None:
    """Within a block, a load of the element a store just wrote becomes the stored value (`v[i] = ...;
    x[i] += dt * v[i]`): an adjoint that replays the kernel on the state before it must not read memory there.
    Any other store or atomic to the field forgets what was known of it (indices may alias)."""
    repl: dict[int, Stmt] = {}

    def block(b: Block) -> None:
        known: dict[tuple, Stmt] = {}
        keep = []
        for s in b.stmts:
            if repl:
                s.operands = tuple(repl.get(id(o), o) for o in s.operands)
            if s.op is Op.GLOBAL_LOAD:
                key = _element(s.operands[0])
                if key in known and known[key].type is s.type:
                    repl[id(s)] = known[key]
                    continue
            elif _writes_global(s):
                key = _element(s.operands[0])
                for k in [k for k in known if k[0] == key[0]]:
                    del known[k]
                if s.op is Op.GLOBAL_STORE:
                    known[key] = s.operands[1]
            for nested in s.blocks:
                block(nested)
                # what a nested block stored is not known after it (it may not have run)
                for k in [k for k in known if any(_stores_to(nested, k[0]))]:
                    del known[k]
            keep.append(s)
        b.stmts = keep

    block(kernel.body)
    if repl:  # loads forwarded inside nested blocks may be used later in enclosing ones
        for s in walk(kernel.body):
            s.operands = tuple(repl.get(id(o), o) for o in s.operands)


def _stores_to(block: Block, target: int):
    for s in walk(block):
        if _writes_global(s) and id(s.operands[0].attrs["target"]) == target:
            yield s


def _invariant(s: Stmt) -> bool:
    """A value every iteration of the kernel's loops shares (arguments, constants, arithmetic of them)."""
    if s.op in (Op.ARG, Op.CONST):
        return True
    return s.op in (Op.ADD, Op.SUB, Op.MUL, Op.CAST) and all(_invariant(o) for o in s.operands)


def _other_slice(a: Stmt, b: Stmt) -> bool:
    """Two accesses of one field that no iterations share: in some axis both use the same launch-wide value
    with different constant offsets (`x[t, i]` and `x[t + 1, j]`)."""
    for x, y in zip(a.operands, b.operands):
        (bx, cx), (by, cy) = offset_form(x), offset_form(y)
        if bx is by and cx != cy and (bx is None or _invariant(bx)):
            return True
    return False


def check_in_place_and_adjoint(kernel: Kernel) -> bool:
    """The pipeline step for the adjoints ti.ad.checkpoint runs (on the state before the kernel)."""
    from simgrad.autodiff.reverse import make_adjoint

    forward_stores(kernel)
    check_owned_in_place(kernel)
    return make_adjoint(kernel)


def _kind(target) -> str:
    return "field" if isinstance(target, FieldRef) else "ndarray"


def check_and_adjoint(kernel: Kernel) -> bool:
    """The pipeline step for .grad kernels: the compile-time rule check, then the adjoint transform."""
    from simgrad.autodiff.reverse import make_adjoint

    check_access_rules(kernel)
    return make_adjoint(kernel)
