"""The LLVM backend of ir/vecmath.py: each f32 math function as an internal always-inline function of plain
arithmetic and selects, so a loop that calls it vectorises (a libm call would keep the loop scalar). Used on
the CPU with fast_math (KernelCodegen.vector_math); the GPU keeps libdevice, fast_math=False keeps libm."""

from __future__ import annotations

import re
import struct

from simgrad.ir import vecmath as vm
from simgrad.ir.ops import Op

_INTRINSIC = {"fabs": "llvm.fabs.f64", "copysign": "llvm.copysign.f64", "fma": "llvm.fma.f64"}
#: the vector widths whose masked variants a fallback to libm has (the loop vectoriser calls them for the lanes
#: outside the fast path: LLVM's VFABI, `vector-function-abi-variant`)
_WIDTHS = (2, 4, 8, 16)


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
        self.tables: set[str] = set()
        self.slow: set[tuple[str, int]] = set()  # libm functions the fallbacks call (name, arity)
        self.n = 0
        self.block = "entry"

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

    def call(self, name: str, *args: vm.V) -> vm.V:
        fn = _INTRINSIC[name]
        self.decls.add(f"declare double @{fn}({', '.join(['double'] * len(args))})")
        return self._new(f"call double @{fn}({', '.join(f'double {x.h}' for x in args)})", "double")

    def load(self, table: str, idx: vm.V) -> vm.V:
        self.tables.add(table)
        size = vm.TABLES[table].size
        p = self._new(f"getelementptr inbounds [{size} x double], ptr @sg_vm_{table}, i64 0, i64 {idx.h}", "ptr")
        return self._new(f"load double, ptr {p.h}, align 8", "double")

    def fallback(self, cond: vm.V, name: str, args: list[vm.V], fast: vm.V) -> vm.V:
        """libm's `name` for the lanes where cond holds: a branch the vectoriser predicates, the call carrying
        its masked vector variants."""
        self.slow.add((name, len(args)))
        self.n += 1
        slow, join = f"slow{self.n}", f"join{self.n}"
        self.lines.append(f"  br i1 {cond.h}, label %{slow}, label %{join}")
        self.lines.append(f"{slow}:")
        r = f"%s{self.n}"
        params = ", ".join(f"double {a.h}" for a in args)
        self.lines.append(f"  {r} = call double @sg_vm_{name}_slow({params}) {_variant_attrs(name, len(args))}")
        self.lines.append(f"  br label %{join}")
        self.lines.append(f"{join}:")
        out = self._new(f"phi double [ {r}, %{slow} ], [ {fast.h}, %{self.block} ]", "double")
        self.block = join
        return out


def _variant_attrs(name: str, arity: int) -> str:
    v = "v" * arity
    variants = ",".join(f"_ZGV_LLVM_M{w}{v}_sg_vm_{name}_slow(sg_vm_{name}_slow_v{w})" for w in _WIDTHS)
    return f'nounwind willreturn memory(none) "vector-function-abi-variant"="{variants}"'


def _slow_functions(name: str, arity: int) -> list[str]:
    """The scalar libm wrapper and its masked vector variants (each active lane calls libm; none: nothing)."""
    params = ", ".join(f"double %a{i}" for i in range(arity))
    args = ", ".join(f"double %a{i}" for i in range(arity))
    out = [f"define internal double @sg_vm_{name}_slow({params}) noinline nounwind willreturn memory(none) {{\n"
           f"  %r = call double @{name}({args})\n  ret double %r\n}}"]
    for w in _WIDTHS:
        vt = f"<{w} x double>"
        lines = [f"define internal {vt} @sg_vm_{name}_slow_v{w}("
                 + ", ".join(f"{vt} %a{i}" for i in range(arity)) + f", <{w} x i1> %m) noinline nounwind {{",
                 "entry:", f"  %bits = bitcast <{w} x i1> %m to i{w}", f"  %none = icmp eq i{w} %bits, 0",
                 f"  br i1 %none, label %done, label %l0"]
        acc = "%a0"
        for i in range(w):
            lines += [f"l{i}:", f"  %m{i} = extractelement <{w} x i1> %m, i32 {i}",
                      f"  br i1 %m{i}, label %c{i}, label %n{i}", f"c{i}:"]
            xs = []
            for j in range(arity):
                lines.append(f"  %x{i}_{j} = extractelement {vt} %a{j}, i32 {i}")
                xs.append(f"double %x{i}_{j}")
            lines += [f"  %y{i} = call double @{name}({', '.join(xs)})",
                      f"  %v{i} = insertelement {vt} {acc}, double %y{i}, i32 {i}", f"  br label %n{i}",
                      f"n{i}:", f"  %acc{i} = phi {vt} [ %v{i}, %c{i} ], [ {acc}, %l{i} ]"]
            nxt = f"l{i + 1}" if i + 1 < w else "done"
            lines.append(f"  br label %{nxt}")
            acc = f"%acc{i}"
        lines += ["done:", f"  %out = phi {vt} [ %a0, %entry ], [ {acc}, %n{w - 1} ]", f"  ret {vt} %out", "}"]
        out.append("\n".join(lines))
    return out


