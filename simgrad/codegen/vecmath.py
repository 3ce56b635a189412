"""The LLVM backend of ir/vecmath.py: the math functions' vector versions, which a vectorised loop calls in place
of libm. A math call stays the scalar libm call (`nobuiltin`, so LLVM keeps it as written) and carries LLVM's
vector-function ABI attribute naming our vector functions of 2..16 lanes: the loop vectoriser, which cannot
vectorise a libm call otherwise (llvmlite gives it no vector math library), calls them for whole vectors. A loop
that does not vectorise keeps libm's scalar code, as before (faster there than our f64-based code: measured on
snow_phaseField, whose loops do not vectorise, inlining our functions made a step 1.7-2.2x slower). Used on the
CPU under fast_math (KernelCodegen.vector_math); the GPU keeps libdevice, fast_math=False plain libm calls."""

from __future__ import annotations

import re
import struct

from simgrad.ir import vecmath as vm
from simgrad.ir.ops import Op

#: lanes of the vector versions, by element type (AVX-512 holds 8 doubles, 16 floats)
WIDTHS = {"double": (4, 8), "float": (8, 16)}
_SLOW_WIDTHS = (4, 8)
_USED = "@llvm.compiler.used"


def _literal(v, ty: str) -> str:
    if ty in ("double", "float"):  # LLVM writes float constants as the double of the same value
        return f"0x{struct.unpack('<Q', struct.pack('<d', float(v)))[0]:016X}"
    if ty == "i1":
        return "true" if v else "false"
    return str(int(v))


_SUFFIX = {"double": "f64", "float": "f32", "i64": "i64", "i32": "i32", "i1": "i1", "ptr": "p0"}


class _Text:
    """Each operation as one LLVM instruction on vectors of `w` lanes."""

    def __init__(self, w: int) -> None:
        self.w = w
        self.lines: list[str] = []
        self.decls: set[str] = set()
        self.tables: set[str] = set()
        self.slow: set[tuple[str, int]] = set()  # libm functions the fallbacks call (name, arity)
        self.n = 0

    def t(self, ty: str) -> str:
        return f"<{self.w} x {ty}>"

    def _new(self, text: str, ty: str) -> vm.V:
        self.n += 1
        name = f"%v{self.n}"
        self.lines.append(f"  {name} = {text}")
        return vm.V(self, name, ty)

    def const(self, v, ty: str) -> vm.V:
        return vm.V(self, f"splat ({ty} {_literal(v, ty)})", ty)

    def bin(self, op: str, a: vm.V, b: vm.V) -> vm.V:
        return self._new(f"{op} {self.t(a.ty)} {a.h}, {b.h}", a.ty)

    def cmp(self, pred: str, a: vm.V, b: vm.V) -> vm.V:
        kind = "fcmp" if a.ty in ("double", "float") else "icmp"
        return self._new(f"{kind} {pred} {self.t(a.ty)} {a.h}, {b.h}", "i1")

    def select(self, c: vm.V, a: vm.V, b: vm.V) -> vm.V:
        return self._new(f"select {self.t('i1')} {c.h}, {self.t(a.ty)} {a.h}, {self.t(b.ty)} {b.h}", a.ty)

    def cast(self, how: str, a: vm.V, ty: str) -> vm.V:
        return self._new(f"{how} {self.t(a.ty)} {a.h} to {self.t(ty)}", ty)

    def call(self, name: str, *args: vm.V) -> vm.V:
        vt = self.t("double")
        fn = f"llvm.{name}.v{self.w}f64"
        self.decls.add(f"declare {vt} @{fn}({', '.join([vt] * len(args))})")
        return self._new(f"call {vt} @{fn}({', '.join(f'{vt} {x.h}' for x in args)})", "double")

    def load(self, table: str, idx: vm.V) -> vm.V:
        self.tables.add(table)
        w = self.w
        p = self._new(f"getelementptr inbounds double, ptr @sg_vm_{table}, {self.t('i64')} {idx.h}", "ptr")
        fn = f"llvm.masked.gather.v{w}f64.v{w}p0"
        self.decls.add(f"declare {self.t('double')} @{fn}({self.t('ptr')}, {self.t('i1')}, {self.t('double')})")
        return self._new(f"call {self.t('double')} @{fn}({self.t('ptr')} align 8 {p.h}, "
                         f"{self.t('i1')} splat (i1 true), {self.t('double')} poison)", "double")

    def fallback(self, cond: vm.V, name: str, args: list[vm.V], fast: vm.V) -> vm.V:
        """libm's `name` for the lanes where cond holds (a call that does nothing when none does)."""
        self.slow.add((name, len(args)))
        vt = self.t("double")
        params = ", ".join(f"{vt} {a.h}" for a in args)
        r = self._new(f"call {vt} @sg_vm_{name}_slow_v{self.w}({params}, {self.t('i1')} {cond.h})", "double")
        return self.select(cond, r, fast)


