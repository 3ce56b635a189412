"""Remove break/continue from serial loops before differentiation.

A jump becomes a store to a flag, and every statement that could follow the jump is guarded by
`if flag == 0`. Afterwards the only jump left in a loop is the header test of a while loop (the first
statements of its body), so the adjoint can replay a loop as "n iterations, each one complete", with n
recorded on the tape. This is what lets us differentiate while/break/continue, which Taichi refuses.
A serial range-for that can break is first turned into a while loop over a counter, so that it too runs
(and its adjoint replays) only the iterations before the break.
"""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.builder import Builder
from simgrad.ir.nodes import Block, Stmt
from simgrad.ir.ops import Op


def _new(op, type_, operands, block, loc, attrs=None, nblocks=0) -> Stmt:
    return Builder.detached(op, type_, operands, attrs, loc, block, nblocks)


def _const(v, loc, type_=dt.i32) -> Stmt:
    return Builder.constant(v, type_, loc)


def structurize(block: Block) -> None:
    """Rewrite every loop in `block` (recursively) that contains its own break/continue."""
    for s in list(block.stmts):
        for b in s.blocks:
            structurize(b)
        if s.op in (Op.RANGE_FOR, Op.WHILE) and _has_jump(s.blocks[0]):
            if s.op is Op.RANGE_FOR and _has_jump(s.blocks[0], (Op.BREAK,)) and not s.attrs.get("parallel"):
                s = _range_to_while(s)
            _rewrite_loop(s)


def _has_jump(block: Block, kinds=(Op.BREAK, Op.CONTINUE)) -> bool:
    for s in block.stmts:
        if s.op in kinds and not s.attrs.get("header"):
            return True
        if s.op is Op.IF and any(_has_jump(b, kinds) for b in s.blocks):
            return True
    return False


def _range_to_while(loop: Stmt) -> Stmt:
    """`for i in range(a, b)` that can break becomes `i = a; while i < b: (i += 1 first) body`.

    Guarding the body alone would leave the statements before the jump running in every iteration after
    the break; as a while loop, the adjoint replays exactly the iterations that ran (its trip count is on
    the tape) and the tape holds nothing for the skipped ones."""
    outer, loc, t = loop.block, loop.loc, loop.type
    assert outer is not None, "internal: a loop outside any block"
    begin, end = loop.operands
    idx = _new(Op.ALLOCA, t, (), outer, loc)
    init = _new(Op.LOCAL_STORE, None, (idx, begin), outer, loc)
    w = _new(Op.WHILE, None, (), outer, loc, nblocks=1)
    body = w.blocks[0]
    i = _new(Op.LOCAL_LOAD, t, (idx,), body, loc)
    done = _new(Op.GE, dt.i32, (i, end), body, loc)
    stop = _new(Op.IF, None, (done,), body, loc, nblocks=2)
    stop.blocks[0].stmts.append(_new(Op.BREAK, None, (), stop.blocks[0], loc, {"header": True}))
    nxt = _new(Op.ADD, t, (i, _const(1, loc, t)), body, loc)
    step = _new(Op.LOCAL_STORE, None, (idx, nxt), body, loc)
    old = loop.blocks[0].stmts
    for x in old:
        x.block = body
    _replace_uses(old, loop, i)
    body.stmts = [i, done, stop, nxt, step] + old
    k = outer.stmts.index(loop)
    outer.stmts[k:k + 1] = [idx, init, w]
    return w


def _replace_uses(stmts: list[Stmt], old: Stmt, new: Stmt) -> None:
    for s in stmts:
        if any(o is old for o in s.operands):
            s.operands = tuple(new if o is old else o for o in s.operands)
        for b in s.blocks:
            _replace_uses(b.stmts, old, new)


