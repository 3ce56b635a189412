"""IR -> LLVM IR text, the part every LLVM target shares: the `LOWERING` table maps each Op to the
function that emits it; structured control flow maps to basic blocks.

A kernel becomes one entry function `void entry(ptr ctx)` (the context's slots: runtime/abi.py). How
atomics are done was decided before (passes/parallel_strategy.py); how a top-level parallel loop runs is
the target's: codegen/cpu.py outlines it into a task for the thread pool.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np

from simgrad import dtypes as dt
from simgrad.codegen import arith
from simgrad.codegen.access import lower_check_index as check_index
from simgrad.codegen.access import lower_global_ptr as global_address
from simgrad.codegen.alias import MemoryFacts, root_facts
from simgrad.codegen.sparse import lower_sparse_action, lower_sparse_cell, lower_tree_root
from simgrad.ir.nodes import Block, Kernel, Stmt
from simgrad.ir.ops import OPS, Op
from simgrad.passes.parallel_strategy import ATOMIC, PAIR, PLAIN, PRIVATE, REDUCE
from simgrad.passes.privatize import access_key
from simgrad.runtime import abi, fpenv


def llvm_type(t: dt.DataType) -> str:
    return t.llvm


def const_text(value, t: dt.DataType) -> str:
    if t.is_float:
        if t is dt.f16:
            return f"0xH{np.float16(value).view(np.uint16):04X}"
        if t is dt.f32:
            value = float(np.float32(value))
        return "0x{:016X}".format(struct.unpack("<Q", struct.pack("<d", float(value)))[0])
    if t is dt.u1:
        return "true" if value else "false"
    return str(int(value))


class ModuleText:
    """Declarations and globals shared by the functions of one kernel module."""

    def __init__(self) -> None:
        self.decls: set[str] = set()
        self.globals: list[str] = []
        self.functions: list[str] = []
        self.facts = MemoryFacts()  # field memory's alias scopes (codegen/alias.py)

    def declare(self, text: str) -> None:
        self.decls.add(text)

    def string(self, s: str) -> str:
        data = s.encode() + b"\0"
        name = f"@.str{len(self.globals)}"
        esc = "".join(chr(b) if 32 <= b < 127 and b not in (34, 92) else f"\\{b:02X}" for b in data)
        self.globals.append(f'{name} = private unnamed_addr constant [{len(data)} x i8] c"{esc}"')
        return name

    def text(self) -> str:
        return "\n".join(sorted(self.decls) + self.globals + self.facts.globals() + self.functions
                         + [_RUNTIME_HELPERS]) + "\n"


_RUNTIME_HELPERS = r"""
define internal void @sg_report(ptr %ctx, i64 %code, i64 %value) noinline {
  %ep = getelementptr i64, ptr %ctx, i64 @CTX_ERR@
  %err = load ptr, ptr %ep
  %r = cmpxchg ptr %err, i64 0, i64 %code monotonic monotonic
  %ok = extractvalue { i64, i1 } %r, 1
  br i1 %ok, label %store, label %done
store:
  %vp = getelementptr i64, ptr %err, i64 1
  store i64 %value, ptr %vp
  br label %done
done:
  ret void
}

