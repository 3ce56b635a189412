"""IR -> LLVM IR text. One `lower_<op>` per Op; structured control flow maps to basic blocks.

A kernel becomes one entry function `void entry(ptr ctx)`. Each top-level parallel loop is outlined
into a task function `void task(ptr closure, i64 lo, i64 hi, i32 tid)` that the runtime's
parallel_for splits across threads; the closure carries every value the loop body uses from outside.

The context's slots (roots table, error buffer, RNG states, ...) are defined in runtime/abi.py.
"""

from __future__ import annotations

import struct

import numpy as np

from simgrad import dtypes as dt
from simgrad.codegen.privatize import access_key, emit_private_launch, private_regions, slice_shift
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import Op
from simgrad.lang.field import ScalarField
from simgrad.runtime import abi


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

    def declare(self, text: str) -> None:
        self.decls.add(text)

    def string(self, s: str) -> str:
        data = s.encode() + b"\0"
        name = f"@.str{len(self.globals)}"
        esc = "".join(chr(b) if 32 <= b < 127 and b not in (34, 92) else f"\\{b:02X}" for b in data)
        self.globals.append(f'{name} = private unnamed_addr constant [{len(data)} x i8] c"{esc}"')
        return name

    def text(self) -> str:
        return "\n".join(sorted(self.decls) + self.globals + self.functions + [_RUNTIME_HELPERS]) + "\n"


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

    def __init__(self, gen: KernelCodegen, name: str, params: str, in_task: bool):
        self.gen = gen
        self.name = name
        self.params = params
        self.in_task = in_task
        self.prologue: list[str] = []
        self.body: list[str] = []
        self.names: dict[Stmt, str] = {}
        self.counter = 0
        self.loops: list[tuple[str, str]] = []  # (break label, continue label)
        self.roots: dict[int, str] = {}
        self.array_bases: dict[int, str] = {}
        self.array_shapes: dict[tuple[int, int], str] = {}
        self.tid = "%tid" if in_task else "0"
        self.shared: set = set()  # locals of the caller that a task writes through a pointer
        self.reduction_of: dict[int, str] = {}  # ATOMIC statement -> this thread's partial-sum variable
        self.private_roots: dict[tuple, str] = {}  # (id(field), slice key) -> root of this thread's copy
        self.private_prefix: dict[int, int] = {}  # id(field) -> leading axes that pick the slice

    def private_root(self, region, slot: int) -> None:
        """Point the region's updates at this thread's zeroed copy (closure slot `slot`), shifted so that
        the fields' usual byte offsets land inside it."""
        q, buf, t64, off, base, root = (self.tmp("pr") for _ in range(6))
        lines = [f"{q} = getelementptr i64, ptr %clo, i64 {slot}", f"{buf} = load ptr, ptr {q}",
                 f"{t64} = zext i32 %tid to i64", f"{off} = mul i64 {t64}, {region.hi - region.lo}",
                 f"{base} = getelementptr inbounds i8, ptr {buf}, i64 {off}"]
        shift = slice_shift(lines, lambda: self.tmp("sh"), self.v, region)
        neg = self.tmp("pr")
        lines += [f"{neg} = sub i64 {-region.lo}, {shift}", f"{root} = getelementptr i8, ptr {base}, i64 {neg}"]
        self.prologue += ["  " + line for line in lines]
        for tid, key in region.keys:
            self.private_roots[(tid, key)] = root
            self.private_prefix[tid] = len(key)  # every update of a field uses the same number of prefix axes

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
        return self.roots[tree_id]

    def array_base(self, arg) -> str:
        if arg.slot not in self.array_bases:
            self.array_bases[arg.slot] = self.ctx_slot(abi.CTX_ARGS + arg.slot, "ptr")
        return self.array_bases[arg.slot]

    def array_shape(self, arg, dim: int) -> str:
        key = (arg.slot, dim)
        if key not in self.array_shapes:
            self.array_shapes[key] = self.ctx_slot(abi.CTX_ARGS + arg.slot + 1 + dim, "i64")
        return self.array_shapes[key]

    def tape(self) -> tuple[str, str, str]:
        """(base, top variable, capacity) of this function's tape, set up in the prologue on first use."""
        if not hasattr(self, "_tape"):
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
            return const_text(s.attrs["value"], s.type)
        return self.names[s]

    def text(self) -> str:
        return "\n".join([f"define {self.params} {{", "entry:", *self.prologue, *self.body, "}"])


