"""Reverse mode: the adjoint of a kernel, built as an IR-to-IR transform (source transformation).

For each top-level parallel loop the adjoint is a parallel loop over the same range whose body first
replays the forward body (without its global writes) and then walks it backwards, accumulating adjoints
in local variables and atomically into `.grad` fields. Top-level serial statements are replayed once and
reversed at the end, in reverse task order.

Values that the backward walk needs but that live in nested blocks (inside if/for/while) are saved on a
per-thread LIFO tape (the adstack): each statement pushes the operand values its derivative needs right
after it runs, and the backward walk pops them in exactly the reverse order. Control decisions go on the
same tape: if-conditions, serial loop bounds, and while-loop trip counts, so serial loops run reversed and
while loops (which Taichi cannot differentiate) replay the recorded number of iterations.

A serial range-for inside a task that stores no local declared outside it (Taichi's case for long inner
loops such as a ray march) is not replayed at all: its replay could have no effect, since global writes
are dropped. Its backward loop instead recomputes each iteration's forward statements and then reverses
them, so nothing per iteration goes on the tape. The values it takes from outside (its bounds, outer SSA
values, and a snapshot of each outer local it reads, loaded where the loop stood) are taken as the replay
passes the loop: directly when they are still in scope in the backward walk, else through the tape once
per execution of the loop. Values inside such a body that its nested blocks need still use the tape, but
each iteration pops what its own recompute pushed.

Adjoints are accumulated only for active values, those that depend on a field with a gradient (`_active`):
the derivative chains of everything else (a ray's positions from the camera, weights from loop indices)
could never reach a .grad field, and LLVM does not remove them once they run through adjoint locals.
"""

from __future__ import annotations

from collections.abc import Sequence

from simgrad import dtypes as dt
from simgrad.autodiff.rules import NEEDS_VALUES, REVERSE, ZERO_GRADIENT
from simgrad.autodiff.structurize import structurize
from simgrad.errors import GradientError
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import ArrayRef, FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import Op

_DROPPED = (Op.PRINT, Op.ASSERT, Op.RET_STORE)
# statements whose own adjoint is nothing (a local's adjoint belongs to its loads and stores)
_NO_ADJOINT = (Op.ALLOCA, Op.CONST, Op.ARG, Op.ARRAY_SHAPE, Op.GLOBAL_PTR, Op.BREAK, Op.CONTINUE,
               Op.TAPE_RESET, Op.TAPE_PUSH, Op.TAPE_POP, Op.RANDOM) + _DROPPED


class _Task:
    """Where adjoint variables of one task live: declared at the top of its block, zeroed per iteration."""

    def __init__(self, block: Block):
        self.block = block
        self.decls: list[Stmt] = []


def _grad_of(ptr: Stmt):
    """The gradient field of the element `ptr` points to, or None when it has no placed gradient or
    ti.stop_grad covers the access."""
    target = ptr.attrs["target"]
    if isinstance(target, (FieldRef, ArrayRef)) and target.grad is not None and not ptr.attrs.get("stop_grad"):
        return target.grad
    return None


def _is_global_ptr(s: Stmt) -> bool:
    return s.op is Op.GLOBAL_PTR


