"""f16 <-> f32 conversion routines for x86 CPUs without F16C.

There LLVM lowers every half conversion (and half arithmetic, done in f32) to calls of compiler-rt's
`__extendhfsf2` / `__truncsfhf2`, which MCJIT cannot resolve: the process aborts. runtime/jit.py
links these definitions (runtime/ll/half.ll) first when the host lacks F16C. Integer code only (a
`fpext half` there would call itself); rounding is to nearest, ties to even, as the hardware's."""

from __future__ import annotations

from simgrad.runtime import ll

SYMBOLS = ["__extendhfsf2", "__truncsfhf2"]


def needed(triple: str, features: str) -> bool:
    return triple.startswith(("x86_64", "i386", "i686")) and "+f16c" not in features.split(",")


IR = ll.load("half")