# ti.init(fast_math=True), the default as in Taichi, lets LLVM ignore the sign of zero, which is what
# turns an adjoint's `0.0 + g` into `g` (about 1.5x on MPM adjoints). The other fast-math flags are
# left out on purpose: reassoc and arcp break the guarded formulas of the decompositions (small
# denominators), nnan/ninf would break inf sentinels and isnan, and contract made LLVM 22 abort while
# emitting a f64 matrix-inverse adjoint on this CPU.
FAST_MATH_FLAGS = "nsz "


class KernelCodegen:
    def __init__(self, kernel: Kernel, symbol: str, debug: bool = False, fast_math: bool = True):
        self.kernel = kernel
        self.symbol = symbol
        self.debug = debug
        self.fm = FAST_MATH_FLAGS if fast_math else ""
        self.module = ModuleText()
        self.error_table: list[tuple] = []  # (kind, loc, detail) per error code - 1
        self.ntasks = 0

    def generate(self) -> str:
        self.uses: dict[int, int] = {}
        for x in walk(self.kernel.body):
            for o in x.operands:
                self.uses[id(o)] = self.uses.get(id(o), 0) + 1
        f = FunctionText(self, self.symbol, f"void @{self.symbol}(ptr %ctx)", in_task=False)
        self.lower_block(f, self.kernel.body)
        f.emit("ret void")
        self.module.functions.append(f.text())
        self.module.globals.append("!0 = !{}")
        return self.module.text()

    def error_code(self, kind: str, loc, detail) -> int:
        self.error_table.append((kind, loc, detail))
        return len(self.error_table)

    # -- blocks and control flow -------------------------------------------------------------------
    def lower_block(self, f: FunctionText, block: Block) -> None:
        stmts = block.stmts
        k = 0
        while k < len(stmts):
            s = stmts[k]
            if s.op is Op.ATOMIC and f.in_task and k + 2 < len(stmts) and self._pair_atomic(f, s, *stmts[k + 1:k + 3]):
                k += 3
                continue
            getattr(self, "lower_" + s.op.name.lower())(f, s)
            k += 1

    def _pair_atomic(self, f, a: Stmt, p2: Stmt, b: Stmt) -> bool:
        """`v[I] += w` on an f32 2-vector (or two neighbouring components): one 64-bit compare-and-swap
        instead of two, which halves the lock-prefixed instructions of a particle-to-grid scatter."""
        if b.op is not Op.ATOMIC or b.operands[0] is not p2 or a.type is not dt.f32 or b.type is not dt.f32:
            return False
        if a.attrs["kind"] != "add" or b.attrs["kind"] != "add" or self.uses.get(id(a)) or self.uses.get(id(b)):
            return False
        p1 = a.operands[0]
        if p1.op is not Op.GLOBAL_PTR or p2.op is not Op.GLOBAL_PTR or p1.operands != p2.operands:
            return False
        t1, t2 = p1.attrs["target"], p2.attrs["target"]
        if not isinstance(t1, ScalarField) or not isinstance(t2, ScalarField) or self.debug:
            return False
        (tree1, c1, terms1, _), (tree2, c2, terms2, _) = t1.layout, t2.layout
        if tree1 != tree2 or terms1 != terms2 or c2 != c1 + 4 or c1 % 8 or any(t.stride % 8 for t in terms1):
            return False
        if _owned_by_iteration(f, p1) or _owned_by_iteration(f, p2) or id(a) in f.reduction_of \
                or id(b) in f.reduction_of or f.private_root_of(p1) or f.private_root_of(p2):
            return False
        self.lower_global_ptr(f, p1)
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
        return True

    def lower_if(self, f, s):
        c = f.tmp("c")
        f.emit(f"{c} = icmp ne i32 {f.v(s.operands[0])}, 0")
        then_l, else_l, end_l = f.label("then"), f.label("else"), f.label("endif")
        f.emit(f"br i1 {c}, label %{then_l}, label %{else_l}")
        f.start_block(then_l)
        self.lower_block(f, s.blocks[0])
        f.emit(f"br label %{end_l}")
        f.start_block(else_l)
        self.lower_block(f, s.blocks[1])
        f.emit(f"br label %{end_l}")
        f.start_block(end_l)

    def lower_while(self, f, s):
        head, end = f.label("while"), f.label("endwhile")
        f.emit(f"br label %{head}")
        f.start_block(head)
        f.loops.append((end, head))
        self.lower_block(f, s.blocks[0])
        f.loops.pop()
        f.emit(f"br label %{head}")
        f.start_block(end)

    def lower_break(self, f, s):
        f.emit(f"br label %{f.loops[-1][0]}")
        f.start_block(f.label("dead"))

    def lower_continue(self, f, s):
        f.emit(f"br label %{f.loops[-1][1]}")
        f.start_block(f.label("dead"))

    def lower_range_for(self, f, s):
        if s.attrs.get("parallel") and not f.in_task:
            self._parallel_for(f, s)
        else:
            self._serial_loop(f, s, f.v(s.operands[0]), f.v(s.operands[1]))

    def _serial_loop(self, f, s, begin: str, end: str):
        ty = llvm_type(s.type)
        pre = f.label("pre")
        f.emit(f"br label %{pre}")
        f.start_block(pre)
        head, body, latch, done = f.label("head"), f.label("body"), f.label("latch"), f.label("done")
        f.emit(f"br label %{head}")
        f.start_block(head)
        i, nxt = f.tmp("i"), f.tmp("inext")
        f.emit(f"{i} = phi {ty} [{begin}, %{pre}], [{nxt}, %{latch}]")
        c = f.tmp("c")
        f.emit(f"{c} = icmp slt {ty} {i}, {end}")
        f.emit(f"br i1 {c}, label %{body}, label %{done}")
        f.start_block(body)
        f.names[s] = i
        f.loops.append((done, latch))
        self.lower_block(f, s.blocks[0])
        f.loops.pop()
        f.emit(f"br label %{latch}")
        f.start_block(latch)
        f.emit(f"{nxt} = add {ty} {i}, 1")
        f.emit(f"br label %{head}")
        f.start_block(done)

    def _parallel_for(self, f, s):
        captured = _free_values(s)
        inside = {id(x) for x in walk(s.blocks[0])}
        # fields some iteration writes at an element it does not own keep every update atomic
        shared_targets = {id(x.operands[0].attrs["target"]) for x in walk(s.blocks[0])
                          if x.op in (Op.ATOMIC, Op.GLOBAL_STORE) and x.operands[0].op is Op.GLOBAL_PTR
                          and not _injective_in(s, x.operands[0], inside)}
        reductions = _reductions(s, inside, self.uses)
        reduced = {key[0] for key in reductions}
        regions, weight = private_regions(s, inside, self.uses, shared_targets, reduced, self.debug)
        clo = f.tmp("clo")
        f.prologue.append(f"  {clo} = alloca [{len(captured) + len(regions) + 1} x i64], align 8")
        f.emit(f"store ptr %ctx, ptr {clo}")
        stored = {id(x.operands[0]) for x in walk(s.blocks[0]) if x.op in (Op.LOCAL_STORE, Op.ATOMIC)}
        slots = []  # (k, llvm type, by value) per captured value
        for k, v in enumerate(captured, start=1):
            by_value = v.op is Op.ALLOCA and id(v) not in stored  # read-only local: a private copy
            is_ptr = v.op is Op.GLOBAL_PTR or (v.op is Op.ALLOCA and not by_value)
            ty = "ptr" if is_ptr else llvm_type(v.type)
            src = f.v(v)
            if by_value:
                src = f.tmp("ld")
                f.emit(f"{src} = load {ty}, ptr {f.v(v)}")
            p = f.tmp("cap")
            f.emit(f"{p} = getelementptr i64, ptr {clo}, i64 {k}")
            f.emit(f"store {ty} {src}, ptr {p}")
            slots.append((k, ty, by_value))
        self.ntasks += 1
        tname = f"{self.symbol}_task{self.ntasks}"
        self._emit_task(s, tname, captured, slots, inside, shared_targets, reductions, [])
        ty = llvm_type(s.type)
        b64, e64 = f.tmp("b"), f.tmp("e")
        ext = "sext" if ty != "i64" else None
        for dst, src in ((b64, s.operands[0]), (e64, s.operands[1])):
            f.emit(f"{dst} = {ext} {ty} {f.v(src)} to i64" if ext else f"{dst} = add i64 {f.v(src)}, 0")
        pfor = f.ctx_slot(abi.CTX_PFOR, "ptr")
        grain = s.attrs.get("block_dim") or max(1, 4096 // max(1, _cost(s.blocks[0])))
        if not regions:
            f.emit(f"call void {pfor}(ptr @{tname}, ptr {clo}, i64 {b64}, i64 {e64}, i64 {grain})")
            return
        pname = f"{tname}_private"
        self._emit_task(s, pname, captured, slots, inside, shared_targets, reductions, regions,
                        first_slot=len(captured) + 1)
        nthreads = f.ctx_slot(abi.CTX_NTHREADS, "i64")
        emit_private_launch(f, regions, weight, clo, len(captured) + 1, tname, pname, pfor, nthreads, b64, e64,
                            grain)

    def _emit_task(self, s, tname, captured, slots, inside, shared_targets, reductions, regions, first_slot=0):
        """The outlined loop: `task(closure, lo, hi, tid)`; with `regions`, the variant that adds into this
        thread's private copies of those regions (closure slots from `first_slot` hold the copies)."""
        t = FunctionText(self, tname, f"internal void @{tname}(ptr %clo, i64 %lo, i64 %hi, i32 %tid)", True)
        t.loop = s
        t.inside = inside
        t.shared_targets = shared_targets
        t.prologue.append("  %ctx = load ptr, ptr %clo")
        for v, (k, ty, by_value) in zip(captured, slots):
            q, val = t.tmp("cap"), t.tmp("capv")
            t.prologue.append(f"  {q} = getelementptr i64, ptr %clo, i64 {k}")
            t.prologue.append(f"  {val} = load {ty}, ptr {q}")
            if by_value:
                copy = t.tmp("var")
                t.prologue.append(f"  {copy} = alloca {ty}")
                t.prologue.append(f"  store {ty} {val}, ptr {copy}")
                val = copy
            t.names[v] = val
            if v.op is Op.ALLOCA and not by_value:
                t.shared.add(v)
        for k, r in enumerate(regions):
            t.private_root(r, first_slot + k)
        ty = llvm_type(s.type)
        lo, hi = t.tmp("lo"), t.tmp("hi")
        t.prologue.append(f"  {lo} = trunc i64 %lo to {ty}" if ty != "i64" else f"  {lo} = add i64 %lo, 0")
        t.prologue.append(f"  {hi} = trunc i64 %hi to {ty}" if ty != "i64" else f"  {hi} = add i64 %hi, 0")
        for _place, adds in reductions.values():  # each thread sums into its own variable first
            acc = t.tmp("red")
            rty = llvm_type(adds[0].type)
            t.prologue += [f"  {acc} = alloca {rty}", f"  store {rty} {const_text(0, adds[0].type)}, ptr {acc}"]
            for a in adds:
                t.reduction_of[id(a)] = acc
        self._serial_loop(t, s, lo, hi)
        for _key, (place, adds) in reductions.items():  # ... and adds it to the shared place once per chunk
            rty = llvm_type(adds[0].type)
            total = t.tmp("sum")
            t.emit(f"{total} = load {rty}, ptr {t.reduction_of[id(adds[0])]}")
            if place.op is Op.GLOBAL_PTR:
                self.lower_global_ptr(t, place)
            op = "fadd" if adds[0].type.is_float else "add"
            t.emit(f"{t.tmp('old')} = atomicrmw {op} ptr {t.v(place)}, {rty} {total} monotonic")
        t.emit("ret void")
        self.module.functions.append(t.text())

    # -- memory ------------------------------------------------------------------------------------
    def lower_const(self, f, s):
        f.names[s] = const_text(s.attrs["value"], s.type)

    def lower_arg(self, f, s):
        f.names[s] = f.ctx_slot(abi.CTX_ARGS + s.attrs["slot"], llvm_type(s.type))

    def lower_array_shape(self, f, s):
        v = f.array_shape(s.attrs["arg"], s.attrs["dim"])
        r = f.tmp("sh")
        f.emit(f"{r} = trunc i64 {v} to i32" if s.type is dt.i32 else f"{r} = add i64 {v}, 0")
        f.names[s] = r

    def lower_alloca(self, f, s):
        a = f.tmp("var")
        f.prologue.append(f"  {a} = alloca {llvm_type(s.type)}")
        f.prologue.append(f"  store {llvm_type(s.type)} {const_text(0, s.type)}, ptr {a}")
        f.names[s] = a

    def lower_local_load(self, f, s):
        r = f.tmp("l")
        f.emit(f"{r} = load {llvm_type(s.type)}, ptr {f.v(s.operands[0])}")
        f.names[s] = r

    def lower_local_store(self, f, s):
        a, v = s.operands
        f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {f.v(a)}")

    def lower_global_ptr(self, f, s):
        from simgrad.codegen.access import lower_global_ptr

        f.names[s] = lower_global_ptr(self, f, s)

    def lower_global_load(self, f, s):
        r = f.tmp("g")
        f.emit(f"{r} = load {llvm_type(s.type)}, ptr {f.v(s.operands[0])}")
        f.names[s] = r

    def lower_global_store(self, f, s):
        p, v = s.operands
        f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {f.v(p)}")

    def lower_atomic(self, f, s):
        p, v = s.operands
        t = s.type
        ty = llvm_type(t)
        kind = s.attrs["kind"]
        if t.is_float:
            op = {"add": "fadd", "min": "fmin", "max": "fmax", "xchg": "xchg"}[kind]
        else:
            op = {"add": "add", "and": "and", "or": "or", "xor": "xor", "xchg": "xchg",
                  "min": "min" if t.is_signed else "umin", "max": "max" if t.is_signed else "umax"}[kind]
        r = f.tmp("old")
        acc = f.reduction_of.get(id(s))
        if acc is not None:  # a reduction: this thread's own partial sum
            f.emit(f"{r} = load {ty}, ptr {acc}")
            n = f.tmp("new")
            f.emit(_combine_text(n, op, ty, r, f.v(v), self.fm))
            f.emit(f"store {ty} {n}, ptr {acc}")
            f.names[s] = r
            return
        private = (p.op is Op.ALLOCA and p not in f.shared) or _owned_by_iteration(f, p) \
            or f.private_root_of(p) is not None
        if not f.in_task or private:  # serial code or a thread's own local: a plain read-modify-write
            f.emit(f"{r} = load {ty}, ptr {f.v(p)}")
            n = f.tmp("new")
            f.emit(_combine_text(n, op, ty, r, f.v(v), self.fm))
            f.emit(f"store {ty} {n}, ptr {f.v(p)}")
        else:
            f.emit(f"{r} = atomicrmw {op} ptr {f.v(p)}, {ty} {f.v(v)} monotonic")
        f.names[s] = r

    def lower_ret_store(self, f, s):
        (v,) = s.operands
        slot = abi.CTX_ARGS + self.kernel.ret_slot + s.attrs["slot"]
        p = f.tmp("rp")
        f.emit(f"{p} = getelementptr i64, ptr %ctx, i64 {slot}")
        f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {p}")

    # -- arithmetic ----------------------------------------------------------------------------------
    def _bin(self, f, s):
        from simgrad.codegen.arith import lower_binary

        f.names[s] = lower_binary(f, s)

    def _un(self, f, s):
        from simgrad.codegen.arith import lower_unary

        f.names[s] = lower_unary(f, s)

    def lower_cast(self, f, s):
        from simgrad.codegen.arith import lower_cast

        f.names[s] = lower_cast(f, s.operands[0], s.type)

    def lower_bitcast(self, f, s):
        r = f.tmp("bc")
        (a,) = s.operands
        f.emit(f"{r} = bitcast {llvm_type(a.type)} {f.v(a)} to {llvm_type(s.type)}")
        f.names[s] = r

    def lower_select(self, f, s):
        c, a, b = s.operands
        ci, r = f.tmp("c"), f.tmp("sel")
        f.emit(f"{ci} = icmp ne {llvm_type(c.type)} {f.v(c)}, 0")
        f.emit(f"{r} = select i1 {ci}, {llvm_type(a.type)} {f.v(a)}, {llvm_type(b.type)} {f.v(b)}")
        f.names[s] = r

    # -- runtime services ----------------------------------------------------------------------------
    def lower_print(self, f, s):
        from simgrad.codegen.arith import lower_cast

        self.module.declare("declare i32 @printf(ptr, ...)")
        self.module.declare("declare i32 @fflush(ptr)")
        fmt = self.module.string(s.attrs["format"])
        args = []
        for v in s.operands:
            t = v.type
            if t.is_float:
                args.append(f"double {lower_cast(f, v, dt.f64)}")
            elif t.bits < 32:
                args.append(f"i32 {lower_cast(f, v, dt.i32 if t.is_signed else dt.u32)}")
            else:
                args.append(f"{llvm_type(t)} {f.v(v)}")
        f.emit(f"call i32 (ptr, ...) @printf(ptr {fmt}{''.join(', ' + a for a in args)})")
        f.emit("call i32 @fflush(ptr null)")

    def lower_assert(self, f, s):
        code = self.error_code("assert", s.loc, s.attrs["message"])
        self._check(f, f.v(s.operands[0]), code, "0")

    def _check(self, f, ok_i32: str, code: int, value: str) -> None:
        c = f.tmp("ok")
        f.emit(f"{c} = icmp ne i32 {ok_i32}, 0")
        good, bad = f.label("ok"), f.label("fail")
        f.emit(f"br i1 {c}, label %{good}, label %{bad}, !prof !1")
        f.start_block(bad)
        f.emit(f"call void @sg_report(ptr %ctx, i64 {code}, i64 {value})")
        f.emit(f"br label %{good}")
        f.start_block(good)
        if "!1 = " not in "".join(self.module.globals):
            self.module.globals.append('!1 = !{!"branch_weights", i32 1000, i32 1}')

    def lower_tape_reset(self, f, s):
        _, top, _ = f.tape()
        f.emit(f"store i64 0, ptr {top}")

    def lower_tape_push(self, f, s):
        base, top, cap = f.tape()
        (v,) = s.operands
        t, ok, okz, last, idx, p, n = (f.tmp("tp") for _ in range(7))
        f.emit(f"{t} = load i64, ptr {top}")
        f.emit(f"{ok} = icmp ult i64 {t}, {cap}")
        f.emit(f"{okz} = zext i1 {ok} to i32")
        code = self.error_code("adstack", s.loc, s.attrs.get("message", "adstack overflow"))
        self._check(f, okz, code, t)
        f.emit(f"{last} = sub i64 {cap}, 1")
        f.emit(f"{idx} = select i1 {ok}, i64 {t}, i64 {last}")
        f.emit(f"{p} = getelementptr i64, ptr {base}, i64 {idx}")
        f.emit(f"store {llvm_type(v.type)} {f.v(v)}, ptr {p}")
        f.emit(f"{n} = add i64 {t}, 1")
        f.emit(f"store i64 {n}, ptr {top}")

    def lower_tape_pop(self, f, s):
        base, top, cap = f.tape()
        t, n, last, idx, p, r = (f.tmp("tq") for _ in range(6))
        f.emit(f"{t} = load i64, ptr {top}")
        f.emit(f"{n} = sub i64 {t}, 1")
        f.emit(f"store i64 {n}, ptr {top}")
        f.emit(f"{last} = sub i64 {cap}, 1")
        f.gen.module.declare("declare i64 @llvm.umin.i64(i64, i64)")
        f.emit(f"{idx} = call i64 @llvm.umin.i64(i64 {n}, i64 {last})")
        f.emit(f"{p} = getelementptr i64, ptr {base}, i64 {idx}")
        f.emit(f"{r} = load {llvm_type(s.type)}, ptr {p}")
        f.names[s] = r

    def lower_random(self, f, s):
        from simgrad.codegen.arith import random_value

        f.names[s] = random_value(f, s.type)


def _combine_text(dst, op, ty, a, b, fm: str) -> str:
    if op == "xchg":
        return f"{dst} = select i1 true, {ty} {b}, {ty} {b}"
    if op in ("fadd", "add", "and", "or", "xor"):
        return f"{dst} = {op} {fm if op == 'fadd' else ''}{ty} {a}, {b}"
    intr = {"fmin": "minnum", "fmax": "maxnum", "min": "smin", "max": "smax", "umin": "umin", "umax": "umax"}[op]
    suffix = {"float": "f32", "double": "f64", "half": "f16"}.get(ty, ty)
    return f"{dst} = call {ty} @llvm.{intr}.{suffix}({ty} {a}, {ty} {b})"


for _op in (Op.ADD, Op.SUB, Op.MUL, Op.DIV, Op.FLOORDIV, Op.MOD, Op.RAW_DIV, Op.RAW_MOD, Op.POW, Op.MIN,
            Op.MAX, Op.BIT_AND, Op.BIT_OR, Op.BIT_XOR, Op.SHL, Op.SHR, Op.ATAN2, Op.LT, Op.LE, Op.GT, Op.GE,
            Op.EQ, Op.NE):
    setattr(KernelCodegen, "lower_" + _op.name.lower(), KernelCodegen._bin)
for _op in (Op.NEG, Op.BIT_NOT, Op.LOGICAL_NOT, Op.SQRT, Op.RSQRT, Op.SIN, Op.COS, Op.TAN, Op.ASIN,
            Op.ACOS, Op.EXP, Op.LOG, Op.TANH, Op.FLOOR, Op.CEIL, Op.ROUND, Op.ABS):
    setattr(KernelCodegen, "lower_" + _op.name.lower(), KernelCodegen._un)


def _owned_by_iteration(f: FunctionText, ptr: Stmt) -> bool:
    """True when no other iteration of this task's parallel loop can touch the element `ptr` addresses:
    its indices are an injective function of the loop index (the index itself, or the div/mod pair of
    a flattened struct-for) plus loop-invariant values. Then an atomic update needs no atomic instruction."""
    loop = getattr(f, "loop", None)
    if loop is None or ptr.op is not Op.GLOBAL_PTR or id(ptr.attrs["target"]) in f.shared_targets:
        return False
    return _injective_in(loop, ptr, f.inside)


def _injective_in(loop: Stmt, ptr: Stmt, inside: set) -> bool:
    """True when the element's indices determine the loop index: apart from loop-invariant values they
    are digits `(index // d) % m` of it (raw division by constants, as flattened struct-for and ndrange
    loops produce) that chain from d = 1 up to a digit without modulus."""
    digits = {}
    for o in ptr.operands:
        d = _digit_of(o, loop)
        if d is not None:
            digits.setdefault(d[0], set()).add(d[1])
        elif o.op is not Op.CONST and id(o) in inside:
            return False
    place = 1
    while place in digits:
        mods = digits[place]
        if 0 in mods:
            return True
        step = max(mods)  # the widest digit at this place
        if step <= 1:
            return False
        place *= step
    return False


def _digit_of(o: Stmt, loop: Stmt):
    """(divisor, modulus or 0) when o is (loop // divisor) % modulus by raw division by constants."""
    mod = 0
    if o.op is Op.RAW_MOD and o.operands[1].op is Op.CONST:
        mod = o.operands[1].attrs["value"]
        o = o.operands[0]
    div = 1
    while o.op is Op.RAW_DIV and o.operands[1].op is Op.CONST and o.operands[1].attrs["value"] > 0:
        div *= o.operands[1].attrs["value"]
        o = o.operands[0]
    return (div, mod) if o is loop and mod >= 0 else None


def _reductions(loop: Stmt, inside: set, uses: dict) -> dict:
    """Places a parallel loop only accumulates into (`total[None] += v`, `s += v` on a kernel-scope
    local): every access is an atomic add whose old value is unused, at loop-invariant indices.
    Returns {key: (a pointer statement, [the ATOMIC statements])}; these sum per thread first."""
    groups: dict = {}
    spoiled: set = set()
    inside = inside | {id(loop)}  # the loop index varies too
    for x in walk(loop.blocks[0]):
        for k, o in enumerate(x.operands):
            is_place = (o.op is Op.ALLOCA and id(o) not in inside) or o.op is Op.GLOBAL_PTR
            if not is_place:
                continue
            if o.op is Op.GLOBAL_PTR:
                if any(i.op is not Op.CONST and id(i) in inside for i in o.operands):
                    spoiled.add(id(o.attrs["target"]))
                    continue
                key = (id(o.attrs["target"]), tuple(id(i) if i.op is not Op.CONST else ("c", i.attrs["value"])
                                                    for i in o.operands))
            else:
                key = (id(o),)
            reducing = x.op is Op.ATOMIC and k == 0 and x.attrs["kind"] == "add" and not uses.get(id(x))
            if not reducing:
                spoiled.add(key[0])
                continue
            place, adds = groups.setdefault(key, (o, []))
            adds.append(x)
    by_target: dict = {}
    for key in groups:
        by_target.setdefault(key[0], []).append(key)
    return {key: groups[key] for key in groups if key[0] not in spoiled and len(by_target[key[0]]) == 1}


def _free_values(loop: Stmt) -> list[Stmt]:
    """Values used inside `loop` but defined outside it (constants excepted), in first-use order."""
    inside = {id(s) for s in walk(loop.blocks[0])}
    inside.add(id(loop))
    seen: dict[int, Stmt] = {}
    for s in walk(loop.blocks[0]):
        for o in s.operands:
            if id(o) not in inside and o.op is not Op.CONST and id(o) not in seen:
                seen[id(o)] = o
    return list(seen.values())


def _cost(block: Block) -> int:
    return sum(1 for _ in walk(block))