def _slow_functions(name: str, arity: int) -> list[str]:
    """Vector functions that call libm's `name` on the lanes their mask selects (the others: the first operand)."""
    out = []
    for w in _SLOW_WIDTHS:
        vt = f"<{w} x double>"
        lines = [f"define internal {vt} @sg_vm_{name}_slow_v{w}("
                 + ", ".join(f"{vt} %a{i}" for i in range(arity)) + f", <{w} x i1> %m) noinline nounwind {{",
                 "entry:", f"  %bits = bitcast <{w} x i1> %m to i{w}", f"  %none = icmp eq i{w} %bits, 0",
                 "  br i1 %none, label %done, label %l0"]
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
                      f"n{i}:", f"  %acc{i} = phi {vt} [ %v{i}, %c{i} ], [ {acc}, %l{i} ]",
                      f"  br label %{f'l{i + 1}' if i + 1 < w else 'done'}"]
            acc = f"%acc{i}"
        lines += ["done:", f"  %out = phi {vt} [ %a0, %entry ], [ {acc}, %n{w - 1} ]", f"  ret {vt} %out", "}"]
        out.append("\n".join(lines))
    return out


#: functions whose value where every operand is zero is exact and cheap (cos 0 = 1, exp 0 = 1, sin +-0 = +-0,
#: tan +-0 = +-0, atan2(+-0, +0) = +-0), by what the result is: a constant, or the first operand
_AT_ZERO = {Op.COS: 1.0, Op.EXP: 1.0, Op.SIN: None, Op.TAN: None, Op.ATAN2: None}


def _zero_shortcut(op: Op, base: str, w: int, ty: str, arity: int, full: str) -> str:
    """`{base}_v{w}`: the value at zero when every lane's operands are zeros (the flat part of a field: a zero
    gradient's angle and its cosine in snow_phaseField), else `full`'s. Bit for bit libm's either way."""
    vt = f"<{w} x {ty}>"
    it = f"<{w} x i{64 if ty == 'double' else 32}>"
    params = ", ".join(f"{vt} %a{i}" for i in range(arity))
    lines = [f"define internal {vt} @{base}_v{w}({params}) nounwind {{", "entry:",
             f"  %z{'0' if arity == 2 else ''} = fcmp oeq {vt} %a0, zeroinitializer"]
    if arity == 2:  # atan2(y, x): x must be +0 (x = -0 gives +-pi)
        lines += [f"  %xb = bitcast {vt} %a1 to {it}", f"  %z1 = icmp eq {it} %xb, zeroinitializer",
                  f"  %z = and <{w} x i1> %z0, %z1"]
    value = "%a0" if _AT_ZERO[op] is None else f"splat ({ty} {_literal(_AT_ZERO[op], ty)})"
    lines += [f"  %bits = bitcast <{w} x i1> %z to i{w}", f"  %all = icmp eq i{w} %bits, -1",
              "  br i1 %all, label %zero, label %full", f"zero:\n  ret {vt} {value}",
              f"full:\n  %r = call {vt} {full}({params})\n  ret {vt} %r", "}"]
    return "\n".join(lines)


def libm_name(op: Op, ty: str) -> str:
    name = (vm.FUNCTIONS if ty == "float" else vm.FUNCTIONS64)[op][0]
    return name + ("f" if ty == "float" else "")


