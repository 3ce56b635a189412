"""IR statements and blocks: a typed, hierarchical SSA form. A statement's value is the statement."""

from __future__ import annotations

from collections.abc import Iterator

from simgrad.dtypes import DataType
from simgrad.errors import Loc
from simgrad.ir.ops import Op


class Block:
    """An ordered list of statements; control statements own nested blocks."""

    __slots__ = ("stmts", "parent")

    def __init__(self, parent: Stmt | None = None):
        self.stmts: list[Stmt] = []
        self.parent = parent

    def __iter__(self) -> Iterator[Stmt]:
        return iter(self.stmts)

    def __len__(self) -> int:
        return len(self.stmts)


class Stmt:
    """One IR statement. Created only through `Builder`, which checks operand types."""

    __slots__ = ("op", "type", "operands", "attrs", "loc", "blocks", "id", "block")
    _counter = 0

    def __init__(self, op: Op, type: DataType | None, operands: tuple, attrs: dict, loc: Loc | None):
        self.op = op
        self.type = type
        self.operands = operands
        self.attrs = attrs
        self.loc = loc
        self.blocks: tuple[Block, ...] = ()
        self.block: Block | None = None
        Stmt._counter += 1
        self.id = Stmt._counter

    @property
    def vtype(self) -> DataType:
        """The type of the value this statement defines; asking a store or a branch is an internal error."""
        t = self.type
        if t is None:
            raise AssertionError(f"internal: {self!r} defines no value")
        return t

    def __repr__(self) -> str:
        return f"%{self.id}:{self.type}={self.op.name.lower()}"


def walk(block: Block) -> Iterator[Stmt]:
    """Every statement in `block`, depth first, in program order."""
    for s in block.stmts:
        yield s
        for b in s.blocks:
            yield from walk(b)


def indices_of(ptr: Stmt) -> tuple[Stmt, ...]:
    """A GLOBAL_PTR's index operands, whether or not passes/lower_access.py has appended its offset."""
    return ptr.operands[:-1] if ptr.attrs.get("lowered") else ptr.operands


def offset_form(s: Stmt) -> tuple[Stmt | None, int]:
    """(base, constant) with s == base + constant, looking through integer +/- constants; (None, value) for a
    constant. Two indices with the same base and different constants never name the same element."""
    c = 0
    while True:
        if s.op is Op.CONST:
            return None, c + s.attrs["value"]
        if s.op in (Op.ADD, Op.SUB) and s.operands[1].op is Op.CONST:
            c += s.operands[1].attrs["value"] * (1 if s.op is Op.ADD else -1)
            s = s.operands[0]
        elif s.op is Op.ADD and s.operands[0].op is Op.CONST:
            c += s.operands[0].attrs["value"]
            s = s.operands[1]
        else:
            return s, c


class Kernel:
    """The IR of one kernel instantiation: a body block plus what the launcher needs to know."""

    def __init__(self, name: str):
        self.name = name
        self.body = Block()
        self.returns: list[DataType] = []
        self.ret_slot = 0  # the first context slot after the arguments: return values go there
        self.uses_tape = False  # an adjoint that pushes values on the per-thread tape (autodiff sets it)
        self.tape_bound: int | None = None  # tape entries a thread needs, when the loop bounds prove it
        self.functions: list[Function] = []  # the real functions its CALLs (and theirs) reach


class Function(Kernel):
    """A real function of a kernel (a recursive ti.real_func, frontend/calls.py): a body block that begins
    with its PARAMs and ends with one FUNC_RETURN; the passes run on it as on a kernel body, codegen emits
    it as an LLVM function. `returns` are its results' types (not kernel return slots)."""

    def __init__(self, name: str, params: list[DataType], returns: list[DataType], loc: Loc | None):
        super().__init__(name)
        self.params = params
        self.returns = returns
        self.loc = loc

    def ir_name(self) -> str:
        return f"@{self.name}"
