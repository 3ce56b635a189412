"""Python AST -> IR. One visitor; a `visit_<Node>` per supported construct, a located error for the rest.

The visitor evaluates what is known at compile time in Python (constants, ti.static, Python objects
such as fields) and emits IR for everything that depends on run-time values. ti.func calls are inlined.
"""

from __future__ import annotations

import ast
import builtins
import operator

from simgrad import dtypes as dt
from simgrad.errors import (
    SimgradAssertionError,
    SimgradError,
    SimgradIndexError,
    SimgradNameError,
    SimgradSyntaxError,
    SimgradTypeError,
)
from simgrad.frontend.frames import Frame
from simgrad.frontend.refs import LOCAL_REFS, DynamicElementRef, GlobalRef, MatrixRef, StructRef, VarRef
from simgrad.frontend.source import FunctionSource
from simgrad.frontend.speculate import speculatable
from simgrad.ir import context
from simgrad.ir.builder import Builder
from simgrad.ir.nodes import Kernel
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.field import Field, MatrixField, ScalarField
from simgrad.lang.functions import BoundFunc
from simgrad.lang.matrix import Matrix, _swizzle_indices, dtype_of
from simgrad.lang.struct import Struct, StructField, StructType
from simgrad.lang.types import MatrixType

_BINOPS = {
    ast.Add: operators.add, ast.Sub: operators.sub, ast.Mult: operators.mul, ast.Div: operators.truediv,
    ast.FloorDiv: operators.floordiv, ast.Mod: operators.mod, ast.Pow: operators.pow,
    ast.BitAnd: operators.bit_and, ast.BitOr: operators.bit_or, ast.BitXor: operators.bit_xor,
    ast.LShift: operators.shl, ast.RShift: operators.shr,
    ast.MatMult: lambda a, b: a @ b,
}
_AUG_KIND = {
    ast.Add: "add", ast.Sub: "sub", ast.Mult: "mul", ast.Div: "div", ast.FloorDiv: "floordiv",
    ast.Mod: "mod", ast.Pow: "pow", ast.BitAnd: "and", ast.BitOr: "or", ast.BitXor: "xor",
    ast.LShift: "shl", ast.RShift: "shr",
}
_OVERFLOW_CHECKED = (ast.Add, ast.Sub, ast.Mult, ast.LShift)
_OVERFLOW_OPS = (Op.ADD, Op.SUB, Op.MUL, Op.SHL)
_CMPOPS = {
    ast.Lt: operators.lt, ast.LtE: operators.le, ast.Gt: operators.gt, ast.GtE: operators.ge,
    ast.Eq: operators.eq, ast.NotEq: operators.ne,
}
_PY_CMP = {ast.Is: operator.is_, ast.IsNot: operator.is_not, ast.In: lambda a, b: a in b,
           ast.NotIn: lambda a, b: a not in b}  # `is` is refused (eval_Compare), `in` only on ti.static values