class _Variants:
    """The vector versions of one function (unmasked and masked, per width) and what they need in the module."""

    def __init__(self, op: Op, ty: str, arity: int) -> None:
        fn = (vm.FUNCTIONS if ty == "float" else vm.FUNCTIONS64)[op][1]
        base = f"sg_vm_{libm_name(op, ty)}"
        self.functions: list[str] = []
        self.decls: set[str] = set()
        self.tables: set[str] = set()
        slow: set[tuple[str, int]] = set()
        names = []
        for w in WIDTHS[ty]:
            be = _Text(w)
            r = fn(*(vm.V(be, f"%a{i}", ty) for i in range(arity)))
            vt = be.t(ty)
            params = ", ".join(f"{vt} %a{i}" for i in range(arity))
            args = ", ".join(f"{vt} %a{i}" for i in range(arity))
            full = f"@{base}_v{w}" if op not in _AT_ZERO else f"@{base}_full{w}"
            self.functions.append("\n".join([f"define internal {vt} {full}({params}) nounwind {{", "entry:",
                                             *be.lines, f"  ret {vt} {r.h}", "}"]))
            if op in _AT_ZERO:
                self.functions.append(_zero_shortcut(op, base, w, ty, arity, full))
            # masked: nothing computed when no lane is on (a vectorised branch its loop rarely takes, the else
            # side of snow_phaseField's `if gradNorm < 1e-8` on a mostly flat field); off lanes are don't-care
            self.functions.append(f"define internal {vt} @{base}_m{w}({params}, <{w} x i1> %m) nounwind {{\n"
                                  f"entry:\n  %bits = bitcast <{w} x i1> %m to i{w}\n"
                                  f"  %none = icmp eq i{w} %bits, 0\n  br i1 %none, label %off, label %on\n"
                                  f"on:\n  %r = call {vt} @{base}_v{w}({args})\n  ret {vt} %r\n"
                                  f"off:\n  ret {vt} %a0\n}}")
            self.decls |= be.decls
            self.tables |= be.tables
            slow |= be.slow
            names += [f"@{base}_v{w}", f"@{base}_m{w}"]
        for name, k in sorted(slow):
            self.functions += _slow_functions(name, k)
            self.decls.add(f"declare double @{name}({', '.join(['double'] * k)})")
            names += [f"@sg_vm_{name}_slow_v{w}" for w in _SLOW_WIDTHS]
        self.used = names
        v = "v" * arity
        self.attrs = ("nounwind willreturn memory(none) \"vector-function-abi-variant\"=\""
                      + ",".join(f"_ZGV_LLVM_{k}{w}{v}_{libm_name(op, ty)}({base}_{suffix}{w})"
                                 for w in WIDTHS[ty] for k, suffix in (("N", "v"), ("M", "m"))) + "\"")


def _table_global(name: str) -> str:
    data = vm.TABLES[name]
    values = ", ".join(f"double {_literal(v, 'double')}" for v in data)
    return f"@sg_vm_{name} = internal unnamed_addr constant [{data.size} x double] [{values}], align 64"


_CACHE: dict[tuple[Op, str], _Variants] = {}


def emit_call(f, op: Op, ty: str, args: list[str]) -> str:
    """`op` of float or double operands: the libm call, with our vector versions defined in the module (kept
    alive for the vectoriser through llvm.compiler.used) and named on the call."""
    if (op, ty) not in _CACHE:
        _CACHE[(op, ty)] = _Variants(op, ty, len(args))
    d = _CACHE[(op, ty)]
    module = f.gen.module
    if d.functions[0] not in module.functions:
        module.functions.extend(t for t in d.functions if t not in module.functions)
        for decl in d.decls:
            module.declare(decl)
        for t in d.tables:
            if not any(g.startswith(f"@sg_vm_{t} ") for g in module.globals):
                module.globals.append(_table_global(t))
        old = next((g for g in module.globals if g.startswith(_USED)), None)
        names = sorted(set(d.used) | (set(re.findall(r"@sg_vm_\w+", old)) if old else set()))
        if old:
            module.globals.remove(old)
        module.globals.append(f"{_USED} = appending global [{len(names)} x ptr] "
                              f"[{', '.join(f'ptr {n}' for n in names)}], section \"llvm.metadata\"")
    name = libm_name(op, ty)
    module.declare(f"declare {ty} @{name}({', '.join([ty] * len(args))})")
    r = f.tmp(name)
    f.emit(f"{r} = call {ty} @{name}({', '.join(f'{ty} {a}' for a in args)}) {d.attrs}")
    return r
