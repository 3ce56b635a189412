"""What the kernel lowering keeps per inlined function (Frame: its scopes and early-return state) and the
compile-time `range(...)` (RangeSpec). Shared by frontend/lower.py, calls.py and loops.py, which import it
downward instead of each other."""

from __future__ import annotations

import builtins

from simgrad.errors import SimgradSyntaxError
from simgrad.frontend.refs import MatrixRef, VarRef
from simgrad.frontend.source import FunctionSource
from simgrad.ir import context
from simgrad.ir.nodes import Block
from simgrad.lang.expr import Expr


class RangeSpec:
    """`range(...)` seen inside a kernel: a run-time loop unless wrapped in ti.static."""

    def __init__(self, *args):
        if len(args) == 1:
            self.start, self.stop, self.step = 0, args[0], 1
        elif len(args) == 2:
            self.start, self.stop, self.step = args[0], args[1], 1
        else:
            self.start, self.stop, self.step = args
        if isinstance(self.step, Expr):
            raise SimgradSyntaxError("range() step must be a compile-time constant", context.current_loc())

    def __iter__(self):
        return iter(builtins.range(self.start, self.stop, self.step))

    def __len__(self):
        return len(builtins.range(self.start, self.stop, self.step))


class Frame:
    """One function being lowered (the kernel or an inlined ti.func): its scopes and return state."""

    def __init__(self, src: FunctionSource, is_kernel: bool):
        self.src = src
        self.is_kernel = is_kernel
        # a kernel's parameters are immutable (Taichi's rule): assigning one is an error, not a new local
        self.arg_names = {a.arg for a in src.tree.args.args} if is_kernel else set()
        self.scopes: list[dict] = [{}]
        self.return_value = None
        self.has_returned = False
        self.dynamic_depth = 0  # run-time control flow nesting inside this frame
        self.guard_depth = 0  # of which return guards (`if not returned:`), transparent to ti.static jumps
        # early returns from run-time control flow in a ti.func: the value and a flag live in locals declared
        # at the function's entry (entry_block/entry_index); the rest of the body is guarded by the flag
        self.entry_block: Block | None = None
        self.entry_index = 0
        self.loop_base = 0  # run-time loops open when the function was entered
        self.ret_var: VarRef | MatrixRef | None = None
        self.ret_flag: VarRef | None = None
        self.dynamic_returns = 0
        self.returned_here = False
        self.real = False  # a ti.real_func: its loops are serial (it is a function the kernel calls)
        self.real_key = None  # a real function's specialisation (frontend/realfuncs.py): calling it inside recurses
