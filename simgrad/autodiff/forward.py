"""Forward-mode differentiation (Jacobian-vector products) of a kernel, in the IR.

Every float value `s` gets a tangent `ds`, emitted right after `s` in the same block, so it is in scope
wherever `s` is: constants, arguments and values read from fields without a placed dual have none (zero);
a load of a field with a dual (`x.dual`, ti.root.lazy_dual()) loads the tangent from it; a store or an
atomic add into such a field stores or adds the tangent into its dual as well. Locals get a tangent local
beside them. Control flow is kept as it is: a forward kernel runs the primal computation once, with the
tangents alongside, so loops, branches and break/continue need no tape.

The derivative of an elementwise operation is its JVP rule, rules.FORWARD, which sits beside every reverse
rule and is made from it: for a scalar operation the VJP contribution to operand k, `g * df/dx_k`, is linear
in `g`, so with `g` set to the tangent of x_k it is the term `df/dx_k * dx_k` of the JVP. Both modes thus
differentiate exactly the same operations, and one without a rule is refused in both, naming it.
"""

from __future__ import annotations

from simgrad.errors import GradientError
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt
from simgrad.ir.ops import Op

from .rules import FORWARD, ZERO_GRADIENT


def make_forward(kernel: Kernel) -> bool:
    """Add the tangent computation to `kernel` in place (the pipeline step of forward-mode kernels)."""
    _Forward(kernel).block(kernel.body)
    return True


def adjoint_then_forward(kernel: Kernel) -> bool:
    """The adjoint of `kernel` with tangents (forward over reverse): inside ti.ad.FwdMode, `kernel.grad()`
    writes d(gradient) into the gradients' duals, i.e. Hessian-vector products H @ seed."""
    from .validate import check_and_adjoint

    check_and_adjoint(kernel)
    f = _Forward(kernel)
    f.block(kernel.body)
    if f.taped and kernel.tape_bound is not None:
        kernel.tape_bound *= 2  # a value and its tangent per entry at most
    return True


def _dual_of(ptr: Stmt):
    target = ptr.attrs["target"]
    if isinstance(target, FieldRef) and target.dual is not None and not ptr.attrs.get("stop_grad"):
        return target.dual
    return None  # ndarrays have no duals (as in Taichi)


class _Forward:
    def __init__(self, kernel: Kernel):
        self.kernel = kernel
        self.tan: dict[int, Stmt] = {}  # statement id -> its tangent (absent: zero)
        self.taped = False  # tangents pushed on the adjoint's tape

    def block(self, block: Block) -> None:
        out: list[Stmt] = []
        for s in block.stmts:
            for nested in s.blocks:
                self.block(nested)
            if s.op is Op.TAPE_PUSH and s.operands and s.operands[0].type is not None \
                    and s.operands[0].type.is_float:
                # (an adjoint's tape, forward over reverse) every float value goes on with its tangent (zero when
                # it has none), the tangent first, so that popping the value, then its tangent, takes them off
                # in the right order
                value = s.operands[0]
                tangent = self.t(value) or Builder.constant(0.0, value.vtype, s.loc)
                push = Builder.detached(Op.TAPE_PUSH, None, (tangent,), dict(s.attrs), s.loc)
                push.block = block
                out.append(push)
                self.taped = True
            out.append(s)
            scratch = Block()
            b = Builder(scratch)
            b.loc = s.loc
            self.statement(b, s)
            for x in scratch.stmts:
                x.block = block
            out.extend(scratch.stmts)
        block.stmts = out

    def t(self, s: Stmt) -> Stmt | None:
        return self.tan.get(id(s))

    def statement(self, b: Builder, s: Stmt) -> None:
        op = s.op
        if op is Op.TAPE_POP:
            if s.type is not None and s.type.is_float:  # every float entry was pushed with its tangent
                self.tan[id(s)] = b.emit(Op.TAPE_POP, s.type, (), dict(s.attrs))
            return
        if op is Op.ALLOCA:
            if s.type is not None and s.type.is_float:
                var = b.emit(Op.ALLOCA, s.type)
                b.emit(Op.LOCAL_STORE, None, (var, b.const(0.0, s.type)))
                self.tan[id(s)] = var
        elif op is Op.LOCAL_LOAD:
            tvar = self.t(s.operands[0])
            if tvar is not None:
                self.tan[id(s)] = b.emit(Op.LOCAL_LOAD, s.type, (tvar,))
        elif op is Op.LOCAL_STORE:
            tvar = self.t(s.operands[0])
            if tvar is not None:
                b.emit(Op.LOCAL_STORE, None, (tvar, self._value(b, s.operands[1], tvar.vtype)))
        elif op is Op.GLOBAL_LOAD:
            dual = _dual_of(s.operands[0])
            if dual is not None and s.vtype.is_float:
                self.tan[id(s)] = b.emit(Op.GLOBAL_LOAD, s.type, (self._ptr(b, s.operands[0], dual),))
        elif op is Op.GLOBAL_STORE:
            ptr = s.operands[0]
            dual = _dual_of(ptr)
            if dual is not None:
                b.emit(Op.GLOBAL_STORE, None, (self._ptr(b, ptr, dual), self._value(b, s.operands[1], dual.dtype)))
        elif op is Op.ATOMIC:
            self._atomic(b, s)
        elif op is Op.CAST:
            src = s.operands[0]
            if s.vtype.is_float and src.vtype.is_float and self.t(src) is not None:
                self.tan[id(s)] = b.cast(self.tan[id(src)], s.vtype)
        elif s.type is None or not s.type.is_float or not s.operands:
            return
        elif all(self.t(o) is None for o in s.operands):
            return
        elif op in FORWARD:
            total = FORWARD[op](b, [self.t(o) for o in s.operands], *s.operands)
            if total is not None:
                self.tan[id(s)] = b.cast(total, s.vtype) if total.type is not s.type else total
        elif op in ZERO_GRADIENT or op is Op.RANDOM:
            return
        else:
            raise GradientError(f"no derivative rule for the operation '{op.name.lower()}' on {s.type} "
                                "(forward mode)", s.loc)

    def _value(self, b: Builder, v: Stmt, t) -> Stmt:
        d = self.t(v)
        return b.const(0.0, t) if d is None else (d if d.type is t else b.cast(d, t))

    @staticmethod
    def _ptr(b: Builder, ptr: Stmt, dual) -> Stmt:
        return b.emit(Op.GLOBAL_PTR, dual.dtype, tuple(ptr.operands), {"target": dual})

    def _atomic(self, b: Builder, s: Stmt) -> None:
        ptr, v = s.operands
        kind = s.attrs["kind"]
        if ptr.op is Op.GLOBAL_PTR:
            dual = _dual_of(ptr)
            if dual is None:
                return
            target = self._ptr(b, ptr, dual)
        else:
            local = self.t(ptr)
            if local is None:
                return
            target = local
        if kind in ("add", "sub"):
            d = self._value(b, v, s.vtype)
            self.tan[id(s)] = b.emit(Op.ATOMIC, s.type, (target, d), {"kind": kind})
        elif ptr.op is not Op.GLOBAL_PTR and kind in ("min", "max"):
            # a local's min/max (`s` is its old value): the tangent follows the operand that wins
            old = b.emit(Op.LOCAL_LOAD, s.type, (target,))
            take = b.lt(v, s) if kind == "min" else b.gt(v, s)
            b.emit(Op.LOCAL_STORE, None, (target, b.select(take, self._value(b, v, s.vtype), old)))
        else:
            raise GradientError(f"forward mode does not differentiate atomic '{kind}' on a field with a dual",
                                s.loc)