define internal i32 @sg_rand_u32(ptr %ctx, i32 %tid) {
  %rp = getelementptr i64, ptr %ctx, i64 @CTX_RNG@
  %base = load ptr, ptr %rp
  %off = mul i32 %tid, 16
  %s = getelementptr i8, ptr %base, i32 %off
  %p1 = getelementptr i32, ptr %s, i32 1
  %p2 = getelementptr i32, ptr %s, i32 2
  %p3 = getelementptr i32, ptr %s, i32 3
  %x = load i32, ptr %s
  %y = load i32, ptr %p1
  %z = load i32, ptr %p2
  %w = load i32, ptr %p3
  %t0 = shl i32 %x, 11
  %t = xor i32 %x, %t0
  %t1 = lshr i32 %t, 8
  %t2 = xor i32 %t, %t1
  %w1 = lshr i32 %w, 19
  %w2 = xor i32 %w, %w1
  %n = xor i32 %w2, %t2
  store i32 %y, ptr %s
  store i32 %z, ptr %p1
  store i32 %w, ptr %p2
  store i32 %n, ptr %p3
  ret i32 %n
}
""".replace("@CTX_ERR@", str(abi.CTX_ERR)).replace("@CTX_RNG@", str(abi.CTX_RNG))


class FunctionText:
    """Emits one LLVM function; keeps allocas in the entry block so LLVM can promote them."""

    def __init__(self, gen: KernelCodegen, name: str, params: str, in_task: bool, host_entry: bool = False):
        self.gen = gen
        self.name = name
        self.params = params
        self.in_task = in_task
        self.host_entry = host_entry  # called from the host: it sets the float mode (runtime/fpenv.py)
        self.prologue: list[str] = []
        self.body: list[str] = []
        self.names: dict[Stmt, str] = {}
        self.counter = 0
        self.loops: list[tuple[str, str]] = []  # (break label, continue label)
        self.roots: dict[int, str] = {}
        self.root_ends: dict[int, tuple[int, int]] = {}  # tree -> (its root's prologue line, bytes known there)
        self.array_bases: dict[int, str] = {}
        self.array_shapes: dict[tuple[int, int], str] = {}
        self.tid = "%tid" if in_task else "0"
        self.loop: Stmt | None = None  # the parallel loop whose iterations this function runs (a task)
        self._tape: tuple[str, str, str] | None = None
        self._cancel: str | None = None
        # what the target's task set up (codegen/cpu.py): per-thread sums and per-thread copies
        self.reduction_of: dict[int, str] = {}  # ATOMIC statement -> this thread's partial-sum variable
        self.private_roots: dict[tuple, str] = {}  # (id(field), slice key) -> root of this thread's copy
        self.private_prefix: dict[int, int] = {}  # id(field) -> leading axes that pick the slice
        self.private_marks: dict[str, tuple[str, str] | None] = {}  # root -> (this thread's page map, copy offset of 0)
        self.bound: set[int] = set()  # statements whose value the enclosing loop gives (lower_block skips them)
        self.cursors: dict[int, str] = {}  # dynamic node's pool -> this function's chunk cursor (codegen/sparse.py)
        # TREE_ROOT / SPARSE_CELL -> (pointer, i64 offsets) whose sum is its u64 address (codegen/access.py)
        self.addr_base: dict[Stmt, tuple[str, tuple[str, ...]]] = {}
        # a real function (KernelCodegen.emit_functions): its thread and call depth are parameters, a Ctrl-C
        # leaves it by `exit` (the kernel's entry reports the interruption), its updates of shared places are atomic
        self.is_function = False
        self.depth = "0"
        self.exit = "ret void"
        self.serial = False  # a task variant run only on the calling thread alone: its atomics are plain
        # a task's `!llvm.access.group` (codegen/cpu.py parallel_group): its field loads and stores, which no other
        # iteration of its parallel loop may touch but through atomics; the loop's latch names it
        self.access_group: str | None = None
        self.parallel_loop_md = ""
        # lane loops whose iterations are independent (passes/fission.py, passes/lanes_memory.py `parallel_lanes`):
        # their loop IDs; the group of the one being emitted, which its lane slots' accesses are in
        self.lane_loops: dict[Stmt, str] = {}
        self.lane_group: str | None = None

    def private_root_of(self, ptr: Stmt) -> str | None:
        """The private root an update of this task goes through, if its field is privatised here."""
        if not self.private_roots or ptr.op is not Op.GLOBAL_PTR:
            return None
        tid = id(ptr.attrs["target"])
        nprefix = self.private_prefix.get(tid)
        return None if nprefix is None else self.private_roots.get((tid, access_key(ptr, nprefix)))

    def tmp(self, hint: str = "t") -> str:
        self.counter += 1
        return f"%{hint}.{self.counter}"  # the dot keeps hints ending in digits from clashing

    def label(self, hint: str) -> str:
        self.counter += 1
        return f"{hint}.{self.counter}"

    def emit(self, line: str) -> None:
        self.body.append("  " + line)

    def start_block(self, label: str) -> None:
        self.body.append(f"{label}:")

    def cancel_flag(self) -> str:
        """Pointer to the process's cancel flag (set by Ctrl-C), loaded once per function."""
        if self._cancel is None:
            self._cancel = self.ctx_slot(abi.CTX_CANCEL, "ptr")
        return self._cancel

    def cancelled(self) -> str:
        """An i1: whether Ctrl-C was pressed (the flag read now)."""
        v, c = self.tmp("cancel"), self.tmp("cancelled")
        self.emit(f"{v} = load atomic i32, ptr {self.cancel_flag()} monotonic, align 4")
        self.emit(f"{c} = icmp ne i32 {v}, 0")
        return c

    def cancel_point(self) -> None:
        """Leave the function when Ctrl-C was pressed: a task simply returns (the pool hands out no more
        chunks); the kernel's entry function reports the interruption first."""
        c = self.cancelled()
        stop, go = self.label("stop"), self.label("go")
        self.emit(f"br i1 {c}, label %{stop}, label %{go}")
        self.start_block(stop)
        if not self.in_task and not self.is_function:
            self.emit(f"call void @sg_report(ptr %ctx, i64 {abi.ERR_INTERRUPTED}, i64 0)")
        self.emit(self.exit)
        self.start_block(go)

    def ctx_slot(self, slot: int, ty: str) -> str:
        p = self.tmp("cp")
        v = self.tmp("cv")
        self.prologue.append(f"  {p} = getelementptr i64, ptr %ctx, i64 {slot}")
        self.prologue.append(f"  {v} = load {ty}, ptr {p}")
        return v

    def root(self, tree_id: int) -> str:
        if tree_id not in self.roots:
            table = self.ctx_slot(abi.CTX_ROOTS, "ptr")
            p = self.tmp("rp")
            v = self.tmp("root")
            self.prologue.append(f"  {p} = getelementptr ptr, ptr {table}, i64 {tree_id}")
            self.prologue.append(f"  {v} = load ptr, ptr {p}, !invariant.load !0")
            self.roots[tree_id] = v
            self.root_ends[tree_id] = (len(self.prologue) - 1, 0)
        return self.roots[tree_id]

    def reaches(self, tree_id: int, nbytes: int) -> None:
        """A field of the tree reaches nbytes into its buffer: its root's load says so (codegen/alias.py)."""
        self.root(tree_id)
        line, known = self.root_ends[tree_id]
        if nbytes > known:
            text = self.prologue[line].split(", !invariant.load")[0]
            self.prologue[line] = f"{text}, !invariant.load !0{root_facts(nbytes)}"
            self.root_ends[tree_id] = (line, nbytes)

    def array_base(self, arg) -> str:
        if arg.slot not in self.array_bases:
            self.array_bases[arg.slot] = self.ctx_slot(abi.CTX_ARGS + arg.slot, "ptr")
        return self.array_bases[arg.slot]

    def array_shape(self, arg, dim: int) -> str:
        key = (arg.extents_slot, dim)
        if key not in self.array_shapes:
            self.array_shapes[key] = self.ctx_slot(abi.CTX_ARGS + arg.extents_slot + 1 + dim, "i64")
        return self.array_shapes[key]

    def tape(self) -> tuple[str, str, str]:
        """(base, top variable, capacity) of this function's tape, set up in the prologue on first use."""
        if self._tape is None:
            cap = self.ctx_slot(abi.CTX_TAPE_CAP, "i64")
            if self.in_task:
                all_ = self.ctx_slot(abi.CTX_TAPE, "ptr")
                t64, off, base = self.tmp("tt"), self.tmp("toff"), self.tmp("tbase")
                self.prologue += [f"  {t64} = zext i32 %tid to i64", f"  {off} = mul i64 {t64}, {cap}",
                                  f"  {base} = getelementptr i64, ptr {all_}, i64 {off}"]
            else:
                base = self.ctx_slot(abi.CTX_TAPE_SERIAL, "ptr")
            top = self.tmp("ttop")
            self.prologue += [f"  {top} = alloca i64", f"  store i64 0, ptr {top}"]
            self._tape = (base, top, cap)
        return self._tape

    def v(self, s: Stmt) -> str:
        if s.op is Op.CONST:
            return const_text(s.attrs["value"], s.vtype)
        return self.names[s]

    def text(self) -> str:
        lines = ["entry:", *self.prologue, *self.body]
        attrs = self.gen.fn_attrs
        if self.host_entry and self.gen.switch_fp_mode:
            for d in fpenv.DECLS:
                self.gen.module.declare(d)
            return fpenv.wrap_entry(self.params, attrs, lines)
        return "\n".join([f"define {self.params}{' ' + attrs if attrs else ''} {{", *lines, "}"])


# ti.init(fast_math=True), the default as in Taichi, lets LLVM ignore the sign of zero, which is what
# turns an adjoint's `0.0 + g` into `g` (about 1.5x on MPM adjoints). The other fast-math flags are
# left out on purpose (reassoc only on the sums serial loops carry: KernelCodegen.float_flags): reassoc and
# arcp everywhere break the guarded formulas of the decompositions (small denominators), nnan/ninf would
# break inf sentinels and isnan, and contract made LLVM 22 abort while emitting a f64 matrix-inverse adjoint
# on this CPU.
FAST_MATH_FLAGS = "nsz "