class KernelLowering:
    """Compiles one kernel instantiation. `bind` the parameters, then `compile_body`."""

    MAX_INLINE_DEPTH = 64

    def __init__(self, ir: Kernel, src: FunctionSource, debug: bool = False, parallel_listgen: bool = False):
        self.ir = ir
        # a sparse struct-for lists its active cells in parallel, in no fixed order (the GPU: one thread would
        # walk every cell), instead of in one serial pass in cell order (the CPU)
        self.parallel_listgen = parallel_listgen
        self.builder = Builder(ir.body)
        self.frames = [Frame(src, True)]
        self.loop_stack: list[str] = []  # "parallel" | "serial" for enclosing run-time loops
        self.depth = 0  # run-time control flow nesting across inlined frames
        self.next_loop_config: dict | None = None
        self.debug = debug
        self.return_types: list | None = None
        self.return_struct: StructType | None = None  # a struct return type (compiler/driver.py), checked at return
        self.guard = None  # a fingerprint.Guard when this instantiation may be cached
        self.stopped_grads: dict[int, object] = {}  # id(FieldRef) -> the top-level loop ti.stop_grad is in
        self.static_loops: list[tuple] = []  # the ti.static loops being unrolled (frontend/loops.py _unroll)
        self.static_scope = 0  # > 0 while the arguments of a ti.static(...) call are evaluated (frontend/calls.py)
        # specialisation key -> (IR Function, result annotation) of the recursive real functions (frontend/realfuncs.py)
        self.real_functions: dict = {}

    @property
    def frame(self) -> Frame:
        return self.frames[-1]

    # -- what lang objects ask of the compiler on the context stack (lang imports no frontend) -----------
    def call_func(self, fn, args: list, kwargs: dict):
        """A ti.func called from Python code running at compile time: inlined here."""
        from simgrad.frontend.calls import call_func

        return call_func(self, fn, args, kwargs, self.frame.src.tree)

    def stop_grad(self, field) -> None:
        """ti.stop_grad(x): no gradient flows through x's elements for the rest of this top-level loop
        (the rest of the kernel when called outside one), as in Taichi."""
        fields = field.comps if hasattr(field, "comps") else [field]
        top = self.builder.blocks[1].parent if len(self.builder.blocks) > 1 else None
        for f in fields:
            self.stopped_grads[id(f.ref())] = top

    def grad_stopped(self, target) -> bool:
        if id(target) not in self.stopped_grads:
            return False
        top = self.stopped_grads[id(target)]
        return top is None or (len(self.builder.blocks) > 1 and self.builder.blocks[1].parent is top)

    def emit_fill(self, field, value) -> None:
        from simgrad.frontend.loops import emit_fill

        emit_fill(field, value)

    # -- scopes --------------------------------------------------------------------------------------
    def bind(self, name: str, value) -> None:
        self.frame.scopes[-1][name] = value

    def lookup(self, name: str, node: ast.AST):
        for scope in reversed(self.frame.scopes):
            if name in scope:
                return scope[name]
        src = self.frame.src
        if self.guard is not None:
            self.guard.name(src.func, name)
        if name in src.closure:
            return src.closure[name]
        if name in src.globals:
            return src.globals[name]
        if hasattr(builtins, name):
            return getattr(builtins, name)
        raise SimgradNameError(f'Name "{name}" is not defined', src.loc(node))

    def new_var(self, value, dtype=None):
        """A fresh local initialised with `value` (a scalar, a matrix or a struct)."""
        if isinstance(value, Struct):
            members = {k: self.new_var(v, _member_dtype(value, k)) for k, v in value.items()}
            return StructRef(value._type, members)
        if isinstance(value, Matrix):
            t = dt.from_any(dtype) if dtype is not None else dtype_of(value)
            refs = [VarRef(t) for _ in value.entries]
            ref = MatrixRef(refs, value.n, value.m)
            ref.store(value)
            return ref
        if isinstance(value, Expr):
            t = value.dtype
        elif isinstance(value, bool):
            t = dt.Defaults.ip
        else:
            t = operators.to_expr(value).dtype
        if dtype is not None:
            t = dt.from_any(dtype)
        ref = VarRef(t)
        ref.store(value)
        return ref

    # -- entry points ---------------------------------------------------------------------------------
    def compile_body(self) -> None:
        context.push(self)
        try:
            self.visit_block(self.frame.src.tree.body)
            if self.return_types and not self.frame.has_returned:
                raise SimgradSyntaxError("Kernel has a return type but does not have a return statement",
                                         self.loc(self.frame.src.tree))
        finally:
            context.pop()

    def loc(self, node):
        return self.frame.src.loc(node)

    def visit_block(self, stmts: list[ast.stmt]) -> None:
        for k, s in enumerate(stmts):
            frame = self.frame
            if frame.has_returned:  # after a compile-time return (a taken ti.static branch, unrolled loop)
                return
            before = frame.dynamic_returns
            self.visit_stmt(s)
            if frame.returned_here:  # `return` inside run-time control flow: the rest of this block is dead
                frame.returned_here = False
                return
            if frame.dynamic_returns != before:  # `s` may have returned: leave loops, guard what follows
                assert frame.ret_flag is not None
                if len(self.loop_stack) > frame.loop_base:
                    stop = self.builder.emit(Op.IF, None, (operators.ne(frame.ret_flag.load(), 0).stmt,), nblocks=2)
                    with self.dynamic(stop.blocks[0]):
                        self._loop_jump(s, Op.BREAK, written=False)
                rest = stmts[k + 1:]
                if rest:
                    with self.unless_returned():
                        self.visit_block(rest)
                return

    def unless_returned(self):
        """Enter `if not returned:` (after an early return inside run-time control flow of a ti.func), for
        the code that follows it. A ti.static loop's break/continue still belongs to that loop inside it."""
        frame = self.frame
        assert frame.ret_flag is not None
        guard = self.builder.emit(Op.IF, None, (operators.eq(frame.ret_flag.load(), 0).stmt,), nblocks=2)
        return self.dynamic(guard.blocks[0], return_guard=True)

    def _entry_var(self, dtype) -> VarRef:
        """A local of the current ti.func declared (zeroed) at its entry, whatever block we are in now."""
        frame = self.frame
        assert frame.entry_block is not None
        alloca = Builder.detached(Op.ALLOCA, dtype, (), None, self.builder.loc, frame.entry_block)
        zero = Builder.detached(Op.LOCAL_STORE, None, (alloca, self.builder.const(0, dtype)), None,
                                self.builder.loc, frame.entry_block)
        frame.entry_block.stmts[frame.entry_index:frame.entry_index] = [alloca, zero]
        frame.entry_index += 2
        ref = VarRef.__new__(VarRef)
        ref.alloca = alloca
        return ref

    def _dynamic_return(self, value, node) -> None:
        """`return v` inside run-time control flow of a ti.func: store v and the flag, leave the loops of
        this function (break), and let visit_block skip or guard everything after it."""
        frame = self.frame
        if frame.entry_block is None:
            raise SimgradSyntaxError("Return inside non-static if/for is not supported here", self.loc(node))
        if frame.ret_flag is None:
            frame.ret_flag = self._entry_var(dt.i32)
            ann = self.eval(frame.src.tree.returns) if frame.src.tree.returns is not None else None
            if isinstance(value, Matrix):
                t = ann.dtype if isinstance(ann, MatrixType) else dtype_of(value)
                frame.ret_var = MatrixRef([self._entry_var(t) for _ in value.entries], value.n, value.m)
            elif isinstance(value, (Expr, int, float)) and not isinstance(value, bool):
                t = ann if isinstance(ann, dt.DataType) else operators.to_expr(value).dtype
                frame.ret_var = self._entry_var(t)
            elif value is not None:
                raise SimgradSyntaxError(f"a {type(value).__name__} cannot be returned from inside run-time "
                                         "control flow", self.loc(node))
        if value is not None:
            if frame.ret_var is None:
                raise SimgradSyntaxError("this function returns a value on some paths and nothing on others",
                                         self.loc(node))
            frame.ret_var.store(value)
        assert frame.ret_flag is not None
        frame.ret_flag.store(1)
        if len(self.loop_stack) > frame.loop_base:
            self._loop_jump(node, Op.BREAK, written=False)
        frame.dynamic_returns += 1
        frame.returned_here = True

    def visit_stmt(self, node: ast.stmt) -> None:
        saved = self.builder.loc
        self.builder.loc = self.loc(node)
        try:
            method = getattr(self, "visit_" + type(node).__name__, None)
            if method is None:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):  # Taichi's words
                    where = "ti.kernel" if self.frame.is_kernel else "ti.func"
                    raise SimgradSyntaxError(f"Function definition is not allowed in '{where}': define the "
                                             "ti.func outside and call it", self.loc(node))
                raise SimgradSyntaxError(
                    f'Unsupported node "{type(node).__name__}": the Python construct is not supported in kernels',
                    self.loc(node))
            method(node)
        except SimgradError as e:
            if e.loc is None:
                e.loc = self.loc(node)
                e.args = (str(e),)
            raise
        except (TypeError, ValueError, IndexError, NameError, AttributeError, KeyError, ZeroDivisionError) as e:
            cls = {TypeError: SimgradTypeError, IndexError: SimgradIndexError, NameError: SimgradNameError}
            err = cls.get(type(e), SimgradSyntaxError)
            raise err(f"{type(e).__name__}: {e}", self.loc(node)) from e
        finally:
            self.builder.loc = saved

    # -- statements ---------------------------------------------------------------------------------
    def visit_Expr(self, node: ast.Expr) -> None:
        if isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            return  # docstring
        self.eval(node.value)

    def visit_Pass(self, node) -> None:
        pass

    def visit_Assign(self, node: ast.Assign) -> None:
        value = self.eval(node.value)
        if getattr(value, "ndim", 0) and type(value).__module__ == "numpy" and not _is_static_call(node.value):
            raise SimgradTypeError("Only 0-dimensional numpy array can be used to initialize a scalar expression "
                                   "(keep an array as a compile-time value with ti.static(np.array(...)))",
                                   self.loc(node))
        for target in node.targets:
            self.assign(target, value)

    def _check_not_argument(self, target: ast.expr) -> None:
        if isinstance(target, ast.Name) and target.id in self.frame.arg_names:
            raise SimgradSyntaxError(f'Kernel argument "{target.id}" is immutable in the kernel. If you want to '
                                     f"change its value, please create a new variable ({target.id}_ = {target.id})",
                                     self.loc(target))

    def visit_AnnAssign(self, node: ast.AnnAssign) -> None:
        if not isinstance(node.target, ast.Name):
            raise SimgradSyntaxError("annotated assignment needs a plain name", self.loc(node))
        self._check_not_argument(node.target)
        ann = self.eval(node.annotation)
        value = self.eval(node.value) if node.value is not None else 0
        from simgrad.lang.types import MatrixType

        current = self.frame.scopes[-1].get(node.target.id)
        if isinstance(current, VarRef) and isinstance(ann, dt.DataType):  # Taichi: an assignment, same type only
            if current.dtype is not ann:
                raise SimgradSyntaxError(f"Static assign cannot have type overloading: '{node.target.id}' is "
                                         f"{current.dtype}, annotated {ann} here", self.loc(node))
            current.store(operators.cast(value, ann))
            return

        if isinstance(ann, MatrixType):
            self.bind(node.target.id, self.new_var(ann.make(value), ann.dtype))
        else:
            self.bind(node.target.id, self.new_var(value, ann))

    def assign(self, target: ast.expr, value) -> None:
        if isinstance(target, ast.Name):
            self._check_not_argument(target)
            name = target.id
            current = self._local(name)
            if isinstance(current, LOCAL_REFS):
                current.store(value)
            elif isinstance(current, Expr):  # an argument or loop index: a new local shadows it
                if name not in self.frame.scopes[-1]:  # only in its own scope: else outer reads miss it
                    raise SimgradSyntaxError(
                        f"'{name}' is a kernel argument or loop index of an enclosing scope and cannot be "
                        f"assigned here (arguments are immutable in Taichi); copy it into a local first "
                        f"({name}_ = {name})", self.loc(target))
                self.bind(name, self.new_var(value))
            elif isinstance(value, (Expr, Matrix, int, float, bool, Struct)):
                self.bind(name, self.new_var(value))
            elif type(value) is list:
                self.bind(name, VarList(self, value))
            else:
                self.bind(name, value)
        elif isinstance(target, (ast.Tuple, ast.List)):
            values = list(value.entries if isinstance(value, Matrix) and value.m == 0 else value)
            if len(values) != len(target.elts):
                raise SimgradSyntaxError(
                    f"cannot unpack {len(values)} values into {len(target.elts)} names", self.loc(target)
                )
            for t, v in zip(target.elts, values):
                self.assign(t, v)
        elif isinstance(target, (ast.Subscript, ast.Attribute)):
            ref = self.ref(target)
            if ref is None:
                self._python_setitem(target, value)
            else:
                ref.store(value)
        else:
            raise SimgradSyntaxError(f"cannot assign to {type(target).__name__}", self.loc(target))

    def _python_setitem(self, target, value):
        obj = self.eval(target.value)
        if isinstance(target, ast.Subscript):
            index = self.eval_index(target.slice)
            if isinstance(obj, VarList) and obj.is_var(index):
                obj.ref(index).store(value)  # a run-time store, as Taichi's element variables take it
                return
            depth = obj.depth if isinstance(obj, VarList) else 0
            if self.frame.dynamic_depth > depth and isinstance(obj, (list, dict)):
                raise SimgradSyntaxError(
                    "a Python list or dict element is assigned inside run-time control flow (an `if` or loop "
                    "on run-time values): the assignment would happen at compile time, whatever the condition; "
                    "keep the value in a local variable (or a ti.Vector) instead", self.loc(target))
            if self.guard is not None:
                self.guard.taint("a Python object is modified at compile time")
            obj[index] = value
        else:
            setattr(obj, target.attr, value)

    def _local(self, name):
        for scope in reversed(self.frame.scopes):
            if name in scope:
                return scope[name]
        return None

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        kind = _AUG_KIND.get(type(node.op))
        if kind is None:
            raise SimgradSyntaxError(f"augmented assignment {type(node.op).__name__} is not supported",
                                     self.loc(node))
        self._check_not_argument(node.target)
        value = self.eval(node.value)
        if isinstance(node.target, ast.Name):
            ref = self._local(node.target.id)
            if not isinstance(ref, LOCAL_REFS):
                cur = self.eval(node.target)
                self.assign(node.target, _BINOPS[type(node.op)](cur, value))
                return
        else:
            ref = self.ref(node.target)
            if ref is None:
                cur = self.eval(node.target)
                self._python_setitem(node.target, _BINOPS[type(node.op)](cur, value))
                return
        if self.debug and kind in ("mul", "shl"):  # a plain update (load, op, store): checked as Taichi does
            block = context.builder().block
            first = len(block.stmts)
            ref.atomic(kind, value)
            for st in block.stmts[first:]:
                self._check_overflow(node, Expr(st))
            return
        ref.atomic(kind, value)

    def visit_If(self, node: ast.If) -> None:
        cond = self.eval(node.test)
        if not isinstance(cond, (Expr, Matrix)):
            # a Python value decides at compile time; unless it is ti.static(...), Taichi still treats the
            # body as nested, so a for loop inside is not an outermost (parallel) loop
            # and its body is a scope of its own (Taichi's: `if True: a = 0` leaves no `a` after the if)
            nested = not _is_static_call(node.test)
            self.depth += nested
            if nested:
                self.frame.scopes.append({})
            try:
                self.visit_block(node.body if cond else node.orelse)
            finally:
                self.depth -= nested
                if nested:
                    self.frame.scopes.pop()
            return
        if isinstance(cond, Matrix):
            raise SimgradTypeError("the condition of an if must be a scalar (use .any() / .all())",
                                   self.loc(node.test))
        c = operators.ne(cond, 0)
        stmt = self.builder.emit(Op.IF, None, (c.stmt,), nblocks=2)
        for block, body in zip(stmt.blocks, (node.body, node.orelse)):
            with self.dynamic(block):
                self.visit_block(body)

    def dynamic(self, block, return_guard: bool = False):
        """Enter a run-time block: a new scope, one more level of run-time nesting."""
        compiler = self
        guards = int(return_guard)

        class _Ctx:
            def __enter__(self):
                compiler.builder.blocks.append(block)
                compiler.frame.scopes.append({})
                compiler.frame.dynamic_depth += 1
                compiler.frame.guard_depth += guards
                compiler.depth += 1

            def __exit__(self, *exc):
                compiler.depth -= 1
                compiler.frame.guard_depth -= guards
                compiler.frame.dynamic_depth -= 1
                compiler.frame.scopes.pop()
                compiler.builder.blocks.pop()

        return _Ctx()

    def visit_While(self, node: ast.While) -> None:
        if node.orelse:
            raise SimgradSyntaxError("while ... else is not supported in kernels", self.loc(node))
        loop = self.builder.emit(Op.WHILE, None, (), nblocks=1)
        self.loop_stack.append("serial")
        try:
            with self.dynamic(loop.blocks[0]):
                cond = self.eval(node.test)
                if isinstance(cond, Expr):
                    stop = self.builder.emit(Op.IF, None, (operators.eq(cond, 0).stmt,), nblocks=2)
                    with self.builder.inside(stop.blocks[0]):
                        self.builder.emit(Op.BREAK, None, attrs={"header": True})
                elif not cond:
                    self.builder.emit(Op.BREAK, None, attrs={"header": True})
                self.visit_block(node.body)
        finally:
            self.loop_stack.pop()

    def static_jump_target(self) -> tuple:
        """Where a break/continue is: the frame, the run-time loops and the run-time branches open (return
        guards not counted). It belongs to the innermost ti.static loop if that loop was entered here."""
        frame = self.frame
        return frame, len(self.loop_stack), frame.dynamic_depth - frame.guard_depth

    def visit_Break(self, node) -> None:
        self._loop_jump(node, Op.BREAK)

    def visit_Continue(self, node) -> None:
        self._loop_jump(node, Op.CONTINUE)

    def _loop_jump(self, node, op: Op, written: bool = True) -> None:
        """A break/continue; `written`: the user's own, not the break an early return makes."""
        if self.static_loops and self.static_loops[-1] == self.static_jump_target():
            from simgrad.frontend.loops import StaticJump

            raise StaticJump(op is Op.BREAK)
        word = op.name.lower()
        if written and self.static_loops and self.static_loops[-1][:2] == self.static_jump_target()[:2]:
            # the innermost loop is a ti.static one, and a run-time if lies in between (Taichi's words)
            raise SimgradSyntaxError(f"You are trying to `{word}` a static `for` loop, but the `{word}` statement "
                                     "is inside a non-static `if`", self.loc(node))
        if not self.loop_stack:
            raise SimgradSyntaxError(f"'{word}' outside a run-time loop", self.loc(node))
        if op is Op.BREAK and self.loop_stack[-1] == "parallel":
            raise SimgradSyntaxError(
                "Cannot break in the outermost loop: it is a parallel for; use a serial loop "
                "(ti.loop_config(serialize=True)) or a flag", self.loc(node))
        self.builder.emit(op, None)

    def visit_Return(self, node: ast.Return) -> None:
        frame = self.frame
        if frame.is_kernel and frame.dynamic_depth:
            raise SimgradSyntaxError(
                "Return inside non-static if/for is not supported in a kernel; assign the result to a variable "
                "and return it at the end", self.loc(node))
        value = self.eval(node.value) if node.value is not None else None
        if frame.dynamic_depth or frame.ret_flag is not None:
            self._dynamic_return(value, node)
            return
        if frame.is_kernel:
            self.emit_kernel_return(value, node)
        frame.return_value = value
        frame.has_returned = True

    def emit_kernel_return(self, value, node) -> None:
        if value is None and self.return_types is None:  # a bare `return` / `return None`
            return
        if self.return_types is None:
            raise SimgradSyntaxError("this kernel returns a value but has no return annotation (-> ti.f32)",
                                     self.loc(node))
        want = self.return_struct
        have = getattr(value, "_type", None) if isinstance(value, Struct) else None
        if want is not None and have is not None and have is not want and \
                [(k, repr(t)) for k, t in have.members.items()] != [(k, repr(t)) for k, t in want.members.items()]:
            raise SimgradTypeError(f"the kernel returns a struct of type {have!r}, but is annotated with {want!r}",
                                   self.loc(node))

        def flat(v) -> list:  # a struct's leaves in order, matrices by entry
            if isinstance(v, Struct):
                return [x for _, leaf in _struct_leaves(v) for x in flat(leaf)]
            return list(v.entries) if isinstance(v, Matrix) else [v]

        values = [x for v in value for x in flat(v)] if isinstance(value, (tuple, list)) else flat(value)
        if len(values) != len(self.return_types):
            raise SimgradTypeError(f"kernel returns {len(values)} values but is annotated with "
                                   f"{len(self.return_types)}", self.loc(node))
        for slot, (v, t) in enumerate(zip(values, self.return_types)):
            e = operators.cast_expr(operators.to_expr(v, t), t)
            self.builder.emit(Op.RET_STORE, None, (e.stmt,), {"slot": slot})

    def visit_Assert(self, node: ast.Assert) -> None:
        """The condition is evaluated (its calls run, as in Taichi) but checked only in debug mode; one known
        at compile time fails then and there, with the run-time assertion's error class."""
        cond = self.eval(node.test)
        if not self.debug:
            return
        from simgrad.frontend.printing import FormattedString

        msg = self.eval(node.msg) if node.msg is not None else None
        if msg is not None and not isinstance(msg, (str, FormattedString)):
            msg = str(msg)
        text: str | list = msg if isinstance(msg, str) else ast.unparse(node.test)
        if not isinstance(cond, Expr):
            if not cond:
                raise SimgradAssertionError(f"assertion failed at compile time: {text}", self.loc(node))
            return
        args: tuple = ()
        if isinstance(msg, FormattedString):  # formatted on the host from the values the kernel reports
            from simgrad.runtime.abi import ERR_MAX_ARGS

            if len(msg.values) > ERR_MAX_ARGS:
                raise SimgradSyntaxError(f"an assert message can show at most {ERR_MAX_ARGS} kernel values, "
                                         f"this one has {len(msg.values)}", self.loc(node))
            args, text = tuple(v.stmt for v in msg.values), msg.template()
        self.builder.emit(Op.ASSERT, None, (operators.ne(cond, 0).stmt, *args), {"message": text})

    def visit_For(self, node: ast.For) -> None:
        from simgrad.frontend.loops import lower_for

        if node.orelse:
            raise SimgradSyntaxError("for ... else is not supported in kernels", self.loc(node))
        lower_for(self, node)

    # -- expressions ----------------------------------------------------------------------------------
    def eval(self, node: ast.expr):
        method = getattr(self, "eval_" + type(node).__name__, None)
        if method is None:
            raise SimgradSyntaxError(
                f"the Python expression '{type(node).__name__}' is not supported in kernels", self.loc(node))
        return method(node)

    def eval_Constant(self, node):
        return node.value

    def eval_Name(self, node: ast.Name):
        v = self.lookup(node.id, node)
        if isinstance(v, LOCAL_REFS):
            return v.load()
        if isinstance(v, Field) and v._auto_name:
            v.adopt_name(node.id)
        return v

    def eval_Tuple(self, node):
        return tuple(self.eval(e) for e in node.elts)

    def eval_List(self, node):
        return [self.eval(e) for e in node.elts]

    def eval_Dict(self, node):
        out: dict = {}
        for k, v in zip(node.keys, node.values):
            if k is None:  # {**other}
                out.update(self.eval(v))
            else:
                out[self.eval(k)] = self.eval(v)
        return out

    def eval_Starred(self, node):
        return _Starred(self.eval(node.value))

    def eval_BinOp(self, node: ast.BinOp):
        a, b = self.eval(node.left), self.eval(node.right)
        if isinstance(node.op, ast.Mod) and isinstance(a, str):  # "x = %d" % x
            from simgrad.frontend.printing import percent_format

            return percent_format(a, b)
        r = _BINOPS[type(node.op)](a, b)
        if self.debug and type(node.op) in _OVERFLOW_CHECKED:
            self._check_overflow(node, r)
        return r

    def _check_overflow(self, node: ast.BinOp | ast.AugAssign, r) -> None:
        """Debug mode: an integer + - * << the user wrote reports its overflow as Taichi does (printed with the
        line, the wrapped value kept: codegen/arith.py _checked_overflow); arithmetic simgrad emits itself (an
        index's offset, a power's squarings) is never checked."""
        for e in (r.entries if isinstance(r, Matrix) else [r]):
            s = e.stmt if isinstance(e, Expr) else None
            if s is not None and s.op in _OVERFLOW_OPS and s.type.is_int and s.type is not dt.u1:
                s.attrs["overflow"] = (self.frame.src.file, node.lineno, node.col_offset, node.end_lineno,
                                       node.end_col_offset, self.frame.src.tree.name)

    def eval_UnaryOp(self, node: ast.UnaryOp):
        v = self.eval(node.operand)
        if isinstance(node.op, ast.USub):
            return operators.neg(v)
        if isinstance(node.op, ast.UAdd):
            return v
        if isinstance(node.op, ast.Invert):
            return operators.bit_not(v)
        if isinstance(v, (Expr, Matrix)):
            return operators.logical_not(v)
        return not v

    def eval_BoolOp(self, node: ast.BoolOp):
        """Python's `and`/`or`, as in Taichi: the value is `b if a else a` / `a if a else b`, and `b` is
        evaluated only when needed, so `i < n and x[i] > 0` never reads x[n]."""
        is_and = isinstance(node.op, ast.And)
        result = self.eval(node.values[0])
        for sub in node.values[1:]:
            if not isinstance(result, (Expr, Matrix)):  # Python short-circuit on compile-time values
                if (not result) if is_and else result:
                    return result
                result = self.eval(sub)
                continue
            if isinstance(result, Matrix):  # element-wise on matrices: both sides, 1/0 entries
                other = self.eval(sub)
                result = operators.logical_and(result, other) if is_and else operators.logical_or(result, other)
                continue
            left, right = (lambda a=result: a), (lambda n=sub: self.eval(n))
            result = self.choose(result, right, left) if is_and else self.choose(result, left, right)
        return result

    def eval_Compare(self, node: ast.Compare):
        left = self.eval(node.left)
        result = None
        for op, right_node in zip(node.ops, node.comparators):
            right = self.eval(right_node)
            if type(op) in _PY_CMP:  # Taichi's rules: `is` never, `in` on ti.static values only
                if isinstance(op, (ast.Is, ast.IsNot)):
                    name = "is" if isinstance(op, ast.Is) else "is not"
                    raise SimgradSyntaxError(f'Operator "{name}" in Taichi scope is not supported (use == on '
                                             "values; compare objects outside the kernel)", self.loc(node))
                if not self.static_scope:
                    name = "In" if isinstance(op, ast.In) else "NotIn"
                    raise SimgradSyntaxError(f'"{name}" is only supported inside `ti.static`: wrap the comparison, '
                                             "ti.static(a in b)", self.loc(node))
                r = _PY_CMP[type(op)](left, right)
            else:
                r = _CMPOPS[type(op)](left, right)
            result = r if result is None else operators.logical_and(result, r)
            left = right
        return result

    def eval_IfExp(self, node: ast.IfExp):
        cond = self.eval(node.test)
        if not isinstance(cond, (Expr, Matrix)):
            return self.eval(node.body if cond else node.orelse)
        if isinstance(cond, Matrix):  # Taichi's rule: an element-wise choice is ti.select's
            raise SimgradSyntaxError('The condition of `a if cond else b` is a vector or matrix: Please use '
                                     '"ti.select" instead.', self.loc(node))
        return self.choose(cond, lambda: self.eval(node.body), lambda: self.eval(node.orelse))

    def choose(self, cond: Expr, then_fn, else_fn):
        """A value chosen at run time (ternary, and/or), each side evaluated in its own branch. Sides
        that may run unchosen (no effects, loads only of elements known in bounds: frontend/speculate.py)
        are hoisted and picked by a select (one differentiable op, no branch for LLVM to if-convert); any
        other side stays guarded, as in Taichi (`x[i] if i < n else 0` never reads x[n])."""
        parent = self.builder.block
        c = operators.ne(cond, 0)
        stmt = self.builder.emit(Op.IF, None, (c.stmt,), nblocks=2)
        values = []
        for block, fn in zip(stmt.blocks, (then_fn, else_fn)):
            with self.dynamic(block):
                values.append(fn())
        at = parent.stmts.index(stmt)
        if speculatable(stmt.blocks):
            hoisted = [x for block in stmt.blocks for x in block.stmts]
            for x in hoisted:
                x.block = parent
            parent.stmts[at:at + 1] = hoisted
            return operators.select(c, *values)
        a, b = values
        if isinstance(a, Matrix) or isinstance(b, Matrix):
            if isinstance(a, Matrix) and isinstance(b, Matrix) and a.shape != b.shape:
                raise SimgradTypeError("both sides of a run-time choice must be matrices of one shape",
                                       self.builder.loc)
            mat = a if isinstance(a, Matrix) else b  # a scalar side is broadcast to it (Taichi's `0 if c else v`)
            values = [v if isinstance(v, Matrix) else Matrix(_entries=[v] * len(mat.entries), n=mat.n, m=mat.m)
                      for v in values]
            t = dt.promote(dtype_of(values[0]), dtype_of(values[1]))
            ref: MatrixRef | VarRef = MatrixRef([VarRef(t) for _ in mat.entries], mat.n, mat.m)
        else:
            ref = VarRef(_choice_type(a, b))
        new = parent.stmts[at + 1:]  # the result's ALLOCAs go before the IF
        del parent.stmts[at + 1:]
        parent.stmts[at:at] = new
        for block, v in zip(stmt.blocks, values):
            with self.builder.inside(block):
                ref.store(v)
        return ref.load()

    def eval_Attribute(self, node: ast.Attribute):
        ref = self.ref(node)
        if ref is not None:
            return ref.load()
        if isinstance(node.value, (ast.Name, ast.Subscript, ast.Attribute)):
            base_ref = self.ref(node.value)
            if isinstance(base_ref, StructRef) and node.attr in base_ref.stype.methods:
                return BoundFunc(base_ref.stype.methods[node.attr], base_ref)  # `self` is the struct, by reference
        value = self.eval(node.value)
        try:
            return getattr(value, node.attr)
        except AttributeError:
            raise SimgradSyntaxError(f"'{type(value).__name__}' has no attribute '{node.attr}'",
                                     self.loc(node)) from None

    def eval_NamedExpr(self, node: ast.NamedExpr):
        """`(y := expr)`: assigns y as a statement would, and is the assigned value."""
        value = self.eval(node.value)
        self.assign(node.target, value)
        return self.eval(node.target)

    def eval_Subscript(self, node: ast.Subscript):
        ref = self.ref(node)
        if ref is not None:
            return ref.load()
        value = self.eval(node.value)
        index = self.eval_index(node.slice)
        if isinstance(value, (Expr, Matrix)):
            _refuse_negative(index, self.loc(node))
        return value[index]

    def eval_index(self, node):
        if isinstance(node, ast.Tuple):
            return tuple(self.eval_index(e) if isinstance(e, ast.Slice) else self.eval(e) for e in node.elts)
        if isinstance(node, ast.Slice):
            return slice(*(self.eval(p) if p is not None else None for p in (node.lower, node.upper, node.step)))
        return self.eval(node)

    def eval_JoinedStr(self, node: ast.JoinedStr):
        from simgrad.frontend.printing import FormattedString

        return FormattedString.from_ast(self, node)

    def eval_ListComp(self, node: ast.ListComp):
        return self._comprehension(node, list)

    def eval_DictComp(self, node: ast.DictComp):
        return self._comprehension(node, dict)

    def eval_GeneratorExp(self, node):
        return self._comprehension(node, list)

    def _comprehension(self, node, kind):
        out = []

        def rec(gens):
            if not gens:
                out.append((self.eval(node.key), self.eval(node.value)) if isinstance(node, ast.DictComp)
                           else self.eval(node.elt))
                return
            g = gens[0]
            iterable = self.eval(g.iter)
            if isinstance(iterable, (Expr,)):
                raise SimgradSyntaxError("comprehensions must iterate over compile-time sequences", self.loc(g))
            for item in iterable:
                self.frame.scopes.append({})
                try:
                    self._bind_target(g.target, item)
                    if all(bool(self.eval(c)) for c in g.ifs):
                        rec(gens[1:])
                finally:
                    self.frame.scopes.pop()

        rec(node.generators)
        return kind(out)

    def _bind_target(self, target, value):
        if isinstance(target, ast.Name):
            self.bind(target.id, value)
        else:
            for t, v in zip(target.elts, value):
                self._bind_target(t, v)

    def eval_Call(self, node: ast.Call):
        from simgrad.frontend.calls import call

        return call(self, node)

    def eval_Lambda(self, node):
        raise SimgradSyntaxError("lambda is not supported in kernels; use a @ti.func", self.loc(node))

    # -- references (assignable places) -------------------------------------------------------------------
    def ref(self, node: ast.expr):
        """The Ref for an assignable expression, or None when it is a plain Python object."""
        if isinstance(node, ast.Name):
            v = self.lookup(node.id, node)
            return v if isinstance(v, LOCAL_REFS) else None
        if isinstance(node, ast.Subscript):
            base_ref = self.ref(node.value)
            if base_ref is not None:
                if not isinstance(base_ref, MatrixRef):
                    return None
                key = self.eval_index(node.slice)
                key = key if isinstance(key, tuple) else (key,)
                _refuse_negative(key, self.loc(node))
                if any(isinstance(k, Expr) for k in key) and not any(isinstance(k, slice) for k in key):
                    return DynamicElementRef(base_ref, key)
                return base_ref.index(key if len(key) > 1 else key[0])
            if not _maybe_global(node.value):
                return None
            base = self.eval(node.value)
            if isinstance(base, (Field,)) or _is_array_arg(base):
                index = self.eval_index(node.slice)
                if not isinstance(base, Field):  # a field's Python-number index may be negative (Taichi's rule)
                    _refuse_negative(index, self.loc(node))
                return global_ref(self, base, index, node)
            if _is_builder_arg(base):
                return base.ref(self.eval_index(node.slice), self.loc(node))
            return None
        if isinstance(node, ast.Attribute):
            if not isinstance(node.value, (ast.Name, ast.Subscript, ast.Attribute)):
                return None
            base_ref = self.ref(node.value)
            if isinstance(base_ref, MatrixRef) and _is_swizzle(node.attr):
                return base_ref.swizzle(node.attr)
            if isinstance(base_ref, StructRef):
                return base_ref.member(node.attr)
            return None
        return None


