"""The LLVM backend of ir/vecmath.py: each f32 math function as an internal always-inline function of plain
arithmetic and selects, so a loop that calls it vectorises (a libm call would keep the loop scalar). Used on
the CPU with fast_math (KernelCodegen.vector_math); the GPU keeps libdevice, fast_math=False keeps libm."""

from __future__ import annotations

import struct

from simgrad.ir import vecmath as vm
from simgrad.ir.ops import Op

_TABLE = "@sg_vm_two_over_pi"
_INTRINSIC = {"fabs": "llvm.fabs.f64", "copysign": "llvm.copysign.f64"}


def _literal(v, ty: str) -> str:
    if ty in ("double", "float"):  # LLVM writes float constants as the double of the same value
        return f"0x{struct.unpack('<Q', struct.pack('<d', float(v)))[0]:016X}"
    if ty == "i1":
        return "true" if v else "false"
    return str(int(v))


class _Text:
    """Each operation as one LLVM instruction appended to `lines`."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.decls: set[str] = set()
        self.n = 0

    def _new(self, text: str, ty: str) -> vm.V:
        self.n += 1
        name = f"%v{self.n}"
        self.lines.append(f"  {name} = {text}")
        return vm.V(self, name, ty)

    def const(self, v, ty: str) -> vm.V:
        return vm.V(self, _literal(v, ty), ty)

    def bin(self, op: str, a: vm.V, b: vm.V) -> vm.V:
        return self._new(f"{op} {a.ty} {a.h}, {b.h}", a.ty)

    def cmp(self, pred: str, a: vm.V, b: vm.V) -> vm.V:
        kind = "fcmp" if a.ty in ("double", "float") else "icmp"
        return self._new(f"{kind} {pred} {a.ty} {a.h}, {b.h}", "i1")

    def select(self, c: vm.V, a: vm.V, b: vm.V) -> vm.V:
        return self._new(f"select i1 {c.h}, {a.ty} {a.h}, {b.ty} {b.h}", a.ty)

    def cast(self, how: str, a: vm.V, ty: str) -> vm.V:
        return self._new(f"{how} {a.ty} {a.h} to {ty}", ty)

    def call(self, name: str, a: vm.V, b: vm.V | None = None) -> vm.V:
        fn = _INTRINSIC[name]
        args = [a] if b is None else [a, b]
        self.decls.add(f"declare double @{fn}({', '.join(['double'] * len(args))})")
        return self._new(f"call double @{fn}({', '.join(f'double {x.h}' for x in args)})", "double")

    def load(self, idx: vm.V) -> vm.V:
        p = self._new(f"getelementptr inbounds [{vm.TABLE.size} x double], ptr {_TABLE}, i64 0, i64 {idx.h}", "ptr")
        return self._new(f"load double, ptr {p.h}, align 8", "double")


def _definition(name: str, fn, arity: int) -> tuple[str, set[str]]:
    be = _Text()
    args = [vm.V(be, f"%a{i}", "float") for i in range(arity)]
    r = fn(*args)
    params = ", ".join(f"float %a{i}" for i in range(arity))
    text = "\n".join([f"define internal float @sg_vm_{name}f({params}) alwaysinline nounwind {{", *be.lines,
                      f"  ret float {r.h}", "}"])
    return text, be.decls


def table_global() -> str:
    values = ", ".join(f"double {_literal(v, 'double')}" for v in vm.TABLE)
    return f"{_TABLE} = internal unnamed_addr constant [{vm.TABLE.size} x double] [{values}], align 64"


_CACHE: dict[Op, tuple[str, set[str]]] = {}


def emit_call(f, op: Op, args: list[str]) -> str:
    """`op` of f32 operands as a call of its vectorisable function, defined in the module on first use."""
    name, fn = vm.FUNCTIONS[op]
    if op not in _CACHE:
        _CACHE[op] = _definition(name, fn, len(args))
    text, decls = _CACHE[op]
    module = f.gen.module
    if text not in module.functions:
        module.functions.append(text)
        for d in decls:
            module.declare(d)
        if "@sg_vm_" in text and _TABLE in text and not any(g.startswith(_TABLE) for g in module.globals):
            module.globals.append(table_global())
    r = f.tmp(name)
    f.emit(f"{r} = call float @sg_vm_{name}f({', '.join(f'float {a}' for a in args)})")
    return r