class KernelCodegen:
    """Emits a kernel whose loops and atomics passes/parallel_strategy.py has annotated. How a parallel
    loop runs is the target's (`parallel_loop`, codegen/cpu.py for the CPU); everything else is here."""

    #: sparse pools hand a thread BATCH fresh blocks at a time (runtime/sparse.py): the pool's threads, each with
    #: a slot of its own; a GPU's threads are far more than the slots, so its blocks are bumped one at a time
    batched_alloc = True

    #: float min/max reductions of serial loops as llvm.minimumnum/maximumnum (codegen/arith.py `_REDUCTION`)
    minmax_reductions = True

    #: the function attributes that tell LLVM results are flushed (runtime/fpenv.py), when they are
    flush_attrs = fpenv.CPU_ATTRS

    #: f32 math as ir/vecmath.py's vectorisable functions under fast_math (the CPU; the GPU keeps libdevice)
    vecmath_target = False

    def __init__(self, kernel: Kernel, symbol: str, debug: bool = False, fast_math: bool = True,
                 flush: bool = False):
        self.kernel = kernel
        self.symbol = symbol
        self.debug = debug
        self.fm = FAST_MATH_FLAGS if fast_math else ""
        self.vector_math = fast_math and self.vecmath_target  # codegen/vecmath.py, else libm calls
        # flush-to-zero: every function says so to LLVM; host entries switch the mode (where the host can)
        self.fn_attrs = self.flush_attrs if flush else ""
        self.switch_fp_mode = flush and fpenv.switchable()
        self.module = ModuleText()
        self.error_table: list[tuple] = []  # (kind, loc, detail) per error code - 1
        # context slots after the returns that keep a privatised loop's per-thread copies between launches
        # (allocated zeroed on first use, zeroed again by the final sum; the launcher frees them)
        self.private_slots = 0

    def float_flags(self, s: Stmt) -> str:
        """The fast-math flags of `s`'s float instruction: FAST_MATH_FLAGS, and reassoc on a sum a serial loop
        carries (passes/accumulate.py marks them; fast_math only)."""
        return self.fm + "reassoc " if self.fm and s.attrs.get("reassoc") else self.fm

    def private_slot(self) -> int:
        """The context slot index of one more persistent private buffer."""
        k = abi.CTX_ARGS + self.kernel.ret_slot + len(self.kernel.returns) + 1 + self.private_slots
        self.private_slots += 1
        return k

    def generate(self) -> str:
        f = FunctionText(self, self.symbol, f"void @{self.symbol}(ptr %ctx)", in_task=False, host_entry=True)
        # a new launch starts uncancelled (a Ctrl-C that came before it is Python's to raise)
        f.prologue.append(f"  store atomic i32 0, ptr {f.cancel_flag()} monotonic, align 4")
        self.lower_block(f, self.kernel.body)
        f.cancel_point()  # a parallel loop may have been cut short: say so
        f.emit("ret void")
        self.module.functions.append(f.text())
        self.emit_functions()
        self.module.globals.append("!0 = !{}")
        return self.module.text()

    # -- real functions ------------------------------------------------------------------------------------
    #: calls deep a real function may recurse: a deeper call reports a located error instead of overflowing the
    #: thread's stack (8 MiB for the caller and the pool's threads: 800 bytes a frame)
    max_call_depth = 10000

    def function_text(self, name: str, params: str) -> FunctionText:
        """The emitter of one real function (the GPU target's has its own registers and tape)."""
        return FunctionText(self, name, params, in_task=False)

    def function_symbol(self, func) -> str:
        return f"{self.symbol}_fn{self.kernel.functions.index(func)}"

    @staticmethod
    def result_type(func) -> str:
        """A real function's LLVM return type: void, or a struct of its results."""
        return "{ " + ", ".join(llvm_type(t) for t in func.returns) + " }" if func.returns else "void"

    def emit_functions(self) -> None:
        """`internal RT @sym_fnK(ptr %ctx, i32 %tid, i32 %depth, params...)` per real function: the thread it runs
        on (ti.random's state, thread-indexed buffers) and its call depth travel with each call."""
        for func in self.kernel.functions:
            name, rt = self.function_symbol(func), self.result_type(func)
            params = "".join(f", {llvm_type(t)} %p{k}" for k, t in enumerate(func.params))
            f = self.function_text(name, f"internal {rt} @{name}(ptr %ctx, i32 %tid, i32 %depth{params})")
            f.is_function, f.tid, f.depth = True, "%tid", "%depth"
            f.exit = f"ret {rt} zeroinitializer" if func.returns else "ret void"
            self.lower_block(f, func.body)
            self.module.functions.append(f.text())

    def emit_print(self, f: FunctionText, fmt: str, args: list[str]) -> None:
        """printf(fmt, args...) on the host, flushed at once (a kernel's output interleaves with Python's)."""
        self.module.declare("declare i32 @printf(ptr, ...)")
        self.module.declare("declare i32 @fflush(ptr)")
        f.emit(f"call i32 (ptr, ...) @printf(ptr {fmt}{''.join(', ' + a for a in args)})")
        f.emit("call i32 @fflush(ptr null)")

    def error_code(self, kind: str, loc, detail) -> int:
        self.error_table.append((kind, loc, detail))
        return len(self.error_table)

    def parallel_loop(self, f: FunctionText, s: Stmt) -> None:
        """A top-level parallel RANGE_FOR in the entry function: the target decides how it runs."""
        raise NotImplementedError(f"{type(self).__name__} has no parallel loops")

    def lower_block(self, f: FunctionText, block: Block) -> None:
        stmts = block.stmts
        k = 0
        while k < len(stmts):
            s = stmts[k]
            if f.bound and id(s) in f.bound:
                k += 1
                continue
            if s.op is Op.ATOMIC and f.in_task and atomic_form(f, s) == PAIR:
                # the strategy pass marks `a; ptr; b` triples; lower_access put ptr's offset before ptr
                j = k + 1
                while stmts[j].op is not Op.GLOBAL_PTR:
                    LOWERING[stmts[j].op](self, f, stmts[j])
                    j += 1
                lower_pair(self, f, s, stmts[j], stmts[j + 1])
                k = j + 2
                continue
            LOWERING[s.op](self, f, s)
            k += 1

    def open_reductions(self, f: FunctionText, plan) -> None:
        """Each thread of a parallel loop sums its `+=` updates of a shared place (plan.reductions, decided by
        passes/parallel_strategy.py) into a variable of its own first (every target: a CPU chunk, a GPU thread)."""
        for _place, adds in plan.reductions.values():
            acc = f.tmp("red")
            rty = llvm_type(adds[0].vtype)
            f.prologue += [f"  {acc} = alloca {rty}", f"  store {rty} {const_text(0, adds[0].vtype)}, ptr {acc}"]
            for a in adds:
                f.reduction_of[id(a)] = acc

    def flush_reductions(self, f: FunctionText, plan) -> None:
        """... and adds each sum to the shared place once, atomically, at the end of the thread's work."""
        for place, adds in plan.reductions.values():
            rty = llvm_type(adds[0].vtype)
            total = f.tmp("sum")
            f.emit(f"{total} = load {rty}, ptr {f.reduction_of[id(adds[0])]}")
            if place.op is Op.GLOBAL_PTR:
                lower_global_ptr(self, f, place)
            op = "fadd" if adds[0].vtype.is_float else "add"
            f.emit(f"{f.tmp('old')} = atomicrmw {op} ptr {f.v(place)}, {rty} {total} monotonic")

    def loop_body(self, f: FunctionText, loop: Stmt, brk: str, latch: str) -> None:
        """The body of `loop` (break goes to `brk`, continue to `latch`), then the start of the `latch` block, where
        the caller steps the index (every target's loops: serial, CPU row loops, GPU grid-stride)."""
        f.loops.append((brk, latch))
        self.lower_block(f, loop.blocks[0])
        f.loops.pop()
        f.emit(f"br label %{latch}")
        f.start_block(latch)

    def serial_loop(self, f: FunctionText, s: Stmt, begin: str, end: str, cancel: bool = False) -> None:
        """`for i in [begin, end)`; with `cancel`, in strips of CANCEL_STRIDE iterations with a Ctrl-C check
        before each strip, so the inner loop stays a clean counted loop (LLVM still vectorises it)."""
        ty = llvm_type(s.vtype)
        pre = f.label("pre")
        f.emit(f"br label %{pre}")
        f.start_block(pre)
        head, body, latch, done = f.label("head"), f.label("body"), f.label("latch"), f.label("done")
        exit_to = done
        if cancel:
            # strip: base runs begin, begin + STRIDE, ...; the strip ends at base + STRIDE or at end,
            # decided by the unsigned distance end - base (no overflow near the type's maximum)
            shead, strip, sdone = f.label("strip"), f.label("stripbody"), f.label("stripdone")
            base, stop = f.tmp("base"), f.tmp("stop")
            f.emit(f"br label %{shead}")
            f.start_block(shead)
            f.emit(f"{base} = phi {ty} [{begin}, %{pre}], [{stop}, %{done}]")
            more = f.tmp("more")
            f.emit(f"{more} = icmp slt {ty} {base}, {end}")
            f.emit(f"br i1 {more}, label %{strip}, label %{sdone}")
            f.start_block(strip)
            f.cancel_point()
            dist, far, cut = f.tmp("dist"), f.tmp("far"), f.tmp("cut")
            f.emit(f"{dist} = sub {ty} {end}, {base}")
            f.emit(f"{far} = icmp ugt {ty} {dist}, {CANCEL_STRIDE}")
            f.emit(f"{cut} = add {ty} {base}, {CANCEL_STRIDE}")
            f.emit(f"{stop} = select i1 {far}, {ty} {cut}, {ty} {end}")
            pre = f.label("pre")
            f.emit(f"br label %{pre}")
            f.start_block(pre)
            begin, end, exit_to = base, stop, sdone
        f.emit(f"br label %{head}")
        f.start_block(head)
        i, nxt = f.tmp("i"), f.tmp("inext")
        f.emit(f"{i} = phi {ty} [{begin}, %{pre}], [{nxt}, %{latch}]")
        c = f.tmp("c")
        f.emit(f"{c} = icmp slt {ty} {i}, {end}")
        f.emit(f"br i1 {c}, label %{body}, label %{done}")
        f.start_block(body)
        f.names[s] = i
        self.loop_body(f, s, exit_to, latch)  # a break leaves the strips too
        f.emit(f"{nxt} = add {ty} {i}, 1")
        hint = "llvm.loop.unroll.full" if s.attrs.get("unroll") else \
            "llvm.loop.vectorize.enable" if s.attrs.get("vectorize") else None
        if hint is not None:  # unroll: lower_access's short loop whose copies fold (OwnBlock); vectorize: a loop of
            # fewer trips than LLVM's tiny-trip-count threshold (16), which it would leave scalar
            k = 1000 + 2 * len(self.module.globals)
            value = ", i1 true" if hint.endswith("enable") else ""
            self.module.globals += [f"!{k} = distinct !{{!{k}, !{k + 1}}}", f'!{k + 1} = !{{!"{hint}"{value}}}']
            f.emit(f"br label %{head}, !llvm.loop !{k}")
        else:
            f.emit(f"br label %{head}{self.parallel_latch(f, s)}")
        f.start_block(done)
        if cancel:
            f.emit(f"br label %{shead}")
            f.start_block(sdone)

    def parallel_group(self, f: FunctionText) -> None:
        """Gives task f an access group and its loop the `llvm.loop.parallel_accesses` that names it, for a loop whose
        iterations store to no element another one reads or stores (LoopStrategy.independent; other sharing is a
        race by Taichi's rule, but at one thread taichi runs it in order). Updates (plain ones of owned or private
        elements too), the tape and locals are emitted outside the group. LLVM takes the loop as parallel
        only when every memory access in it is in the group, so one of those leaves it to its own analysis; when
        all are, it needs no run-time overlap checks, which it could not build for a gather (diffmpm3d's g2p
        reads the grid at indices computed from particle positions: "cannot identify array bounds")."""
        k = 1000 + 2 * len(self.module.globals)
        self.module.globals.append(f"!{k} = distinct !{{}}")
        f.access_group = f"!{k}"
        f.parallel_loop_md = self._parallel_loop(f.access_group)

    def parallel_loop_id(self, f: FunctionText) -> str:
        """The `!llvm.loop` of a second loop over task f's iterations (codegen/cpu.py's column split), naming f's
        access group in a loop ID of its own, or '' when f has no group."""
        return f", !llvm.loop {self._parallel_loop(f.access_group)}" if f.access_group else ""

    def _parallel_loop(self, group: str) -> str:
        """A new loop ID whose `llvm.loop.parallel_accesses` names the access group `group`."""
        k = 1000 + 2 * len(self.module.globals)
        self.module.globals += [f"!{k} = distinct !{{!{k}, !{k + 1}}}",
                                f'!{k + 1} = !{{!"llvm.loop.parallel_accesses", {group}}}']
        return f"!{k}"

    def parallel_latch(self, f: FunctionText, s: Stmt) -> str:
        """The `!llvm.loop` of the latch of the loop running task f's iterations of `s` (or of a parallel lane
        loop), or ''."""
        if s in f.lane_loops:
            return f", !llvm.loop {f.lane_loops[s]}"
        return f", !llvm.loop {f.parallel_loop_md}" if f.access_group and s is f.loop else ""

    def need_branch_weights(self) -> None:
        """The `!1` metadata (a cold branch) that failure paths and activations are marked with."""
        if "!1 = " not in "".join(self.module.globals):
            self.module.globals.append('!1 = !{!"branch_weights", i32 1000, i32 1}')

    def _check(self, f, ok_i32: str, code: int, value: str) -> None:
        """Report error `code` (with `value`) unless ok_i32 is nonzero; the failure branch is cold."""
        c = f.tmp("ok")
        f.emit(f"{c} = icmp ne i32 {ok_i32}, 0")
        good, bad = f.label("ok"), f.label("fail")
        f.emit(f"br i1 {c}, label %{good}, label %{bad}, !prof !1")
        f.start_block(bad)
        f.emit(f"call void @sg_report(ptr %ctx, i64 {code}, i64 {value})")
        f.emit(f"br label %{good}")
        f.start_block(good)
        self.need_branch_weights()


