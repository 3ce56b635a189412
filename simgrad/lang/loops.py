"""Loop and compile-time helpers the kernel compiler recognises: ti.static, ti.ndrange, ti.grouped,
ti.loop_config."""

from __future__ import annotations

from simgrad.errors import SimgradSyntaxError


def static(x, *xs):
    """Compile-time evaluation: `if ti.static(c)` picks a branch, `for i in ti.static(range(n))` unrolls."""
    if xs:
        return (x, *xs)
    return x


def static_assert(cond, msg: str = "static assertion failed"):
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
                    raise SimgradSyntaxError("ndrange takes n or (begin, end) per dimension")
                self.bounds.append((a[0], a[1]))
            else:
                self.bounds.append((0, a))

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


_loop_config: dict = {}


def loop_config(*, serialize: bool = False, block_dim: int | None = None, parallelize: int | None = None,
                block_dim_adaptive: bool = True, bit_vectorize: bool = False):
    """Applies to the next for loop in the kernel (Taichi semantics)."""
    from simgrad.frontend import context

    comp = context.current()
    if comp is not None:
        comp.next_loop_config = {"serialize": serialize or parallelize == 1, "block_dim": block_dim}
