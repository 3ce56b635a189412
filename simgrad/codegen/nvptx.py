"""The GPU target (arch=cuda, issue 22): the same IR as the CPU, emitted as grid-stride kernels.

A kernel's top-level statements are cut into segments: each top-level parallel RANGE_FOR becomes a kernel
whose threads walk the flat index with a grid stride (`i = begin + ctaid * ntid + tid; i += ntid * nctaid`),
and each run of other top-level statements a one-thread kernel. Values that cross segments either travel in
scratch words of the context (spills: locals, loads, anything with an effect) or are recomputed by the
consumer (pure arithmetic, arguments, addresses): a serial run of pure statements launches nothing.

One switch, `sim`, picks how a thread learns where it is: on the GPU from `llvm.nvvm.read.ptx.sreg.*`, on the
simulated GPU (SIMGRAD_GPU_SIM=1) from a per-thread struct `{tid, ntid, ctaid, nctaid}` that the host device
(runtime/device.py HostDriver) fills while it runs blocks (on the thread pool) x threads (serially); everything
else is identical, and both are launched by runtime/gpu_launch.py through the same device interface.
The tape (adstack) is per-thread local memory (an alloca); math goes through libdevice (`__nv_*`) on the GPU.
Imports nothing from codegen/cpu.py.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass

from simgrad.codegen.llvm import LOWERING, FunctionText, KernelCodegen, const_text, llvm_type
from simgrad.ir.nodes import Kernel, Stmt, walk
from simgrad.ir.opdefs import OPS, Libm
from simgrad.ir.ops import Op
from simgrad.passes.parallel_strategy import LoopStrategy
from simgrad.runtime import abi, fpenv

TRIPLE = "nvptx64-nvidia-cuda"
DEFAULT_BLOCK = 128
LIBDEVICE_CANDIDATES = ("/usr/local/cuda/nvvm/libdevice/libdevice.10.bc",
                        "/usr/local/cuda-13.0/nvvm/libdevice/libdevice.10.bc")

# statements without effects or memory reads: a later segment recomputes them instead of spilling them
# (every elementwise op of the registry, ir/opdefs.py, is one)
PURE = {Op.ARG, Op.ARRAY_SHAPE, Op.GLOBAL_PTR, Op.CAST, Op.BITCAST, Op.SELECT, *OPS}

SREGS = ("tid.x", "ntid.x", "ctaid.x", "nctaid.x")

# Tape entries a thread keeps in local memory at most (8 KB; Taichi's CUDA adstack is small too). A deeper tape is
# a region per thread of a device buffer of GLOBAL_TAPE_BYTES at most: its loops launch only as many threads as
# the buffer has regions for (the grid-stride loop covers the rest).
GPU_TAPE_LIMIT = 1024
GLOBAL_TAPE_BYTES = 1 << 28


@dataclass(frozen=True)
class Launch:
    """One kernel of the launch sequence: its symbol, grid (None: as many blocks as fill the device) and
    block size. A serial segment is (1, 1)."""

    symbol: str
    grid: int | None
    block: int


class GpuFunction(FunctionText):
    """A segment's function: the tape in this thread's local memory, no Ctrl-C polling on the device."""

    def __init__(self, gen: GpuCodegen, name: str, params: str, in_task: bool, host_entry: bool = False):
        super().__init__(gen, name, params, in_task, host_entry)
        self.gpu = gen
        self._sregs: dict[str, str] = {}

    def sreg(self, name: str) -> str:
        """A special register (tid.x, ntid.x, ctaid.x, nctaid.x), read once in the prologue."""
        if name not in self._sregs:
            v = self.tmp("sr")
            if self.gpu.sim:
                p = self.tmp("srp")
                self.prologue += [f"  {p} = getelementptr i32, ptr %sreg, i32 {SREGS.index(name)}",
                                  f"  {v} = load i32, ptr {p}"]
            else:
                fn = f"@llvm.nvvm.read.ptx.sreg.{name}"
                self.gpu.module.declare(f"declare i32 {fn}()")
                self.prologue.append(f"  {v} = call i32 {fn}()")
            self._sregs[name] = v
        return self._sregs[name]

    def tape(self) -> tuple[str, str, str]:
        if self._tape is None and not self.in_task:
            # the serial code's one tape spans its kernels (pushed before a loop, popped after the next one):
            # the context's serial tape, its top in a scratch word that each launch starts at 0
            base, cap = self.ctx_slot(abi.CTX_TAPE_SERIAL, "ptr"), self.ctx_slot(abi.CTX_TAPE_CAP, "i64")
            top = self.tmp("ttop")
            self.prologue.append(f"  {top} = getelementptr i64, ptr %ctx, i64 {self.gpu.serial_tape_top()}")
            self._tape = (base, top, cap)
        if self._tape is None:
            n = self.gpu.tape_entries
            base, top = self.tmp("tbase"), self.tmp("ttop")
            if n <= GPU_TAPE_LIMIT:
                self.prologue.append(f"  {base} = alloca [{n} x i64], align 8")
            else:  # this thread's region of the launcher's buffer (its grid is capped to the regions there are)
                all_, t64, off = self.ctx_slot(abi.CTX_TAPE, "ptr"), self.tmp("tt"), self.tmp("toff")
                self.prologue += [f"  {t64} = zext i32 {self.tid} to i64", f"  {off} = mul i64 {t64}, {n}",
                                  f"  {base} = getelementptr i64, ptr {all_}, i64 {off}"]
            self.prologue += [f"  {top} = alloca i64", f"  store i64 0, ptr {top}"]
            self._tape = (base, top, str(n))
        return self._tape

    def cancel_point(self) -> None:
        """Ctrl-C cannot reach a running GPU kernel (nor, for the same structure, the simulated one)."""


class GpuCodegen(KernelCodegen):
    """LLVM IR of a kernel's segments for NVPTX (`sim=False`) or for the simulated GPU on the host (`sim=True`,
    with an entry `void symbol(ptr ctx)` that the CPU launcher calls unchanged)."""

    batched_alloc = False

    def __init__(self, kernel: Kernel, symbol: str, *, sim: bool, tape_entries: int = 256, debug: bool = False,
                 fast_math: bool = True, flush: bool = False):
        self.sim = sim
        if not sim:
            self.flush_attrs = fpenv.GPU_ATTRS  # f32 in .ftz forms; f64 has none
        super().__init__(kernel, symbol, debug=debug, fast_math=fast_math, flush=flush)
        self.switch_fp_mode = self.switch_fp_mode and sim  # the simulated GPU's segments are host entries
        self.tape_entries = max(int(tape_entries), 1)
        self.tape_threads = 0  # regions of the deep-tape buffer the launcher allocates (0: none)
        self.launches: list[Launch] = []
        self.spills: dict[int, int] = {}  # id(stmt) -> context slot of its scratch word
        self.scratch_slots = 0
        self.tape_top_slot: int | None = None  # 0 in the host context each launch copies to the device

    #: a GPU thread's stack is small: 1 KiB unless ti.init(cuda_stack_limit=...) says more (runtime/device.py)
    max_call_depth = 256

    def function_text(self, name: str, params: str) -> FunctionText:
        return GpuFunction(self, name, params, in_task=False)

    def emit_print(self, f: FunctionText, fmt: str, args: list[str]) -> None:
        """On the GPU: vprintf(fmt, buffer) with the promoted arguments in a struct, each at its natural
        alignment (the layout CUDA's device printf reads); the driver prints at the next synchronisation."""
        if self.sim:
            super().emit_print(f, fmt, args)
            return
        self.module.declare("declare i32 @vprintf(ptr, ptr)")
        buf = "null"
        if args:
            ty = "{ " + ", ".join(a.split(" ", 1)[0] for a in args) + " }"
            buf = f.tmp("pbuf")
            f.emit(f"{buf} = alloca {ty}, align 8")
            for k, a in enumerate(args):
                p = f.tmp("parg")
                f.emit(f"{p} = getelementptr {ty}, ptr {buf}, i32 0, i32 {k}")
                f.emit(f"store {a}, ptr {p}")
        f.emit(f"call i32 @vprintf(ptr {fmt}, ptr {buf})")

    def serial_tape_top(self) -> int:
        """The scratch word holding the serial tape's top (allocated on first use)."""
        if self.tape_top_slot is None:
            self.tape_top_slot = self.scratch_base() + self.scratch_slots
            self.scratch_slots += 1
        return self.tape_top_slot

    def scratch_base(self) -> int:
        return abi.CTX_ARGS + self.kernel.ret_slot + len(self.kernel.returns) + 1

    # -- segments ----------------------------------------------------------------------------------------
    def _segments(self) -> list[tuple[bool, list[Stmt]]]:
        """(is parallel loop, statements) in program order."""
        segs: list[tuple[bool, list[Stmt]]] = []
        for s in self.kernel.body.stmts:
            if s.op is Op.RANGE_FOR and s.attrs.get("parallel"):
                segs.append((True, [s]))
            elif segs and not segs[-1][0]:
                segs[-1][1].append(s)
            else:
                segs.append((False, [s]))
        return segs

    def _plan_spills(self, segs) -> None:
        """Give a scratch word to every non-pure value a later segment uses (through pure chains too)."""
        seg_of: dict[int, int] = {}
        for k, (_, stmts) in enumerate(segs):
            for s in stmts:
                seg_of[id(s)] = k
                for b in s.blocks:
                    for x in walk(b):
                        seg_of[id(x)] = k
        base = self.scratch_base()
        seen: set[int] = set()  # pure values whose inputs are planned (a DAG: each visited once)

        def need(o: Stmt) -> None:
            if o.op is Op.CONST or id(o) in self.spills or id(o) in seen:
                return
            if o.op in PURE:
                seen.add(id(o))
                for x in o.operands:
                    need(x)
                return
            self.spills[id(o)] = base + self.scratch_slots
            self.scratch_slots += 1

        for k, (_, stmts) in enumerate(segs):
            for s in stmts:
                for x in [s, *(y for b in s.blocks for y in walk(b))]:
                    for o in x.operands:
                        if seg_of.get(id(o), k) != k:
                            need(o)

    def _materialize(self, f: FunctionText, o: Stmt) -> None:
        """Make a value of an earlier segment available in `f`: recompute a pure one, load a spilled one."""
        if o.op is Op.CONST or o in f.names:
            return
        slot = self.spills.get(id(o))
        if slot is None:
            for x in o.operands:
                self._materialize(f, x)
            LOWERING[o.op](self, f, o)
            return
        p = f.tmp("spill")
        f.prologue.append(f"  {p} = getelementptr i64, ptr %ctx, i64 {slot}")
        if o.op is Op.ALLOCA:  # a local shared by segments lives in its scratch word
            f.names[o] = p
        else:
            v = f.tmp("spv")
            f.prologue.append(f"  {v} = load {llvm_type(o.vtype)}, ptr {p}")
            f.names[o] = v

    def _inputs(self, f: FunctionText, stmts: list[Stmt]) -> None:
        inside = {id(x) for s in stmts for x in [s, *(y for b in s.blocks for y in walk(b))]}
        for s in stmts:
            for x in [s, *(y for b in s.blocks for y in walk(b))]:
                for o in x.operands:
                    if id(o) not in inside:
                        self._materialize(f, o)

    def _params(self, name: str) -> str:
        if self.sim:
            return f"void @{name}(ptr %ctx, ptr %sreg)"  # launched by runtime/device.py HostDriver
        return f"ptx_kernel void @{name}(ptr %ctx)"

    def generate(self) -> str:
        segs = self._segments()
        self._plan_spills(segs)
        for k, (parallel, stmts) in enumerate(segs):
            name = f"{self.symbol}_k{k}"
            if parallel:
                self._loop_kernel(name, stmts[0])
            elif not all(s.op in PURE for s in stmts):
                self._serial_kernel(name, stmts)
        self.emit_functions()  # real functions: device functions the segments call (recursion uses the stack)
        self.module.globals.append("!0 = !{}")
        if self.fn_attrs and not self.sim:  # libdevice's __nvvm_reflect("__CUDA_FTZ") answers 1: its .ftz paths
            # (an id of its own: codegen numbers its branch weights from !1)
            self.module.globals += ["!llvm.module.flags = !{!100}", '!100 = !{i32 4, !"nvvm-reflect-ftz", i32 1}']
        return self.module.text()

    def _serial_kernel(self, name: str, stmts: list[Stmt]) -> None:
        f = GpuFunction(self, name, self._params(name), in_task=False, host_entry=True)  # launched
        self._inputs(f, stmts)
        for s in stmts:
            LOWERING[s.op](self, f, s)
            slot = self.spills.get(id(s))
            if slot is None:
                continue
            p = f.tmp("spill")
            f.emit(f"{p} = getelementptr i64, ptr %ctx, i64 {slot}")
            if s.op is Op.ALLOCA:
                f.emit(f"store {llvm_type(s.vtype)} {const_text(0, s.vtype)}, ptr {p}")
                f.names[s] = p
            else:
                f.emit(f"store {llvm_type(s.vtype)} {f.v(s)}, ptr {p}")
        f.emit("ret void")
        self.module.functions.append(f.text())
        self.launches.append(Launch(name, 1, 1))

    def _loop_kernel(self, name: str, s: Stmt) -> None:
        plan: LoopStrategy = s.attrs["strategy"]
        f = GpuFunction(self, name, self._params(name), in_task=True, host_entry=True)  # launched
        f.loop = s
        self._inputs(f, [s])
        tid, ntid, ctaid, nctaid = (f.sreg(r) for r in SREGS)
        gid, stride, gid64, stride64 = f.tmp("gid"), f.tmp("stride"), f.tmp("gid"), f.tmp("stride")
        f.prologue += [f"  {gid} = mul i32 {ctaid}, {ntid}", f"  {gid}.t = add i32 {gid}, {tid}",
                       f"  {stride} = mul i32 {ntid}, {nctaid}", f"  {gid64} = zext i32 {gid}.t to i64",
                       f"  {stride64} = zext i32 {stride} to i64"]
        f.tid = f"{gid}.t"  # ti.global_thread_idx
        self.open_reductions(f, plan)  # per-thread sums, added once per thread
        ty = llvm_type(s.vtype)
        b64, e64 = f.tmp("b"), f.tmp("e")
        for dst, src in ((b64, s.operands[0]), (e64, s.operands[1])):
            f.emit(f"{dst} = sext {ty} {f.v(src)} to i64" if ty != "i64" else f"{dst} = add i64 {f.v(src)}, 0")
        start = f.tmp("start")
        f.emit(f"{start} = add i64 {b64}, {gid64}")
        pre, head, body, latch, done = (f.label(x) for x in ("pre", "head", "body", "latch", "done"))
        f.emit(f"br label %{pre}")
        f.start_block(pre)
        f.emit(f"br label %{head}")
        f.start_block(head)
        i, nxt, c = f.tmp("i"), f.tmp("inext"), f.tmp("c")
        f.emit(f"{i} = phi i64 [{start}, %{pre}], [{nxt}, %{latch}]")
        f.emit(f"{c} = icmp slt i64 {i}, {e64}")
        f.emit(f"br i1 {c}, label %{body}, label %{done}")
        f.start_block(body)
        if ty == "i64":
            f.names[s] = i
        else:
            iv = f.tmp("iv")
            f.emit(f"{iv} = trunc i64 {i} to {ty}")
            f.names[s] = iv
        self.loop_body(f, s, done, latch)
        f.emit(f"{nxt} = add i64 {i}, {stride64}")
        f.emit(f"br label %{head}")
        f.start_block(done)
        self.flush_reductions(f, plan)
        f.emit("ret void")
        self.module.functions.append(f.text())
        block = int(s.attrs.get("block_dim") or DEFAULT_BLOCK)
        lo, hi = s.operands
        grid = None
        if lo.op is Op.CONST and hi.op is Op.CONST:
            n = max(int(hi.attrs["value"]) - int(lo.attrs["value"]), 0)
            grid = max(1, min(-(-n // block), 65535))
        if f._tape is not None and self.tape_entries > GPU_TAPE_LIMIT:  # as many threads as tape regions
            blocks = max(1, GLOBAL_TAPE_BYTES // (8 * self.tape_entries * block))
            grid = min(grid or blocks, blocks)
            self.tape_threads = max(self.tape_threads, grid * block)
        self.launches.append(Launch(name, grid, block))


# -- PTX -----------------------------------------------------------------------------------------------
# LLVM math intrinsics the NVPTX backend cannot select (it does sqrt, fabs, floor, ceil, minnum, ...), and every
# C math call of the registry (ir/opdefs.py `Libm`): libdevice has each as `__nv_<name>` / `__nv_<name>f`
_NV_INTRINSIC = ("sin", "cos", "exp", "log", "pow", "round", "tan", "exp2", "log2", "log10")
_NV_LIBM = tuple(sorted({d.lower_float.name for d in OPS.values() if isinstance(d.lower_float, Libm)}))


def _to_libdevice(text: str) -> str:
    """Rename host math in the module text to libdevice functions (`@llvm.sin.f32` -> `@__nv_sinf`,
    `@tanf` -> `@__nv_tanf`); f16 math was widened to f32 by codegen/arith.py."""
    def intr(m: re.Match) -> str:
        name, sfx = m.group(1), m.group(2)
        return f"@__nv_{name}{'f' if sfx == 'f32' else ''}("

    text = _widen_f16(text)
    text = re.sub(r"@llvm\.(" + "|".join(_NV_INTRINSIC) + r")\.(f32|f64)\(", intr, text)
    return re.sub(r"@(" + "|".join(_NV_LIBM) + r")(f?)\(", lambda m: f"@__nv_{m.group(1)}{m.group(2)}(", text)


def _widen_f16(text: str) -> str:
    """f16 math intrinsics (`@llvm.sin.f16`) become internal wrappers computing at f32: NVPTX selects none of
    them (LLVM aborts the process), and f16 is a storage type here anyway (loads widen to f32)."""
    decls = re.findall(r"^declare half @llvm\.(\w+)\.f16\(((?:half)(?:, half)*)\)$", text, flags=re.M)
    for name, params in decls:
        n = params.count("half")
        args = ", ".join(f"half %a{k}" for k in range(n))
        wide = [f"  %w{k} = fpext half %a{k} to float" for k in range(n)]
        fn = f"@llvm.{name}.f32"
        call = f"  %r = call float {fn}({', '.join(f'float %w{k}' for k in range(n))})"
        body = "\n".join([f"define internal half @sg_h_{name}({args}) alwaysinline {{", "entry:", *wide, call,
                          "  %h = fptrunc float %r to half", "  ret half %h", "}"])
        decl = f"declare float {fn}({', '.join(['float'] * n)})"
        text = text.replace(f"declare half @llvm.{name}.f16({params})", body if decl in text else f"{decl}\n{body}")
        text = text.replace(f"@llvm.{name}.f16(", f"@sg_h_{name}(")
    return text


def libdevice_path() -> str | None:
    env = os.environ.get("SIMGRAD_LIBDEVICE")
    for p in ((env,) if env else ()) + LIBDEVICE_CANDIDATES:
        if p and os.path.exists(p):
            return p
    home = os.environ.get("CUDA_HOME") or os.environ.get("CUDA_PATH")
    if home and os.path.exists(os.path.join(home, "nvvm/libdevice/libdevice.10.bc")):
        return os.path.join(home, "nvvm/libdevice/libdevice.10.bc")
    return None


def compile_ptx(text: str, kernels: set[str], cc: str = "sm_80") -> str:
    """PTX assembly of a GpuCodegen(sim=False) module: libdevice linked (internalised), -O3, NVPTX."""
    import llvmlite.binding as llvm

    llvm.initialize_all_targets()
    llvm.initialize_all_asmprinters()
    tm = llvm.Target.from_triple(TRIPLE).create_target_machine(cpu=cc, opt=3)
    text = _to_libdevice(text)
    context = llvm.create_context()  # what LLVM interns (libdevice's constants too) dies with it
    mod = llvm.parse_assembly(text, context=context)
    mod.triple = TRIPLE
    mod.data_layout = str(tm.target_data)
    mod.verify()
    if "@__nv_" in text:
        path = libdevice_path()
        if path is None:
            raise RuntimeError("arch=cuda math needs libdevice.10.bc (set SIMGRAD_LIBDEVICE or CUDA_HOME)")
        with open(path, "rb") as fh:
            lib = llvm.parse_bitcode(fh.read(), context=context)
        lib.triple = TRIPLE
        lib.data_layout = mod.data_layout
        mod.link_in(lib)
        for fn in mod.functions:  # only the kernels stay visible: the rest of libdevice is dropped
            if not fn.is_declaration and fn.name not in kernels:
                fn.linkage = "internal"
    pto = llvm.create_pipeline_tuning_options(speed_level=3)
    pb = llvm.create_pass_builder(tm, pto)
    pb.getModulePassManager().run(mod, pb)
    ptx = tm.emit_assembly(mod)
    mod.close()
    del mod, context
    return ptx


def ptxas_path() -> str | None:
    return shutil.which("ptxas") or next((p for p in ("/usr/local/cuda/bin/ptxas",) if os.path.exists(p)), None)


def ptxas_check(ptx: str, archs: tuple[str, ...] = ("sm_80", "sm_90")) -> None:
    """Assemble `ptx` with ptxas for each arch; a ptxas error raises RuntimeError with its message."""
    exe = ptxas_path()
    if exe is None:
        raise RuntimeError("SIMGRAD_PTX_CHECK=1 needs ptxas on PATH (CUDA toolkit or the nvidia-cuda-nvcc wheel)")
    with tempfile.TemporaryDirectory() as d:
        src = os.path.join(d, "k.ptx")
        with open(src, "w") as fh:
            fh.write(ptx)
        for arch in archs:
            r = subprocess.run([exe, f"-arch={arch}", src, "-o", os.path.join(d, f"k_{arch}.cubin")],
                               capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"ptxas -arch={arch} rejected the kernel's PTX:\n{r.stderr.strip()}")


def kernel_ptx(kernel: Kernel, symbol: str, *, tape_entries: int = 256, debug: bool = False,
               fast_math: bool = True, flush: bool = False) -> tuple[str, list[Launch]]:
    """PTX of `kernel` (after the passes) and its launch sequence."""
    cg = GpuCodegen(kernel, symbol, sim=False, tape_entries=tape_entries, debug=debug, fast_math=fast_math,
                    flush=flush)
    text = cg.generate()
    return compile_ptx(text, {ln.symbol for ln in cg.launches}), cg.launches