def _rewrite_loop(loop: Stmt) -> None:
    loc = loop.loc
    body = loop.blocks[0]
    # a parallel loop (continue only) gets a flag per iteration; one outside would be shared by threads
    outer = body if loop.attrs.get("parallel") else loop.block
    assert outer is not None, "internal: a loop outside any block"
    flag = _new(Op.ALLOCA, dt.i32, (), outer, loc)
    init = _new(Op.LOCAL_STORE, None, (flag, _const(0, loc)), outer, loc)
    _replace_jumps(body, flag)
    head = []
    if loop.op is Op.WHILE:
        n = 0
        while n < len(body.stmts) and not _is_header_exit(body.stmts[n]) and _is_pure(body.stmts[n]):
            n += 1
        if n < len(body.stmts) and _is_header_exit(body.stmts[n]):
            head = body.stmts[: n + 1]
            body.stmts = body.stmts[n + 1 :]
    # every iteration: clear "continue" (1), keep "break" (2); then run the body only while no flag is set
    ld = _new(Op.LOCAL_LOAD, dt.i32, (flag,), body, loc)
    keep = _new(Op.BIT_AND, dt.i32, (ld, _const(2, loc)), body, loc)
    reset = _new(Op.LOCAL_STORE, None, (flag, keep), body, loc)
    stop = []
    if loop.op is Op.WHILE:
        c = _new(Op.NE, dt.i32, (keep, _const(0, loc)), body, loc)
        exit_if = _new(Op.IF, None, (c,), body, loc, nblocks=2)
        brk = _new(Op.BREAK, None, (), exit_if.blocks[0], loc, {"header": True})
        exit_if.blocks[0].stmts.append(brk)
        stop = [c, exit_if]
    rest = body.stmts
    body.stmts = [ld, keep, reset] + stop + head
    guard = _guarded(rest, flag, body, loc)
    body.stmts += guard
    i = 0 if outer is body else outer.stmts.index(loop)
    outer.stmts[i:i] = [flag, init]


def _is_header_exit(s: Stmt) -> bool:
    return s.op is Op.IF and len(s.blocks[0].stmts) == 1 and bool(s.blocks[0].stmts[0].attrs.get("header"))


def _is_pure(s: Stmt) -> bool:
    return s.op not in (Op.LOCAL_STORE, Op.GLOBAL_STORE, Op.ATOMIC, Op.IF, Op.RANGE_FOR, Op.WHILE, Op.BREAK,
                        Op.CONTINUE, Op.PRINT, Op.ASSERT, Op.RET_STORE)


def _replace_jumps(block: Block, flag: Stmt) -> None:
    for k, s in enumerate(block.stmts):
        if s.op in (Op.BREAK, Op.CONTINUE) and not s.attrs.get("header"):
            value = _const(2 if s.op is Op.BREAK else 1, s.loc)
            block.stmts[k] = _new(Op.LOCAL_STORE, None, (flag, value), block, s.loc, {"jump": True})
        elif s.op is Op.IF:
            for b in s.blocks:
                _replace_jumps(b, flag)


def _sets_flag(s: Stmt) -> bool:
    if s.op is Op.LOCAL_STORE and s.attrs.get("jump"):
        return True
    return s.op is Op.IF and any(_sets_flag(x) for b in s.blocks for x in b.stmts)


def _guarded(stmts: list[Stmt], flag: Stmt, block: Block, loc) -> list[Stmt]:
    """`stmts` with everything after a possible jump wrapped in `if flag == 0`."""
    out: list[Stmt] = []
    for k, s in enumerate(stmts):
        s.block = block
        if s.op is Op.IF:
            for b in s.blocks:
                b.stmts = _guarded(b.stmts, flag, b, loc)
        out.append(s)
        if _sets_flag(s) and k + 1 < len(stmts):
            ld = _new(Op.LOCAL_LOAD, dt.i32, (flag,), block, loc)
            ok = _new(Op.EQ, dt.i32, (ld, _const(0, loc)), block, loc)
            g = _new(Op.IF, None, (ok,), block, loc, nblocks=2)
            g.blocks[0].stmts = _guarded(stmts[k + 1 :], flag, g.blocks[0], loc)
            out += [ld, ok, g]
            break
    return out
