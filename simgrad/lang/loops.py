"""Loop and compile-time helpers the kernel compiler recognises: ti.static, ti.ndrange, ti.grouped,
ti.loop_config."""

from __future__ import annotations

from simgrad.errors import SimgradSyntaxError, SimgradTypeError


def static(x, *xs):
    """Compile-time evaluation: `if ti.static(c)` picks a branch, `for i in ti.static(range(n))` unrolls.
    A run-time value (a kernel argument, a field element) has no compile-time value: refused, located."""
    for v in (x, *xs):
        _check_static(v)
    if xs:
        return (x, *xs)
    return x


def _check_static(v) -> None:
    from simgrad.ir import context
    from simgrad.lang.expr import Expr
    from simgrad.lang.matrix import Matrix

    if not context.in_kernel():
        return
    if isinstance(v, Matrix):
        parts = v.entries
    elif type(v).__name__ == "RangeSpec":
        parts = [v.start, v.stop, v.step]
    elif isinstance(v, ndrange):
        parts = [e for bound in v.bounds for e in bound]
    else:
        parts = [v]
    if any(isinstance(p, Expr) for p in parts):
        raise SimgradSyntaxError("ti.static() arguments must be compile-time constants, but this depends on a "
                                 "run-time value "
                                 "(a kernel argument, a field element or a local variable); use a ti.template() "
                                 "parameter or a Python constant, or drop ti.static for a run-time loop/branch",
                                 context.current_loc())


def static_assert(cond, msg: str = "static assertion failed"):
    from simgrad.lang.expr import Expr
    from simgrad.lang.matrix import Matrix

    if isinstance(cond, (Expr, Matrix)):
        raise SimgradTypeError("Static assert with non-static condition (a kernel value is known only at run "
                               "time; use ti.static values)")
    if not cond:
        raise SimgradSyntaxError(msg)


def static_print(*args, **kwargs):
    print(*args, **kwargs)


class ndrange:
    """A multi-dimensional range; each argument is `n` (0..n) or `(begin, end)`."""

    def __init__(self, *args):
        self.bounds = []
        for a in args:
            if isinstance(a, (tuple, list)):
                if len(a) != 2:
                    raise SimgradSyntaxError("Every argument of ndrange should be a scalar or a tuple/list like "
                                             f"(begin, end): ndrange takes n or (begin, end) per dimension, got {a!r}")
                bounds = (a[0], a[1])
            else:
                bounds = (0, a)
            if any(isinstance(b, float) for b in bounds):  # Python floats (run-time values are checked later)
                raise SimgradTypeError("Every argument of ndrange should be an integer scalar or a tuple/list of "
                                       f"(int, int), got {a!r}")
            self.bounds.append(bounds)

    @property
    def dimensions(self):
        return [e - b for b, e in self.bounds]

    def __iter__(self):
        """Python-scope iteration (and `ti.static(ti.ndrange(...))` unrolling)."""
        import itertools

        return itertools.product(*(range(int(b), int(e)) for b, e in self.bounds))


class grouped:
    """`for I in ti.grouped(x)`: one vector index instead of one name per axis."""

    def __init__(self, target):
        self.target = target

    def __iter__(self):
        """`ti.static(ti.grouped(...))` unrolling: one integer vector per index, in row-major order."""
        import itertools

        from simgrad.lang.matrix import Matrix

        t = self.target
        if isinstance(t, ndrange):
            ranges = [range(int(b), int(e)) for b, e in t.bounds]
        elif hasattr(t, "shape"):  # a field: its indices (offsets included)
            offset = getattr(t._components()[0], "offset", None) if hasattr(t, "_components") else None
            offset = offset or (0,) * len(t.shape)
            ranges = [range(o, o + n) for o, n in zip(offset, t.shape)]
        else:
            raise SimgradSyntaxError(f"cannot unroll ti.grouped over a {type(t).__name__}")
        return (Matrix(list(idx)) for idx in itertools.product(*ranges))


_loop_config: dict = {}


def loop_config(*, serialize: bool = False, block_dim: int | None = None, parallelize: int | None = None,
                block_dim_adaptive: bool = True, bit_vectorize: bool = False, vectorize: bool = False):
    """Applies to the next for loop in the kernel (Taichi semantics). `vectorize` (simgrad's, not Taichi's): an
    inner loop of a few known trips that should still be vector code (LLVM leaves loops of fewer than 16 scalar)."""
    from simgrad.ir import context

    comp = context.current()
    if comp is not None:
        comp.next_loop_config = {"serialize": serialize or parallelize == 1, "block_dim": block_dim,
                                 "vectorize": vectorize}


# -- scheduling hints a CPU does not need: accepted so Taichi programs run, with no effect on results -------
def block_local(*fields) -> None:
    """Taichi caches these fields in GPU shared memory inside the next loop; on a CPU the cache is the cache."""
    _check_fields("block_local", fields)


def cache_read_only(*fields) -> None:
    """Taichi's read-only data cache hint (GPU); nothing to do on a CPU."""
    _check_fields("cache_read_only", fields)


def no_activate(*fields) -> None:
    """Taichi's promise that this kernel touches only active cells of these fields or SNodes (Taichi passes
    SNodes), so its accesses need not activate; activating anyway computes the same for a program that keeps
    the promise."""
    from simgrad.lang.snode import SNode

    _check_fields("no_activate", [f for f in fields if not isinstance(f, SNode)])


def assume_in_range(val, base, low: int, high: int):
    """Taichi's promise that base + low <= val < base + high (it shrinks GPU shared-memory tiles); the value
    itself is returned unchanged."""
    if not (isinstance(low, int) and isinstance(high, int)) or low > high:
        raise ValueError(f"assume_in_range: low and high must be integers with low <= high, got {low}, {high}")
    return val


def loop_unique(val, covers=None):
    """Taichi's promise that `val` differs between the iterations of the enclosing parallel loop (so updates of
    `y[val]` need no atomics, for the fields in `covers`); the value itself is returned unchanged, and the
    updates stay as the atomics analysis decides (passes/parallel_strategy.py), which is correct either way."""
    if covers is not None:
        _check_fields("loop_unique", covers if isinstance(covers, (list, tuple)) else [covers])
    return val


def _check_fields(name: str, fields) -> None:
    from simgrad.lang.field import Field

    for f in fields:
        if not isinstance(f, Field):
            raise TypeError(f"ti.{name} expects fields, got {type(f).__name__}")


def stop_grad(x) -> None:
    """ti.stop_grad(field) inside a kernel: no gradient flows through the field's elements in the rest of
    the enclosing top-level loop (Taichi's scope for it)."""
    from simgrad.ir import context

    comp = context.current()
    if comp is None:
        raise SimgradSyntaxError("ti.stop_grad(field) is called inside a kernel")
    comp.stop_grad(x)