def _refuse_negative(index, loc) -> None:
    """Taichi's rule for subscripts of kernel values other than fields (local matrices, ndarrays): a compile-time
    index or slice bound below zero is a syntax error, not Python's count from the end."""
    if isinstance(index, (tuple, list)):
        for k in index:
            _refuse_negative(k, loc)
    elif isinstance(index, slice):
        _refuse_negative((index.start, index.stop), loc)
    elif isinstance(index, (int, float)) and not isinstance(index, bool) and index < 0:
        raise SimgradSyntaxError("Negative indices are not supported in Taichi kernels.", loc)


class VarList(list):
    """A list bound to a name in a kernel: as Taichi's expr_init does, each run-time value (scalar or matrix)
    becomes a local variable, so ``v[i] = x`` under run-time control flow is a run-time store. Reading the
    list (indexing, iterating, unpacking) loads the variables; ``depth`` is the run-time nesting it was bound
    at (assigning a Python element deeper would happen at compile time: KernelLowering._python_setitem refuses)."""

    def __init__(self, comp: KernelLowering, values):
        self.depth = comp.frame.dynamic_depth
        super().__init__(comp.new_var(v) if isinstance(v, (Expr, Matrix)) else v
                         for v in values)

    def is_var(self, index) -> bool:
        return isinstance(index, int) and isinstance(list.__getitem__(self, index), LOCAL_REFS)

    def ref(self, index):
        return list.__getitem__(self, index)

    @staticmethod
    def _value(v):
        return v.load() if isinstance(v, LOCAL_REFS) else v

    def __getitem__(self, index):
        item = list.__getitem__(self, index)
        return [self._value(v) for v in item] if isinstance(index, slice) else self._value(item)

    def __iter__(self):
        return (self._value(v) for v in list.__iter__(self))

    def __reversed__(self):
        return (self._value(v) for v in list.__reversed__(self))

    def values(self) -> list:
        return list(self.__iter__())

    def __add__(self, other):
        return self.values() + list(other)

    def __radd__(self, other):
        return list(other) + self.values()

    def __mul__(self, n):
        return self.values() * n

    __rmul__ = __mul__

    def copy(self):
        return self.values()

    def __contains__(self, item):
        return item in self.values()