Lowering = Callable[[KernelCodegen, FunctionText, Stmt], None]
# iterations of a serial loop between two Ctrl-C checks (a strip takes ~0.1 ms for a cheap body)
CANCEL_STRIDE = 1 << 16


def atomic_form(f: FunctionText, s: Stmt) -> str:
    """How this function does an ATOMIC (passes/parallel_strategy.py): outside tasks always plain; a
    `private|x` update is plain in the variant over per-thread copies and `x` in the others; in a task's serial
    variant (no other thread runs any of its iterations) every update is plain. A real function may run on
    any thread: its updates are atomic."""
    if f.is_function:
        return ATOMIC
    if not f.in_task:
        return PLAIN
    form = s.attrs["strategy"]
    if form.startswith(PRIVATE):
        form = PLAIN if f.private_roots else form[len(PRIVATE):]
    if f.serial and form in (ATOMIC, PAIR):  # the variant the pool runs on one thread alone (codegen/cpu.py)
        return PLAIN
    return form


# -- control flow ------------------------------------------------------------------------------------
def lower_if(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    c = f.tmp("c")
    f.emit(f"{c} = icmp ne i32 {f.v(s.operands[0])}, 0")
    then_l, else_l, end_l = f.label("then"), f.label("else"), f.label("endif")
    f.emit(f"br i1 {c}, label %{then_l}, label %{else_l}")
    f.start_block(then_l)
    g.lower_block(f, s.blocks[0])
    f.emit(f"br label %{end_l}")
    f.start_block(else_l)
    g.lower_block(f, s.blocks[1])
    f.emit(f"br label %{end_l}")
    f.start_block(end_l)


def lower_while(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    head, end = f.label("while"), f.label("endwhile")
    f.emit(f"br label %{head}")
    f.start_block(head)
    f.cancel_point()  # an endless while must still stop on Ctrl-C
    f.loops.append((end, head))
    g.lower_block(f, s.blocks[0])
    f.loops.pop()
    f.emit(f"br label %{head}")
    f.start_block(end)


def lower_break(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.emit(f"br label %{f.loops[-1][0]}")
    f.start_block(f.label("dead"))


def lower_continue(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.emit(f"br label %{f.loops[-1][1]}")
    f.start_block(f.label("dead"))


def lower_range_for(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    if s.attrs.get("parallel") and not f.in_task:
        g.parallel_loop(f, s)
    else:
        b, e = s.operands
        short = b.op is Op.CONST and e.op is Op.CONST and e.attrs["value"] - b.attrs["value"] <= CANCEL_STRIDE
        short = short or bool(s.attrs.get("lanes"))  # a lane loop (passes/lanes.py): at most its group's width
        if s.attrs.get("parallel_lanes"):
            _parallel_lanes(g, f, s)
            return
        g.serial_loop(f, s, f.v(b), f.v(e), cancel=not short)  # a long or unknown one watches Ctrl-C


def _parallel_lanes(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    """A lane loop whose lanes touch no element another lane stores (passes/lanes_memory.py `parallel_lanes`): its
    field accesses and lane slots in an access group of its own, which its loop ID names (field accesses stay in the
    task's group too, when it has one; the slots, reused by every group of iterations, are in the lane loop's only)."""
    k = 1000 + 2 * len(g.module.globals)
    g.module.globals.append(f"!{k} = distinct !{{}}")
    task_group, lanes = f.access_group, f"!{k}"
    if task_group is None:
        f.access_group = lanes
    else:
        k = 1000 + 2 * len(g.module.globals)
        g.module.globals.append(f"!{k} = !{{{task_group}, {lanes}}}")
        f.access_group = f"!{k}"
    f.lane_group = lanes
    f.lane_loops[s] = g._parallel_loop(lanes)
    b, e = s.operands
    g.serial_loop(f, s, f.v(b), f.v(e))
    f.access_group, f.lane_group = task_group, None


# -- memory ------------------------------------------------------------------------------------------
def lower_const(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = const_text(s.attrs["value"], s.vtype)


def lower_arg(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = f.ctx_slot(abi.CTX_ARGS + s.attrs["slot"], llvm_type(s.vtype))


def lower_array_shape(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    v = f.array_shape(s.attrs["arg"], s.attrs["dim"])
    r = f.tmp("sh")
    f.emit(f"{r} = trunc i64 {v} to i32" if s.type is dt.i32 else f"{r} = add i64 {v}, 0")
    f.names[s] = r


def lower_alloca(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    a = f.tmp("var")
    lanes = s.attrs.get("lanes")
    ty = f"[{lanes} x {llvm_type(s.vtype)}]" if lanes else llvm_type(s.vtype)  # one slot per lane (passes/lanes.py)
    f.prologue.append(f"  {a} = alloca {ty}{', align 64' if lanes else ''}")
    f.prologue.append(f"  store {ty} {'zeroinitializer' if lanes else const_text(0, s.vtype)}, ptr {a}")
    f.names[s] = a


def _local_address(f: FunctionText, a: Stmt, lane: Stmt | None) -> str:
    """A local's address; a lane local's slot of `lane` (LOCAL_LOAD / LOCAL_STORE's last operand)."""
    if lane is None:
        return f.v(a)
    p = f.tmp("lane")
    f.emit(f"{p} = getelementptr inbounds {llvm_type(a.vtype)}, ptr {f.v(a)}, {llvm_type(lane.vtype)} {f.v(lane)}")
    return p


def lower_local_load(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    r = f.tmp("l")
    p = _local_address(f, s.operands[0], s.operands[1] if len(s.operands) > 1 else None)
    f.emit(f"{r} = load {llvm_type(s.vtype)}, ptr {p}{_slot_group(f, s, 1)}")
    f.names[s] = r


def lower_local_store(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    a, v = s.operands[:2]
    p = _local_address(f, a, s.operands[2] if len(s.operands) > 2 else None)
    f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {p}{_slot_group(f, s, 2)}")


def _slot_group(f: FunctionText, s: Stmt, lane: int) -> str:
    """A lane slot's access in a parallel lane loop is in the loop's group (a slot is one lane's: never shared);
    elsewhere (a task's group) not, the slots being reused by every group of iterations."""
    return f", !llvm.access.group {f.lane_group}" if len(s.operands) > lane and f.lane_group else ""


def lower_global_ptr(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = global_address(g, f, s)


def lower_thread_index(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = f.tid  # the pool's thread id in a task, 0 in serial code


def lower_check_index(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = check_index(g, f, s)


def lower_global_load(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    r = f.tmp("g")
    ty = llvm_type(s.vtype)
    # (no alias scope on a plain load: with them LLVM stopped vectorising vortex_rings' advect loop, 4.9 -> 9.8
    # ms, and P2G ran 5% slower; the stores and plain updates keep theirs)
    f.emit(f"{r} = load {ty}, ptr {f.v(s.operands[0])}{group(f)}")
    f.names[s] = r


def group(f: FunctionText) -> str:
    """The access group of a field load or store in a parallel loop's task, if it has one."""
    return f", !llvm.access.group {f.access_group}" if f.access_group else ""


def lower_global_store(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    p, v = s.operands
    ty = llvm_type(v.type)
    f.emit(f"store {ty} {f.v(v)}, ptr {f.v(p)}{g.module.facts.access(p, ty)}{group(f)}")


def lower_atomic(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    if s.attrs["kind"] == "cas":  # (pointer, expected, new) -> the value found (passes/quant.py's loops)
        p, e, n = s.operands
        ty, res, r = llvm_type(s.vtype), f.tmp("cx"), f.tmp("old")
        f.emit(f"{res} = cmpxchg ptr {f.v(p)}, {ty} {f.v(e)}, {ty} {f.v(n)} monotonic monotonic")
        f.emit(f"{r} = extractvalue {{ {ty}, i1 }} {res}, 0")
        f.names[s] = r
        return
    p, v = s.operands
    t = s.vtype
    ty = llvm_type(t)
    kind = s.attrs["kind"]
    if t.is_float:
        op = {"add": "fadd", "mul": "fmul", "min": "fmin", "max": "fmax", "xchg": "xchg"}[kind]
    else:
        op = {"add": "add", "mul": "mul", "and": "and", "or": "or", "xor": "xor", "xchg": "xchg",
              "min": "min" if t.is_signed else "umin", "max": "max" if t.is_signed else "umax"}[kind]
    if t is dt.u1:  # one bit wraps: + is xor, * and min are and, max is or
        op = {"add": "xor", "mul": "and", "umin": "and", "umax": "or"}.get(op, op)
    r = f.tmp("old")
    form = atomic_form(f, s)
    if form == REDUCE:  # this thread's own partial sum
        acc = f.reduction_of[id(s)]
        f.emit(f"{r} = load {ty}, ptr {acc}")
        n = f.tmp("new")
        f.emit(_combine_text(n, op, ty, r, f.v(v), g.fm))
        f.emit(f"store {ty} {n}, ptr {acc}")
    elif form == PLAIN:  # serial code, a local of the iteration, an owned element or a private copy
        md = g.module.facts.access(p, ty)
        # an f16 min/max kept in memory (volatile): LLVM 22's loop vectoriser aborts on a half minnum/maxnum
        # reduction ("VPlan cost model and legacy cost model disagreed"; taichi's test_atomic_max_f16)
        vol = "volatile " if ty == "half" and op in ("fmin", "fmax") else ""
        # in a parallel lane loop (passes/fission.py) an update of the iteration's own element is in its group
        md += group(f) if f.lane_group and s.attrs.get("strategy") == PLAIN and p.op is Op.GLOBAL_PTR else ""
        f.emit(f"{r} = load {vol}{ty}, ptr {f.v(p)}{md}")
        n = f.tmp("new")
        f.emit(_combine_text(n, op, ty, r, f.v(v), g.float_flags(s)))
        f.emit(f"store {vol}{ty} {n}, ptr {f.v(p)}{md}")
    elif op in ("fmul", "mul"):  # no atomicrmw multiplies: a compare-exchange loop
        r = _cas_update(f, f.v(p), ty, t.bits, lambda old, new: _combine_text(new, op, ty, old, f.v(v), g.fm))
    elif t is dt.u1:  # LLVM has no atomics on i1: update the byte that holds it (0 or 1 stays 0 or 1)
        wide, old = f.tmp("wv"), f.tmp("wold")
        f.emit(f"{wide} = zext i1 {f.v(v)} to i8")
        f.emit(f"{old} = atomicrmw {op} ptr {f.v(p)}, i8 {wide} monotonic")
        f.emit(f"{r} = trunc i8 {old} to i1")
    else:
        f.emit(f"{r} = atomicrmw {op} ptr {f.v(p)}, {ty} {f.v(v)} monotonic")
    f.names[s] = r


def _cas_update(f: FunctionText, ptr: str, ty: str, bits: int, combine) -> str:
    """Atomically replace *ptr by combine(old): retry a compare-exchange of the integer bits until no
    other thread wrote in between. Returns the old value."""
    ity = f"i{bits}"
    pre, loop, done = f.label("cas"), f.label("casloop"), f.label("casdone")
    first = f.tmp("cur")
    f.emit(f"{first} = load atomic {ity}, ptr {ptr} monotonic, align {bits // 8}")
    f.emit(f"br label %{pre}")
    f.start_block(pre)
    f.emit(f"br label %{loop}")
    f.start_block(loop)
    cur, old, new, newi, res, got, ok = (f.tmp("c") for _ in range(7))
    f.emit(f"{cur} = phi {ity} [{first}, %{pre}], [{got}, %{loop}]")
    f.emit(f"{old} = bitcast {ity} {cur} to {ty}" if ty != ity else f"{old} = add {ity} {cur}, 0")
    f.emit(combine(old, new))
    f.emit(f"{newi} = bitcast {ty} {new} to {ity}" if ty != ity else f"{newi} = add {ity} {new}, 0")
    f.emit(f"{res} = cmpxchg ptr {ptr}, {ity} {cur}, {ity} {newi} monotonic monotonic")
    f.emit(f"{got} = extractvalue {{ {ity}, i1 }} {res}, 0")
    f.emit(f"{ok} = extractvalue {{ {ity}, i1 }} {res}, 1")
    f.emit(f"br i1 {ok}, label %{done}, label %{loop}")
    f.start_block(done)
    return old


def lower_pair(g: KernelCodegen, f: FunctionText, a: Stmt, p2: Stmt, b: Stmt) -> None:
    """`v[I] += w` on an f32 2-vector: one 64-bit compare-and-swap instead of two atomic adds, which
    halves the lock-prefixed instructions of a particle-to-grid scatter."""
    p1 = a.operands[0]
    lower_global_ptr(g, f, p1)
    f.names[p2] = f.names[p1]
    lo, hi = f.v(a.operands[1]), f.v(b.operands[1])
    v0, v1, inc = f.tmp("pv"), f.tmp("pv"), f.tmp("pinc")
    f.emit(f"{v0} = insertelement <2 x float> poison, float {lo}, i32 0")
    f.emit(f"{v1} = insertelement <2 x float> {v0}, float {hi}, i32 1")
    f.emit(f"{inc} = bitcast <2 x float> {v1} to i64")
    pre, loop, done = f.label("cas"), f.label("casloop"), f.label("casdone")
    first = f.tmp("cur")
    f.emit(f"{first} = load atomic i64, ptr {f.v(p1)} monotonic, align 8")
    f.emit(f"br label %{pre}")
    f.start_block(pre)
    f.emit(f"br label %{loop}")
    f.start_block(loop)
    cur, old, new, sum_, res, got, ok = (f.tmp("c") for _ in range(7))
    f.emit(f"{cur} = phi i64 [{first}, %{pre}], [{got}, %{loop}]")
    f.emit(f"{old} = bitcast i64 {cur} to <2 x float>")
    f.emit(f"{sum_} = fadd <2 x float> {old}, {v1}")
    f.emit(f"{new} = bitcast <2 x float> {sum_} to i64")
    f.emit(f"{res} = cmpxchg ptr {f.v(p1)}, i64 {cur}, i64 {new} monotonic monotonic, align 8")
    f.emit(f"{got} = extractvalue {{ i64, i1 }} {res}, 0")
    f.emit(f"{ok} = extractvalue {{ i64, i1 }} {res}, 1")
    f.emit(f"br i1 {ok}, label %{done}, label %{loop}")
    f.start_block(done)


def lower_ret_store(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    (v,) = s.operands
    slot = abi.CTX_ARGS + g.kernel.ret_slot + s.attrs["slot"]
    p = f.tmp("rp")
    f.emit(f"{p} = getelementptr i64, ptr %ctx, i64 {slot}")
    f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {p}")


# -- arithmetic --------------------------------------------------------------------------------------
def lower_elementwise(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = arith.lower_elementwise(f, s)


def lower_cast(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = arith.lower_cast(f, s.operands[0], s.vtype)


def lower_bitcast(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    r = f.tmp("bc")
    (a,) = s.operands
    if a.op is Op.GLOBAL_PTR:  # ti.get_addr: the element's address as an integer
        f.emit(f"{r} = ptrtoint ptr {f.v(a)} to {llvm_type(s.vtype)}")
    else:
        f.emit(f"{r} = bitcast {llvm_type(a.type)} {f.v(a)} to {llvm_type(s.vtype)}")
    f.names[s] = r


def lower_select(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    c, a, b = s.operands
    ci, r = f.tmp("c"), f.tmp("sel")
    f.emit(f"{ci} = icmp ne {llvm_type(c.type)} {f.v(c)}, 0")
    f.emit(f"{r} = select i1 {ci}, {llvm_type(a.type)} {f.v(a)}, {llvm_type(b.type)} {f.v(b)}")
    f.names[s] = r


# -- runtime services --------------------------------------------------------------------------------
def lower_print(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    """printf's promotions (floats as double, small integers as i32); the target's emit_print makes the call."""
    fmt = g.module.string(s.attrs["format"])
    args = []
    for v in s.operands:
        t = v.type
        if t.is_float:
            args.append(f"double {arith.lower_cast(f, v, dt.f64)}")
        elif t.bits < 32:
            args.append(f"i32 {arith.lower_cast(f, v, dt.i32 if t.is_signed else dt.u32)}")
        else:
            args.append(f"{llvm_type(t)} {f.v(v)}")
    g.emit_print(f, fmt, args)


def lower_assert(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    """A failed assert reports its code; the values of a formatted message (operands after the condition)
    go to the error buffer's argument words, written only by the report that won (the launcher formats)."""
    code = g.error_code("assert", s.loc, s.attrs["message"])
    cond, *values = s.operands
    if not values:
        g._check(f, f.v(cond), code, "0")
        return
    c = f.tmp("ok")
    f.emit(f"{c} = icmp ne i32 {f.v(cond)}, 0")
    good, bad, store = f.label("ok"), f.label("fail"), f.label("fail_args")
    f.emit(f"br i1 {c}, label %{good}, label %{bad}, !prof !1")
    f.start_block(bad)
    ep, err, r, won = (f.tmp("ae") for _ in range(4))
    f.emit(f"{ep} = getelementptr i64, ptr %ctx, i64 {abi.CTX_ERR}")
    f.emit(f"{err} = load ptr, ptr {ep}")
    f.emit(f"{r} = cmpxchg ptr {err}, i64 0, i64 {code} monotonic monotonic")
    f.emit(f"{won} = extractvalue {{ i64, i1 }} {r}, 1")
    f.emit(f"br i1 {won}, label %{store}, label %{good}")
    f.start_block(store)
    for k, v in enumerate(values):
        if v.type.is_float:
            word = f.tmp("aw")
            f.emit(f"{word} = bitcast double {arith.lower_cast(f, v, dt.f64)} to i64")
        else:
            word = arith.lower_cast(f, v, dt.i64 if v.type.is_signed else dt.u64)
        p = f.tmp("ap")
        f.emit(f"{p} = getelementptr i64, ptr {err}, i64 {abi.ERR_ARGS + k}")
        f.emit(f"store i64 {word}, ptr {p}")
    f.emit(f"br label %{good}")
    f.start_block(good)
    g.need_branch_weights()


def lower_tape_reset(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    _, top, _ = f.tape()
    f.emit(f"store i64 0, ptr {top}")


def lower_tape_push(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    base, top, cap = f.tape()
    (v,) = s.operands
    t, ok, okz, last, idx, p, n = (f.tmp("tp") for _ in range(7))
    f.emit(f"{t} = load i64, ptr {top}")
    f.emit(f"{ok} = icmp ult i64 {t}, {cap}")
    f.emit(f"{okz} = zext i1 {ok} to i32")
    code = g.error_code("adstack", s.loc, s.attrs.get("message", "adstack overflow"))
    g._check(f, okz, code, t)
    f.emit(f"{last} = sub i64 {cap}, 1")
    f.emit(f"{idx} = select i1 {ok}, i64 {t}, i64 {last}")
    f.emit(f"{p} = getelementptr i64, ptr {base}, i64 {idx}")
    f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {p}")
    f.emit(f"{n} = add i64 {t}, 1")
    f.emit(f"store i64 {n}, ptr {top}")


def lower_tape_pop(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    base, top, cap = f.tape()
    t, n, last, idx, p, r = (f.tmp("tq") for _ in range(6))
    f.emit(f"{t} = load i64, ptr {top}")
    f.emit(f"{n} = sub i64 {t}, 1")
    f.emit(f"store i64 {n}, ptr {top}")
    f.emit(f"{last} = sub i64 {cap}, 1")
    g.module.declare("declare i64 @llvm.umin.i64(i64, i64)")
    f.emit(f"{idx} = call i64 @llvm.umin.i64(i64 {n}, i64 {last})")
    f.emit(f"{p} = getelementptr i64, ptr {base}, i64 {idx}")
    f.emit(f"{r} = load {llvm_type(s.vtype)}, ptr {p}")
    f.names[s] = r


def lower_random(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = arith.random_value(f, s.vtype)


# -- real functions ----------------------------------------------------------------------------------
def lower_param(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    f.names[s] = f"%p{s.attrs['index']}"


def lower_call(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    """`call @sym_fnK(ctx, tid, depth + 1, args...)`; inside a real function, a call deeper than max_call_depth
    reports the located error and gives zeros instead (its callers unwind, the launcher raises)."""
    func = s.attrs["func"]
    rt = g.result_type(func)
    args = "".join(f", {llvm_type(o.vtype)} {f.v(o)}" for o in s.operands)
    sym = g.function_symbol(func)
    if not f.is_function:
        r = f.tmp("call")
        f.emit(f"{r} = call {rt} @{sym}(ptr %ctx, i32 {f.tid}, i32 1{args})" if func.returns else
               f"call void @{sym}(ptr %ctx, i32 {f.tid}, i32 1{args})")
        f.names[s] = r
        return
    depth, ok, r = f.tmp("depth"), f.tmp("shallow"), f.tmp("call")
    f.emit(f"{depth} = add i32 {f.depth}, 1")
    f.emit(f"{ok} = icmp ule i32 {depth}, {g.max_call_depth}")
    go, deep, join = f.label("call"), f.label("deep"), f.label("called")
    f.emit(f"br i1 {ok}, label %{go}, label %{deep}, !prof !2")
    f.start_block(deep)
    code = g.error_code("recursion", s.loc, f"real function {func.name.rsplit('_', 1)[0]} recursed deeper than "
                                            f"{g.max_call_depth} calls (simgrad's limit on this target, which keeps "
                                            "the thread's stack from overflowing)")
    f.emit(f"call void @sg_report(ptr %ctx, i64 {code}, i64 0)")
    f.emit(f"br label %{join}")
    f.start_block(go)
    if func.returns:
        f.emit(f"{r}.c = call {rt} @{sym}(ptr %ctx, i32 {f.tid}, i32 {depth}{args})")
    else:
        f.emit(f"call void @{sym}(ptr %ctx, i32 {f.tid}, i32 {depth}{args})")
    f.emit(f"br label %{join}")
    f.start_block(join)
    if func.returns:
        f.emit(f"{r} = phi {rt} [zeroinitializer, %{deep}], [{r}.c, %{go}]")
    f.names[s] = r
    if "!2 = " not in "".join(g.module.globals):
        g.module.globals.append('!2 = !{!"branch_weights", i32 1000000, i32 1}')


def lower_call_result(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    (call,) = s.operands
    r = f.tmp("res")
    f.emit(f"{r} = extractvalue {g.result_type(call.attrs['func'])} {f.v(call)}, {s.attrs['index']}")
    f.names[s] = r


def lower_func_return(g: KernelCodegen, f: FunctionText, s: Stmt) -> None:
    if not s.operands:
        f.emit("ret void")
        return
    rt = "{ " + ", ".join(llvm_type(o.vtype) for o in s.operands) + " }"  # the function's result_type
    acc = "undef"
    for k, o in enumerate(s.operands):
        nxt = f.tmp("rv")
        f.emit(f"{nxt} = insertvalue {rt} {acc}, {llvm_type(o.vtype)} {f.v(o)}, {k}")
        acc = nxt
    f.emit(f"ret {rt} {acc}")


def _not_lowered(s: Stmt) -> None:
    raise AssertionError(f"internal: {s!r} reached codegen without passes/lower_access.py")


def _combine_text(dst, op, ty, a, b, fm: str) -> str:
    if op == "xchg":
        return f"{dst} = select i1 true, {ty} {b}, {ty} {b}"
    if op in ("fadd", "add", "fmul", "mul", "and", "or", "xor"):
        return f"{dst} = {op} {fm if op in ('fadd', 'fmul') else ''}{ty} {a}, {b}"
    intr = {"fmin": "minnum", "fmax": "maxnum", "min": "smin", "max": "smax", "umin": "umin", "umax": "umax"}[op]
    suffix = {"float": "f32", "double": "f64", "half": "f16"}.get(ty, ty)
    return f"{dst} = call {ty} @llvm.{intr}.{suffix}({ty} {a}, {ty} {b})"


# Every Op and the function that emits it. A target reuses this table; only parallel loops are its own.
LOWERING: dict[Op, Lowering] = {
    Op.CONST: lower_const, Op.ARG: lower_arg, Op.ALLOCA: lower_alloca, Op.LOCAL_LOAD: lower_local_load,
    Op.LOCAL_STORE: lower_local_store, Op.GLOBAL_PTR: lower_global_ptr, Op.CHECK_INDEX: lower_check_index,
    Op.THREAD_INDEX: lower_thread_index,
    Op.GLOBAL_LOAD: lower_global_load,
    Op.GLOBAL_STORE: lower_global_store, Op.ATOMIC: lower_atomic, Op.ARRAY_SHAPE: lower_array_shape,
    Op.RET_STORE: lower_ret_store,
    **{op: lower_elementwise for op in OPS},  # every registry op (ir/opdefs.py), as its entry says
    Op.CAST: lower_cast, Op.BITCAST: lower_bitcast, Op.SELECT: lower_select,
    Op.IF: lower_if, Op.RANGE_FOR: lower_range_for, Op.WHILE: lower_while, Op.BREAK: lower_break,
    Op.CONTINUE: lower_continue,
    Op.PRINT: lower_print, Op.ASSERT: lower_assert, Op.RANDOM: lower_random, Op.TAPE_RESET: lower_tape_reset,
    Op.TAPE_PUSH: lower_tape_push, Op.TAPE_POP: lower_tape_pop,
    Op.SNODE_OP: lambda g, f, s: _not_lowered(s), Op.TREE_ROOT: lower_tree_root,
    Op.SPARSE_CELL: lower_sparse_cell, Op.SPARSE_ACTION: lower_sparse_action,
    Op.PARAM: lower_param, Op.CALL: lower_call, Op.CALL_RESULT: lower_call_result, Op.FUNC_RETURN: lower_func_return,
}
