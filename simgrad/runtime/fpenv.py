"""Flush to zero: a float result too small to be normal becomes a zero of its sign.

Taichi runs every backend in this mode (it sets the CPU's FTZ bit for the whole process; CUDA kernels use the
.ftz forms), for speed: subnormal results cost x86 a microcode assist each (vortex_rings runs twice as fast).
simgrad does the same by default (`ti.init(flush_denormals=False)` keeps IEEE subnormals), but only while its
own native code runs: numpy and Python around it keep IEEE arithmetic. Inputs are not flushed (FTZ without DAZ,
as Taichi's CPU: a subnormal read from a field still counts as itself).

- x86-64: FTZ is bit 15 of MXCSR, a per-thread register. A kernel's entry saves the caller's MXCSR, sets the
  bit for its own body and restores the caller's on return (`wrap_entry`); the pool's workers take the
  launching thread's MXCSR with each job (threadpool.ll, `pool_params`), so every chunk runs in its mode.
- Other CPUs: no switch is emitted; run-time results keep IEEE subnormals (folding still flushes).
- Every function also tells LLVM the mode (`FN_ATTRS`), so its own constant folding flushes as the machine
  does, and ir/numeric.py's folds flush (`numeric.flushing`) so a folded value equals the computed one."""

from __future__ import annotations

import platform
import re

FTZ_BIT = 0x8000  # MXCSR.FTZ
CPU_ATTRS = '"denormal-fp-math"="preserve-sign,ieee"'  # results flushed, inputs as they are
GPU_ATTRS = '"denormal-fp-math-f32"="preserve-sign,preserve-sign"'  # NVPTX's .ftz forms for f32 (f64 has none)


def switchable(machine: str | None = None) -> bool:
    """Whether this machine's native code can switch flush-to-zero on (x86-64's MXCSR)."""
    return (machine or platform.machine()).lower() in ("x86_64", "amd64")


_HEADER = re.compile(r"^(?P<pre>.*?)void @(?P<name>[\w.$]+)\((?P<args>[^)]*)\)$")


def wrap_entry(params: str, attrs: str, lines: list[str]) -> str:
    """An entry function `define <params>` whose body (`lines`, from its first label on) runs with FTZ set: the
    body becomes `<name>.ftz` (noinline, so no float operation moves across the MXCSR writes) and `<name>`
    saves MXCSR, sets FTZ, calls it and restores the caller's MXCSR."""
    m = _HEADER.match(params)
    if m is None:
        raise ValueError(f"internal: not a void function header: {params}")
    name, args = m.group("name"), m.group("args")
    names = ", ".join(a.strip() for a in args.split(",")) if args.strip() else ""
    inner = f"@{name}.ftz"
    return "\n".join([
        f"define internal void {inner}({args}) noinline {attrs} {{", *lines, "}",
        f"define {m.group('pre')}void @{name}({args}) {{",
        "entry:",
        "  %mxcsr.old = alloca i32, align 4",
        "  %mxcsr.new = alloca i32, align 4",
        "  call void @llvm.x86.sse.stmxcsr(ptr %mxcsr.old)",
        "  %mxcsr.v = load i32, ptr %mxcsr.old, align 4",
        f"  %mxcsr.ftz = or i32 %mxcsr.v, {FTZ_BIT}",
        "  store i32 %mxcsr.ftz, ptr %mxcsr.new, align 4",
        "  call void @llvm.x86.sse.ldmxcsr(ptr %mxcsr.new)",
        f"  call void {inner}({names})",
        "  call void @llvm.x86.sse.ldmxcsr(ptr %mxcsr.old)",
        "  ret void",
        "}",
    ])


DECLS = ("declare void @llvm.x86.sse.stmxcsr(ptr)", "declare void @llvm.x86.sse.ldmxcsr(ptr)")


def pool_params(machine: str) -> dict[str, str]:
    """threadpool.ll's places for the mode: the launching thread publishes its MXCSR with the job
    (`fp_publish`), a worker loads it before running chunks (`fp_adopt`); empty where there is no switch."""
    if not switchable(machine):
        return {"fp_decl": "", "fp_publish": "", "fp_adopt": ""}
    return {"fp_decl": "\n".join(DECLS),
            "fp_publish": "call void @llvm.x86.sse.stmxcsr(ptr @sg_job_mxcsr)",
            "fp_adopt": "call void @llvm.x86.sse.ldmxcsr(ptr @sg_job_mxcsr)"}