def _choice_type(a, b) -> dt.DataType:
    """The type of `a if c else b` for scalars: as `a + b` would promote them."""
    if isinstance(a, Expr) and isinstance(b, Expr):
        return dt.promote(a.dtype, b.dtype)
    if isinstance(a, Expr) or isinstance(b, Expr):
        e, lit = (a, b) if isinstance(a, Expr) else (b, a)
        return dt.promote(e.dtype, operators._literal_type(lit, e.dtype))
    return dt.promote(operators._literal_type(a, None), operators._literal_type(b, None))


def _maybe_global(node) -> bool:
    return isinstance(node, (ast.Name, ast.Attribute, ast.Subscript, ast.Call))


def _is_swizzle(name: str) -> bool:
    """Letters of one of Taichi's groups (xyzw, rgba, stpq: `v.p` is v[2])."""
    return _swizzle_indices(name) is not None


def _is_array_arg(v) -> bool:
    from simgrad.frontend.arrays import ArrayArg

    return isinstance(v, ArrayArg)


def _is_builder_arg(v) -> bool:
    from simgrad.frontend.arrays import BuilderArg

    return isinstance(v, BuilderArg)


def _is_static_call(node: ast.expr) -> bool:
    """`ti.static(...)` / `static(...)` as written in the source."""
    if not isinstance(node, ast.Call):
        return False
    f = node.func
    return (isinstance(f, ast.Attribute) and f.attr == "static") or (isinstance(f, ast.Name) and f.id == "static")