class _Definition:
    """One function's text and what it needs in the module."""

    def __init__(self, symbol: str, ty: str, fn, arity: int) -> None:
        be = _Text()
        r = fn(*(vm.V(be, f"%a{i}", ty) for i in range(arity)))
        params = ", ".join(f"{ty} %a{i}" for i in range(arity))
        self.text = "\n".join([f"define internal {ty} @{symbol}({params}) alwaysinline nounwind {{", "entry:",
                               *be.lines, f"  ret {ty} {r.h}", "}"])
        self.decls = be.decls | {f"declare double @{n}({', '.join(['double'] * k)})" for n, k in be.slow}
        self.tables = be.tables
        self.slow = [t for n, k in sorted(be.slow) for t in _slow_functions(n, k)]
        # kept as written: IPO would otherwise drop the unused variants and specialise the wrapper (a constant
        # argument removed), which unmatches its variants
        self.used = [f"@sg_vm_{n}_slow{v}" for n, k in sorted(be.slow) for v in ("", *(f"_v{w}" for w in _WIDTHS))]


def _table_global(name: str) -> str:
    data = vm.TABLES[name]
    values = ", ".join(f"double {_literal(v, 'double')}" for v in data)
    return f"@sg_vm_{name} = internal unnamed_addr constant [{data.size} x double] [{values}], align 64"


_CACHE: dict[tuple[Op, str], _Definition] = {}
_USED = "@llvm.compiler.used"


def emit_call(f, op: Op, ty: str, args: list[str]) -> str:
    """`op` of float or double operands as a call of its vectorisable function, defined in the module on first
    use (with its tables, and the libm fallbacks' vector variants kept alive for the vectoriser)."""
    name, fn = (vm.FUNCTIONS if ty == "float" else vm.FUNCTIONS64)[op]
    symbol = f"sg_vm_{name}{'f' if ty == 'float' else ''}"
    if (op, ty) not in _CACHE:
        _CACHE[(op, ty)] = _Definition(symbol, ty, fn, len(args))
    d = _CACHE[(op, ty)]
    module = f.gen.module
    if d.text not in module.functions:
        module.functions.append(d.text)
        module.functions.extend(t for t in d.slow if t not in module.functions)
        for decl in d.decls:
            module.declare(decl)
        for t in d.tables:
            if not any(g.startswith(f"@sg_vm_{t} ") for g in module.globals):
                module.globals.append(_table_global(t))
        if d.used:
            old = next((g for g in module.globals if g.startswith(_USED)), None)
            names = sorted(set(d.used) | (set(re.findall(r"@sg_vm_\w+", old)) if old else set()))
            if old:
                module.globals.remove(old)
            module.globals.append(f"{_USED} = appending global [{len(names)} x ptr] "
                                  f"[{', '.join(f'ptr {n}' for n in names)}], section \"llvm.metadata\"")
    r = f.tmp(name)
    f.emit(f"{r} = call {ty} @{symbol}({', '.join(f'{ty} {a}' for a in args)})")
    return r