class Reverse:
    def __init__(self, kernel: Kernel):
        self.kernel = kernel
        self.body = Block()
        self.b = Builder(self.body)
        self.fmap: dict[int, Stmt] = {}  # old statement -> its value in the forward replay
        self.bmap: dict[int, Stmt] = {}  # old statement -> its value in the backward walk (loop indices)
        self.depth: dict[int, int] = {}
        self.owner: dict[int, _Task] = {}
        self.adj: dict[int, Stmt] = {}  # old statement -> adjoint local (ALLOCA)
        self.anchors: list[tuple[int, Block, Stmt | None]] = []
        self.push: dict[int, list[Stmt]] = {}  # old statement -> forward values to push after it
        self.uses: dict[int, int] = {}
        for s in walk(kernel.body):
            for o in s.operands:
                self.uses[id(o)] = self.uses.get(id(o), 0) + 1
        # adjoints only for values that depend on a gradient field and can reach a write of one
        self.active = _active(kernel.body) & _reaching(kernel.body)
        self.task = _Task(self.body)
        self.used_tape = False
        self.in_task = False  # inside a parallel loop's body (only there are serial loops recomputed)
        self.snap: dict[int, list] = {}  # recomputed loop -> [(outer local, snapshot value, in scope)]
        self.held: dict[int, Stmt] = {}  # outer local -> its snapshot, while a recomputed loop is rebuilt
        self._free_cache: dict[int, tuple] = {}

    # -- entry -------------------------------------------------------------------------------------
    def run(self) -> Block:
        top = self.kernel.body.stmts
        kernel_task = self.task
        for s in top:
            if not self._parallel(s):
                self.clone(s, 0)
        for s in reversed(top):
            if self._parallel(s):
                self.adjoint_loop(s)
            else:
                self.backward(s)
        self._declare(kernel_task)
        self._insert_pushes()
        return self.body

    @staticmethod
    def _parallel(s: Stmt) -> bool:
        """A loop with an adjoint loop; a parallel listgen (frontend/loops.py, the GPU) is replayed as it is."""
        return s.op is Op.RANGE_FOR and s.attrs.get("parallel", False) and not s.attrs.get("listgen", False)

    def adjoint_loop(self, loop: Stmt) -> None:
        begin, end = (self.fmap[id(o)] if o.op is not Op.CONST else o for o in loop.operands)
        new = self.b.emit(Op.RANGE_FOR, loop.type, (begin, end), dict(loop.attrs), nblocks=1)
        self.fmap[id(loop)] = new
        self.depth[id(loop)] = 0
        saved = self.task
        self.task = _Task(new.blocks[0])
        self.in_task = True
        with self.b.inside(new.blocks[0]):
            reset = self.b.emit(Op.TAPE_RESET, None)
            for s in loop.blocks[0].stmts:
                self.clone(s, 0)
            for s in reversed(loop.blocks[0].stmts):
                self.backward(s)
        self.in_task = False
        if not any(x.op is Op.TAPE_PUSH for x in walk(new.blocks[0])) and not self.push_pending(loop):
            new.blocks[0].stmts.remove(reset)
        self._declare(self.task)
        self.task = saved

    def push_pending(self, loop: Stmt) -> bool:
        return any(self.push.get(id(s)) for s in walk(loop.blocks[0]))

    def _declare(self, task: _Task) -> None:
        """Adjoint locals at the top of their task, set to zero at every entry (every iteration)."""
        decls = []
        for a in task.decls:
            zero = Builder.constant(0.0 if a.vtype.is_float else 0, a.vtype, a.loc)
            st = Builder.detached(Op.LOCAL_STORE, None, (a, zero), {}, a.loc)
            for x in (a, st):
                x.block = task.block
            decls += [a, st]
        task.block.stmts[0:0] = decls

    # -- forward replay -----------------------------------------------------------------------------
    def v(self, o: Stmt) -> Stmt:
        """The value of `o` where it is being cloned: in a recompute inside the backward walk, loop indices
        and values taken from outside the recomputed loop are in bmap."""
        if o.op is Op.CONST:
            return o
        return self.bmap.get(id(o)) or self.fmap[id(o)]

    def _anchor(self, s: Stmt, new: Stmt | None) -> None:
        if new is None:
            blk = self.b.block
            new = blk.stmts[-1] if blk.stmts else None
        self.anchors.append((id(s), self.b.block, new))

    def clone(self, s: Stmt, depth: int) -> None:
        self.b.loc = s.loc
        self.depth[id(s)] = depth
        self.owner[id(s)] = self.task
        op = s.op
        if op is Op.IF:
            new = self.b.emit(Op.IF, None, (self.v(s.operands[0]),), nblocks=2)
            for ob, nb in zip(s.blocks, new.blocks):
                with self.b.inside(nb):
                    for x in ob.stmts:
                        self.clone(x, depth + 1)
            self.fmap[id(s)] = new
            self._anchor(s, new)
        elif op is Op.RANGE_FOR and self._recomputable(s):
            self._snapshot(s)
        elif op is Op.LOCAL_LOAD and id(s.operands[0]) in self.held:
            # an outer local read by a recomputed loop: its value where the loop stood, in scope
            self.fmap[id(s)] = self.bmap[id(s)] = self.held[id(s.operands[0])]
        elif op is Op.RANGE_FOR:
            # replayed serially, except a top-level parallel listgen (it records nothing on the tape)
            attrs = dict(s.attrs, parallel=depth == 0 and bool(s.attrs.get("listgen") and s.attrs.get("parallel")))
            new = self.b.emit(Op.RANGE_FOR, s.type, tuple(self.v(o) for o in s.operands), attrs, nblocks=1)
            self.fmap[id(s)] = new
            with self.b.inside(new.blocks[0]):
                for x in s.blocks[0].stmts:
                    self.clone(x, depth + 1)
            self._anchor(s, new)
        elif op is Op.WHILE:
            self._clone_while(s, depth)
        elif op is Op.GLOBAL_STORE or (op is Op.ATOMIC and _is_global_ptr(s.operands[0])):
            if op is Op.ATOMIC and self.uses.get(id(s)):
                raise GradientError(
                    "the value returned by an atomic operation on a field cannot be replayed by the "
                    "adjoint kernel (it would apply the update twice); compute it in a separate kernel",
                    s.loc)
            self._anchor(s, None)
        elif op in _DROPPED:
            pass
        elif op is Op.RANDOM:
            raise GradientError("ti.random() inside a kernel that is differentiated: the adjoint would "
                                "replay different random numbers. Draw them in a separate kernel into a "
                                "field.", s.loc)
        elif op is Op.CONTINUE or (op is Op.BREAK and not s.attrs.get("header")):
            raise GradientError("internal: jump left after structurize", s.loc)
        else:
            new = self.b.emit(op, s.type, tuple(self.v(o) for o in s.operands), dict(s.attrs))
            self.fmap[id(s)] = new
            self._anchor(s, new)

    # -- recomputed serial loops -----------------------------------------------------------------------
    def _recomputable(self, loop: Stmt) -> bool:
        """A serial range-for in a task whose body stores no local declared outside it: replaying it has no
        effect (global writes are dropped), so its backward loop can recompute each iteration instead."""
        if not self.in_task or loop.attrs.get("parallel"):
            return False
        inside = {id(x) for x in walk(loop.blocks[0])}
        for x in walk(loop.blocks[0]):
            if x.op in (Op.LOCAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.ALLOCA \
                    and id(x.operands[0]) not in inside:
                return False
        return True

    def _free(self, loop: Stmt) -> tuple[list[Stmt], list[Stmt]]:
        """(SSA values the loop uses from outside, bounds first; outer locals it reads)."""
        got = self._free_cache.get(id(loop))
        if got is None:
            inside = {id(x) for x in walk(loop.blocks[0])} | {id(loop)}
            values: dict[int, Stmt] = {id(o): o for o in loop.operands if o.op is not Op.CONST}
            local: dict[int, Stmt] = {}
            for x in walk(loop.blocks[0]):
                for o in x.operands:
                    if id(o) not in inside and o.op is not Op.CONST:
                        if o.op is Op.GLOBAL_PTR:  # rebuilt from its indices, never taped (not a value)
                            for i in o.operands:
                                if i.op is not Op.CONST:
                                    values.setdefault(id(i), i)
                        (local if o.op is Op.ALLOCA else values).setdefault(id(o), o)
            got = self._free_cache[id(loop)] = (list(values.values()), list(local.values()))
        return got

    def _snapshot(self, loop: Stmt) -> None:
        """In the replay, in place of the loop: load each outer local it reads (it cannot change them, so
        this is the value every iteration saw) and mark the spot where its outer values are pushed."""
        snaps = []
        for a in self._free(loop)[1]:
            held = self.held.get(id(a))
            value = held if held is not None else self.b.emit(Op.LOCAL_LOAD, a.type, (self.v(a),))
            snaps.append((a, value, held is not None))
        self.snap[id(loop)] = snaps
        self._anchor(loop, None)

    def _backward_recompute(self, s: Stmt) -> None:
        """for k reversed: recompute the body's forward statements for index k, then reverse them."""
        values, _ = self._free(s)
        blk = self.b.block
        mark = len(blk.stmts)
        saved_bmap = {id(o): self.bmap.get(id(o)) for o in values}
        saved_held = dict(self.held)
        # outer values not in scope here come through the tape, pushed where the replay passed the loop
        taped = [(o, self.fmap[id(o)], self.bmap) for o in values
                 if id(o) not in self.bmap and self.depth.get(id(o), 0) > 0 and o.op is not Op.GLOBAL_PTR]
        # an element pointer from a nested block (CSE shared it with the loop) is rebuilt from its indices
        rebuilt = [o for o in values if o.op is Op.GLOBAL_PTR and id(o) not in self.bmap
                   and self.depth.get(id(o), 0) > 0]
        nested = self.depth.get(id(s), 0) > 0
        for a, value, held in self.snap[id(s)]:
            if nested and not held:
                taped.append((a, value, self.held))
            else:
                self.held[id(a)] = value
        for o, value, into in reversed(taped):
            into[id(o)] = self.b.emit(Op.TAPE_POP, value.type, (), {"message": self._overflow_text(s)})
        for o in rebuilt:
            self.bmap[id(o)] = self.b.emit(Op.GLOBAL_PTR, o.type, tuple(self.v(i) for i in o.operands),
                                           dict(o.attrs))
        begin, end = (o if o.op is Op.CONST else self.v(o) for o in s.operands)
        n = _trip(self.b, begin, end)
        t = n.vtype
        loop = Builder.detached(Op.RANGE_FOR, t, (self.b.const(0, t), n), {"parallel": False, "reversed": True},
                                s.loc)
        body = Block(loop)
        loop.blocks = (body,)
        with self.b.inside(body):
            k = self.b.binary(Op.SUB, self.b.binary(Op.SUB, n, self.b.const(1, t)), loop)
            self.bmap[id(s)] = self.b.binary(Op.ADD, begin, k)
            for x in s.blocks[0].stmts:
                self.clone(x, 0)
            recomputed = len(body.stmts)
            self.backward_block(s.blocks[0].stmts)
        empty = len(body.stmts) == recomputed
        self.bmap.pop(id(s), None)
        for key, old in saved_bmap.items():
            if old is None:
                self.bmap.pop(key, None)
            else:
                self.bmap[key] = old
        self.held = saved_held
        if empty:  # nothing to differentiate: no loop, no pops, and the replay pushes nothing for it
            del blk.stmts[mark:]
            return
        if taped:
            self.push.setdefault(id(s), []).extend(value for _, value, _ in taped)
            self.used_tape = True
        loop.block = blk
        blk.stmts.append(loop)

    def _clone_while(self, s: Stmt, depth: int) -> None:
        count = self.b.emit(Op.ALLOCA, dt.i32)
        self.b.emit(Op.LOCAL_STORE, None, (count, self.b.const(0, dt.i32)))
        new = self.b.emit(Op.WHILE, None, nblocks=1)
        head, rest = _split_header(s.blocks[0])
        with self.b.inside(new.blocks[0]):
            for x in head:
                self.clone(x, depth + 1)
            c = self.b.emit(Op.LOCAL_LOAD, dt.i32, (count,))
            self.b.emit(Op.LOCAL_STORE, None, (count, self.b.binary(Op.ADD, c, self.b.const(1, dt.i32))))
            for x in rest:
                self.clone(x, depth + 1)
        n = self.b.emit(Op.LOCAL_LOAD, dt.i32, (count,))
        self.fmap[id(s)] = n
        self._anchor(s, n)

    # -- adjoint variables ----------------------------------------------------------------------------
    def _adj_var(self, s: Stmt) -> Stmt:
        a = self.adj.get(id(s))
        if a is None:
            task = self.owner.get(id(s), self.task)
            a = Builder.detached(Op.ALLOCA, s.type, (), {}, s.loc)
            task.decls.append(a)
            self.adj[id(s)] = a
        return a

    def has_adj(self, s: Stmt) -> bool:
        return id(s) in self.adj

    def acc(self, s: Stmt, contribution) -> None:
        """adj(s) += contribution (an atomic on a local shared by parallel iterations)."""
        if s.op is Op.CONST or s.type is None or not s.type.is_float or id(s) not in self.active:
            return
        a = self._adj_var(s)
        c = contribution if isinstance(contribution, Stmt) else self.b.const(contribution, s.vtype)
        self.b.emit(Op.ATOMIC, s.type, (a, self.b.cast(c, s.vtype)), {"kind": "add"})

    def take(self, s: Stmt) -> Stmt:
        """Read adj(s) and reset it, as the definition of s is reversed."""
        a = self.adj[id(s)]
        g = self.b.emit(Op.LOCAL_LOAD, a.type, (a,))
        if self.owner.get(id(s)) is self.task:
            self.b.emit(Op.LOCAL_STORE, None, (a, self.b.const(0, a.vtype)))
        return g

    # -- values in the backward walk ---------------------------------------------------------------------
    def values(self, s: Stmt, olds: list[Stmt]) -> list[Stmt]:
        """Values of `olds` where the derivative of `s` is computed: direct when in scope, else popped."""
        saved = [o for o in olds
                 if o.op is not Op.CONST and id(o) not in self.bmap and self.depth.get(id(o), 0) > 0]
        uniq = list(dict.fromkeys(id(o) for o in saved))
        popped = {}
        if uniq:
            self.push.setdefault(id(s), []).extend(self.fmap[i] for i in uniq)
            self.used_tape = True
            for i in reversed(uniq):
                # typed as the pushed value: a WHILE has no type, its replay value is the i32 trip count
                popped[i] = self.b.emit(Op.TAPE_POP, self.fmap[i].type, (),
                                        {"message": self._overflow_text(s)})
        out = []
        for o in olds:
            if o.op is Op.CONST:
                out.append(o)
            elif id(o) in self.bmap:
                out.append(self.bmap[id(o)])
            elif id(o) in popped:
                out.append(popped[id(o)])
            else:
                out.append(self.fmap[id(o)])
        return out

    def _overflow_text(self, s: Stmt) -> str:
        return (f"the adjoint of kernel {self.kernel.name} needs more tape (adstack) entries per thread than "
                f"the capacity; raise it with ti.init(ad_stack_size=N)")

    # -- backward walk --------------------------------------------------------------------------------------
    def backward_block(self, stmts: list[Stmt]) -> None:
        for s in reversed(stmts):
            self.backward(s)

    def backward(self, s: Stmt) -> None:
        self.b.loc = s.loc
        op = s.op
        if op in _NO_ADJOINT:
            return
        if op is Op.IF:
            self._backward_if(s)
        elif op is Op.RANGE_FOR and id(s) in self.snap:
            self._backward_recompute(s)
        elif op is Op.RANGE_FOR:
            self._backward_loop(s, s.operands)
        elif op is Op.WHILE:
            self._backward_loop(s, None)
        elif op is Op.LOCAL_LOAD:
            if self.has_adj(s) and s.vtype.is_float:
                self.acc(s.operands[0], self.take(s))
        elif op is Op.LOCAL_STORE:
            a, w = s.operands
            if self.has_adj(a) and a.type.is_float:
                ga = self.b.emit(Op.LOCAL_LOAD, a.type, (self.adj[id(a)],))
                if self.owner.get(id(a)) is self.task:
                    self.b.emit(Op.LOCAL_STORE, None, (self.adj[id(a)], self.b.const(0, a.vtype)))
                self.acc(w, ga)
        elif op is Op.ATOMIC:
            self._backward_atomic(s)
        elif op is Op.GLOBAL_LOAD:
            self._backward_global_load(s)
        elif op is Op.GLOBAL_STORE:
            self._backward_global_store(s)
        elif op is Op.CAST:
            if self.has_adj(s):
                g = self.take(s)
                src = s.operands[0]
                if src.vtype.is_float and s.vtype.is_float:
                    self.acc(src, self.b.cast(g, src.vtype))
        elif op in REVERSE and s.type is not None and s.type.is_float:
            if self.has_adj(s):
                g = self.take(s)
                needed = (list(s.operands) if op in NEEDS_VALUES
                          else [o for o in s.operands if not o.type.is_float])
                vals = dict(zip((id(o) for o in needed), self.values(s, needed)))
                args = [vals.get(id(o)) for o in s.operands]
                contribs = REVERSE[op](self.b, g, *args)
                for o, c in zip(s.operands, contribs):
                    if c is not None:
                        self.acc(o, c)
        elif self.has_adj(s):
            if op in ZERO_GRADIENT or not s.vtype.is_float or s.attrs.get("zero_gradient"):
                self.take(s)  # (zero_gradient: a piecewise-constant value built from bits, lang/linalg.py)
            else:
                raise GradientError(f"no derivative rule for the operation '{op.name.lower()}' on {s.type}",
                                    s.loc)

    def _sub_block(self, stmts: list[Stmt], prefix=None) -> Block:
        """Backward of `stmts` built in a detached block (to learn whether it is empty)."""
        blk = Block()
        with self.b.inside(blk):
            if prefix is not None:
                prefix()
            self.backward_block(stmts)
        return blk

    def _attach(self, parent: Stmt, blocks: list[Block]) -> None:
        parent.blocks = tuple(blocks)
        for b in blocks:
            b.parent = parent
            for x in b.stmts:
                x.block = b

    def _backward_if(self, s: Stmt) -> None:
        then_b = self._sub_block(s.blocks[0].stmts)
        else_b = self._sub_block(s.blocks[1].stmts)
        if not then_b.stmts and not else_b.stmts:
            return
        (cond,) = self.values(s, [s.operands[0]])
        new = self.b.emit(Op.IF, None, (cond,))
        self._attach(new, [then_b, else_b])

    def _backward_loop(self, s: Stmt, bounds) -> None:
        index_var = Builder.detached(Op.ALLOCA, s.type or dt.i32, (), {}, s.loc)
        body_old = s.blocks[0].stmts if s.op is Op.RANGE_FOR else _split_header(s.blocks[0])[1]
        # a local stored late in the body feeds loads of the next iteration, whose backward ran before; the
        # store is walked before those loads, so its adjoint variable must exist already
        for x in walk(s.blocks[0]):
            if x.op is Op.LOCAL_LOAD and id(x.operands[0]) in self.active:
                self._adj_var(x.operands[0])

        def bind_index():
            if s.op is Op.RANGE_FOR:
                self.bmap[id(s)] = self.b.emit(Op.LOCAL_LOAD, index_var.type, (index_var,))

        body = self._sub_block(body_old, bind_index)
        if len(body.stmts) <= (1 if s.op is Op.RANGE_FOR else 0):
            return
        self.task.decls.append(index_var)
        if s.op is Op.RANGE_FOR:
            begin, end = self.values(s, list(s.operands))
            n = self.b.binary(Op.SUB, end, begin)
        else:
            (n,) = self.values(s, [s])
        t = n.vtype
        loop = self.b.emit(Op.RANGE_FOR, t, (self.b.const(0, t), n), {"parallel": False, "reversed": True},
                           nblocks=1)
        with self.b.inside(loop.blocks[0]):
            if s.op is Op.RANGE_FOR:
                last = self.b.binary(Op.SUB, n, self.b.const(1, t))
                k = self.b.binary(Op.SUB, last, loop)
                self.b.emit(Op.LOCAL_STORE, None, (index_var, self.b.binary(Op.ADD, begin, k)))
        loop.blocks[0].stmts += body.stmts
        for x in body.stmts:
            x.block = loop.blocks[0]

    def _grad_ptr(self, s: Stmt, ptr: Stmt, extra: Sequence[Stmt] = ()):
        """(pointer to the gradient element, values of `extra`) for a field access, or (None, ...)."""
        grad = _grad_of(ptr)
        if grad is None:
            return None, None, []
        vals = self.values(s, list(ptr.operands) + list(extra))
        idx, rest = vals[: len(ptr.operands)], vals[len(ptr.operands):]
        gp = self.b.emit(Op.GLOBAL_PTR, grad.dtype, tuple(idx), {"target": grad})
        return gp, idx, rest

    def _backward_global_load(self, s: Stmt) -> None:
        if not self.has_adj(s) or not s.vtype.is_float:
            return
        g = self.take(s)
        gp, _, _ = self._grad_ptr(s, s.operands[0])
        if gp is not None:
            self.b.emit(Op.ATOMIC, gp.type, (gp, self.b.cast(g, gp.vtype)), {"kind": "add"})

    def _backward_global_store(self, s: Stmt) -> None:
        """The store overwrote the element, so the gradient that reached it belongs to the stored value and
        is consumed: passed on, then zeroed (an earlier write of that element, or its value before this
        kernel, no longer influences anything through it)."""
        ptr, w = s.operands
        if not ptr.type.is_float or _grad_of(ptr) is None:
            return
        gp, _, _ = self._grad_ptr(s, ptr)
        if w.type.is_float and id(w) in self.active:
            self.acc(w, self.b.emit(Op.GLOBAL_LOAD, gp.type, (gp,)))
        self.b.emit(Op.GLOBAL_STORE, None, (gp, self.b.const(0, gp.type)))

    def _backward_atomic(self, s: Stmt) -> None:
        ptr, w = s.operands
        kind = s.attrs["kind"]
        if not w.type.is_float:
            return
        if self.has_adj(s):
            raise GradientError("the old value returned by an atomic operation is not differentiable", s.loc)
        if ptr.op is Op.ALLOCA:
            if kind != "add":
                raise GradientError(f"atomic_{kind} on a local variable is not differentiable; "
                                    "use ti.min/ti.max", s.loc)
            if self.has_adj(ptr):
                self.acc(w, self.b.emit(Op.LOCAL_LOAD, ptr.type, (self.adj[id(ptr)],)))
            return
        if kind == "add":
            if id(w) not in self.active:
                return
            gp, _, _ = self._grad_ptr(s, ptr)
            if gp is not None:
                self.acc(w, self.b.emit(Op.GLOBAL_LOAD, gp.type, (gp,)))
        elif kind in ("min", "max"):
            # subgradient: the gradient of the final value goes to exactly one operand equal to it (the
            # first whose adjoint runs takes it with an atomic exchange); the value that was in the
            # destination before keeps it only when no operand won
            gp, idx, (wv,) = self._grad_ptr(s, ptr, [w])
            if gp is not None:
                xp = self.b.emit(Op.GLOBAL_PTR, ptr.type, tuple(idx), {"target": ptr.attrs["target"]})
                final = self.b.emit(Op.GLOBAL_LOAD, ptr.type, (xp,))
                won = self.b.emit(Op.IF, None, (self.b.eq(final, wv),), nblocks=2)
                with self.b.inside(won.blocks[0]):
                    zero = self.b.const(0.0, gp.type)
                    taken = self.b.emit(Op.ATOMIC, gp.type, (gp, zero), {"kind": "xchg"})
                    self.acc(w, taken)
        else:
            raise GradientError(f"atomic_{kind} on floats has no derivative", s.loc)

    # -- pushes ---------------------------------------------------------------------------------------
    def _insert_pushes(self) -> None:
        last_at: dict[tuple, Stmt | None] = {}
        for sid, block, anchor in self.anchors:
            values = self.push.get(sid)
            if not values:
                continue
            key = (id(block), id(anchor) if anchor is not None else None)
            after = last_at.get(key, anchor)
            pos = block.stmts.index(after) + 1 if after is not None else 0
            new = []
            for v in values:
                p = Builder.detached(Op.TAPE_PUSH, None, (v,), {"message": self._overflow_text(v)}, v.loc)
                p.block = block
                new.append(p)
            block.stmts[pos:pos] = new
            last_at[key] = new[-1]


def _active(body: Block) -> set[int]:
    """Ids of the values (and locals) that depend on a field with a gradient: only their adjoints can reach
    a .grad field, so the others are never accumulated (e.g. a ray's positions from the camera)."""
    active: set[int] = set()
    changed = True
    while changed:  # a loop-carried local may become active on a later pass
        changed = False
        for s in walk(body):
            if id(s) in active:
                continue
            op = s.op
            if op in (Op.LOCAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.ALLOCA:
                on, s = id(s.operands[1]) in active, s.operands[0]
                if id(s) in active:
                    continue
            elif op is Op.GLOBAL_LOAD:
                on = _grad_of(s.operands[0]) is not None
            elif op is Op.LOCAL_LOAD:
                on = id(s.operands[0]) in active
            else:
                # through integers too, so that a float rebuilt from one (bit_cast) still meets the
                # missing-rule error instead of a silent zero
                on = s.type is not None and any(id(o) in active for o in s.operands)
            if on:
                active.add(id(s))
                changed = True
    return active


def _reaching(body: Block) -> set[int]:
    """Ids of the values (and locals) from which a write of an element with a gradient can be reached: the
    adjoint of any other value is exactly zero, so none is computed. Besides saving work, this keeps a dead
    value's infinite derivative out of the gradient (`v = v * v * v` overflowing to inf in a loop whose
    result is never used gave `0 * inf = NaN` in x.grad, as in taichi)."""
    live: set[int] = set()
    stmts = list(walk(body))
    changed = True
    while changed:  # a loop-carried local becomes live on a later pass
        changed = False
        for s in reversed(stmts):
            op = s.op
            if op in (Op.GLOBAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.GLOBAL_PTR:
                feeds = s.operands[1:] if _grad_of(s.operands[0]) is not None or id(s) in live else ()
            elif op in (Op.LOCAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.ALLOCA:
                feeds = s.operands[1:] if id(s.operands[0]) in live else ()
            elif id(s) not in live or op is Op.GLOBAL_LOAD:
                continue
            else:  # every operand, integers too (a float rebuilt from one must still meet its missing rule)
                feeds = s.operands
            for o in feeds:
                if id(o) not in live and o.op is not Op.CONST:
                    live.add(id(o))
                    changed = True
    return live


def _trip(b: Builder, begin: Stmt, end: Stmt) -> Stmt:
    """end - begin, folded when both are constants (so tape_bound can read it)."""
    if begin.op is Op.CONST and end.op is Op.CONST:
        return b.const(end.attrs["value"] - begin.attrs["value"], end.vtype)
    return b.binary(Op.SUB, end, begin)


def _split_header(body: Block) -> tuple[list[Stmt], list[Stmt]]:
    """A while body as (header: statements up to the last exit test, rest). The header only computes
    the loop condition, so the adjoint replays it but never reverses it."""
    last = -1
    for k, s in enumerate(body.stmts):
        if s.op is Op.IF and len(s.blocks[0].stmts) == 1 and s.blocks[0].stmts[0].attrs.get("header"):
            last = k
        elif s.op in (Op.IF, Op.RANGE_FOR, Op.WHILE, Op.GLOBAL_STORE, Op.ATOMIC):
            break
    return body.stmts[: last + 1], body.stmts[last + 1:]


def make_adjoint(kernel: Kernel) -> bool:
    """The pipeline step: replace the kernel body with its adjoint."""
    structurize(kernel.body)
    r = Reverse(kernel)
    kernel.body = r.run()
    kernel.uses_tape = r.used_tape or any(s.op is Op.TAPE_PUSH for s in walk(kernel.body))
    kernel.tape_bound = tape_bound(kernel.body) if kernel.uses_tape else 0
    kernel.returns = []
    return True


def tape_bound(block: Block) -> int | None:
    """Most tape entries one thread holds at once, when loop bounds are compile-time constants (None:
    unknown, e.g. a while loop or a run-time bound). A parallel loop's body resets the tape every
    iteration, and a loop of the backward walk ("reversed") pops in each iteration what that iteration
    pushed (a recomputed body), so both count once."""
    total = 0
    for s in block.stmts:
        if s.op is Op.TAPE_PUSH:
            total += 1
            continue
        if not s.blocks:
            continue
        inner = [tape_bound(b) for b in s.blocks]
        known = [n for n in inner if n is not None]
        if len(known) < len(inner):
            return None
        n = max(known)
        if n == 0:
            continue
        if s.op is Op.RANGE_FOR and s.attrs.get("parallel"):
            total = max(total, n)
        elif s.op is Op.RANGE_FOR and s.attrs.get("reversed"):
            total += n
        elif s.op is Op.RANGE_FOR:
            b, e = s.operands
            if b.op is not Op.CONST or e.op is not Op.CONST:
                return None
            total += max(e.attrs["value"] - b.attrs["value"], 0) * n
        elif s.op is Op.WHILE:
            return None
        else:
            total += n
    return total