class _Starred:
    def __init__(self, value):
        self.value = value


def global_ref(comp: KernelLowering, base, index, node):
    """Ref of `field[index]` / `array[index]`, with indices cast to i32 and shifted by field offsets."""
    from simgrad.frontend.arrays import ArrayArg

    idx: tuple
    if index is None:
        idx = ()
    elif isinstance(index, tuple):
        idx = index
    else:
        idx = (index,)
    flat: list = []
    for i in idx:
        if isinstance(i, Matrix):
            flat.extend(i.entries)
        else:
            flat.append(i)
    ndim = base.ndim
    if isinstance(base, Field) and len(flat) == ndim - 1 and base.parent() is not None and \
            getattr(base.parent(), "kind", None) == "dynamic":
        from simgrad.lang.sparse import DynamicList

        return DynamicList(base.parent(), flat)  # `w[i].append(v)`, `w[i].length()`
    if len(flat) != ndim:
        what = f"field {base.name}" if isinstance(base, Field) else f"ndarray '{base.name}'"
        raise SimgradIndexError(f"{what} has {ndim} dimension(s) but is indexed with {len(flat)} index(es)"
                                + (" (use x[None] for a 0-d field)" if ndim == 0 else ""), comp.loc(node))
    if isinstance(base, Field):
        base.check_alive(comp.loc(node))
    offset = base._components()[0].offset if isinstance(base, Field) else None
    exprs = []
    for k, i in enumerate(flat):
        if isinstance(i, float) or (isinstance(i, Expr) and i.dtype.is_float):
            raise SimgradTypeError("field indices must be integers (use ti.cast(i, ti.i32) or int(i))",
                                   comp.loc(node))
        if offset:
            i = operators.sub(i, offset[k])
        e = operators.to_expr(i, dt.i32)
        if e.dtype is not dt.i32:
            e = operators.cast_expr(e, dt.i32)
        exprs.append(e)
    if isinstance(base, ArrayArg):
        return base.ref(exprs)
    return _element_ref(base, exprs)


def _element_ref(base: Field, exprs: list):
    if isinstance(base, ScalarField):
        return GlobalRef(base, exprs, base.dtype)
    if isinstance(base, MatrixField):
        refs = [GlobalRef(c, exprs, c.dtype) for c in base.comps]
        return MatrixRef(refs, base.n, base.ncols)
    assert isinstance(base, StructField)
    return StructRef(base.stype, {k: _element_ref(f, exprs) for k, f in base.members.items()})


def _struct_leaves(value: Struct, prefix: tuple = ()) -> list:
    out: list = []
    for k, v in value.items():
        out += _struct_leaves(v, prefix + (k,)) if isinstance(v, Struct) else [(prefix + (k,), v)]
    return out


def _member_dtype(value: Struct, name: str):
    """The declared type of a struct member (a local copy keeps it), or None for an untyped ti.Struct."""
    t = value._type.members[name] if value._type is not None else None
    return t.dtype if isinstance(t, MatrixType) else t if isinstance(t, dt.DataType) else None


__all__ = ["KernelLowering", "global_ref"]
