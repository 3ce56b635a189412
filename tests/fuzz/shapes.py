"""Random programs with the shapes real programs have (issue 21): what gen.py's flat kernels never reach.

Forward programs (`forward_case`): one module text, executed twice with a different `ti` put in its
globals: simgrad compiles it, and `Ref` (a small Python/numpy stand-in for `ti`) runs it as plain Python.
The text has a @ti.dataclass with a ti.func method, ti.funcs and ti.real_funcs that `return` from inside
loops and branches, a kernel taking ndarrays whose parallel loop nests while/for/if, ti.static and
ti.ndrange loops with break/continue at several depths, local vectors and matrices indexed at run time,
struct values, vector fields, u32 hashing, atomics (ti.atomic_* and `+=`) on locals, fields and ndarrays,
slots taken from a shared counter, selects and ternaries whose operands are loads, writes that activate a
sparse field (bitmasked, pointer over dense, pointer over bitmasked) and appends to a dynamic list; a
second kernel reads them back with struct-fors. Lines whose Python meaning differs from the kernel's (an
atomic returns the old value and updates its place) carry their reference form in a `# REF:` comment
(`reference_source`). Every output must agree: integers exactly, f64 to rtol 1e-6 (the f64 add-atomic
sums in a different order), compaction slots as a multiset.

Gradient programs (`gradient_case`): f64 kernels of the same shapes (early-returning ti.funcs, break and
continue under integer conditions, static/ndrange loops, run-time indexed local vectors/matrices, struct
values, atomics into a global and a local, selects of loads) checked by gen.run_gradient (central finite
differences) and gen.run_forward_mode (FwdMode against reverse).

`MUTANTS` plant bugs in the reference (tests/fuzz/test_shapes.py shows the campaign catches each);
taichi_check.py runs the forward programs under real Taichi against the reference (the oracle's check).
"""

from __future__ import annotations

import random
import re

import gen
import numpy as np

T = gen.T  # iterations of the outer (parallel) loop
NSP = 16  # cells of the sparse field
DYN = 8  # capacity of each dynamic list
LAYOUTS = ("bitmasked", "pointer_dense", "pointer_bitmasked")
ATOMIC_INT = ("add", "sub", "min", "max", "and", "or", "xor")  # tot[k] takes only ATOMIC_INT[k]; tot[7] `+=`
ATOMIC_F64 = ("add", "max", "min")  # totf[k]
TOT_INIT = np.array([0, 0, 2**30, -(2**30), -1, 0, 0, 0, 0, 0, 0, 0], np.int32)
TOTF_INIT = np.array([0.0, -1e300, 1e300])
N_OI, N_OF = 8, 10
CAP = 64  # slots of the compaction buffer


class _Shapes(gen._Gen):
    """gen._Gen's operators over more leaves (loads through ndarrays, vectors, matrices, struct members,
    calls, ternaries of loads) and more statements; `ctx` is "kernel" or "func" (a func body sees only its
    parameters u (i32), v (f64), its accumulators r (i32), s (f64), loop variables and fields)."""

    def __init__(self, rng: random.Random, size: int):
        super().__init__(rng, size)
        self.ctx = "kernel"
        self.loops = 0  # loops around the statement being made (break/continue need one)
        self.depth = 0  # block nesting, to bound the program
        self.loop_vars: list[str] = []
        self.leaf_nest = 0
        self.int_funcs: list[str] = []  # ti.func (u: i32, v: f64) -> i32
        self.f64_funcs: list[str] = []  # ti.func / ti.real_func (u: i32, v: f64) -> f64
        self.ret_type = "i32"
        self.no_jump = False  # inside a ti.static loop

    # -- leaves ------------------------------------------------------------------------------------
    def idx(self, n: int) -> str:
        """A run-time index in [0, n): Python's % on i32 is never negative, in both semantics."""
        r = self.r
        base = r.choice(self._ints_simple() + [f"{self._int_simple()} + {self._int_simple()}"])
        return f"({base}) % {n}"

    def _ints_simple(self) -> list[str]:
        if self.ctx == "func":
            return ["u", "r"] + self.loop_vars
        return [f"a{k}" for k in range(gen.N_INT)] + ["t"] + self.loop_vars

    def _int_simple(self) -> str:
        return self.r.choice(self._ints_simple() + [str(self.r.randint(-9, 9))])

    def _int_load(self) -> str:
        r = self.r
        if self.ctx == "func":
            return f"ai[{self.idx(T)}]"
        return r.choice([f"ai[{self.idx(T)}]", f"nd[{self.idx(T)}]", f"v[{self.idx(3)}]", "p.a",
                         f"gv[t][{self.idx(3)}]", f"ti.cast(h >> {r.randint(18, 28)}, ti.i32)"])

    def _f64_load(self) -> str:
        r = self.r
        if self.ctx == "func":
            return f"af[{self.idx(T)}]"
        return r.choice([f"af[{self.idx(T)}]", f"ndf[{self.idx(T)}]", f"vf[{self.idx(2)}]",
                         f"m[{self.idx(2)}, {self.idx(2)}]", "p.x"])

    def int_leaf(self) -> str:
        r = self.r
        if self.leaf_nest > 1:
            return self._int_simple()
        self.leaf_nest += 1
        try:
            k = r.randrange(10)
            if k <= 3:
                return self._int_simple()
            if k <= 6:
                return self._int_load()
            if k == 7:
                return f"({self._int_load()} if {self.cond(0)} else {self._int_load()})"
            if k == 8 and self.int_funcs:
                return f"{r.choice(self.int_funcs)}({self.int_expr(1)}, {self.f64_expr(1)})"
            return f"ti.select({self.cond(0)}, {self._int_load()}, {self.int_expr(0)})"
        finally:
            self.leaf_nest -= 1

    def f64_leaf(self) -> str:
        r = self.r
        if self.leaf_nest > 1:
            return r.choice(["v" if self.ctx == "func" else f"x{r.randrange(gen.N_F64)}", f"{r.uniform(-3, 3):.3f}"])
        self.leaf_nest += 1
        try:
            k = r.randrange(10)
            if k <= 2:
                if self.ctx == "func":
                    return r.choice(["v", "s"])
                return f"x{r.randrange(gen.N_F64)}"
            if k == 3:
                return f"{r.uniform(-3, 3):.3f}"
            if k <= 5:
                return self._f64_load()
            if k == 6:
                return f"({self._f64_load()} if {self.cond(0)} else {self._f64_load()})"
            if k == 7 and self.f64_funcs:
                return f"{r.choice(self.f64_funcs)}({self.int_expr(1)}, {self.f64_expr(1)})"
            if k == 8 and self.ctx == "kernel":
                return f"p.mix({self._int_simple()})"
            return f"ti.select({self.cond(0)}, {self._f64_load()}, {self.f64_expr(0)})"
        finally:
            self.leaf_nest -= 1

    # -- statements --------------------------------------------------------------------------------
    def stmt(self, ind: str) -> list[str]:
        r = self.r
        d = r.randint(1, 2)
        deep = self.depth >= 3
        k = r.randrange(28)
        if k in (25, 26, 27) and self.ctx == "func":
            k = 0
        if k == 25:  # a vector field: own row at a run-time component, atomic vector adds anywhere
            return [f"{ind}" + r.choice([f"gv[t][{self.idx(3)}] = {self.int_expr(d)}",
                                         f"ga[{self.idx(T)}] += ti.Vector([{self.int_expr(0)}, {self.int_expr(0)}, "
                                         f"{self.int_expr(0)}], dt=ti.i32)",
                                         f"ga[{self.idx(T)}][{self.idx(3)}] += {self.int_expr(1)}",
                                         "gv[t] = gv[t] * 2 + v"])]
        if k == 26:  # unsigned hashing
            s1 = r.randint(1, 31)
            return [f"{ind}" + r.choice([f"h = (h ^ (h >> {r.randint(1, 24)})) * ti.u32({r.randrange(1, 2**32)})",
                                         f"h += ti.cast({self.int_expr(1)}, ti.u32)",
                                         f"h = (h << {s1}) | (h >> {32 - s1})",
                                         f"a{r.randrange(gen.N_INT)} = "
                                         f"ti.cast(h % ti.u32({r.randint(1, 999)}), ti.i32)"])]
        if k <= 1:
            return [f"{ind}{self._int_var()} {r.choice(['=', '+=', '^='])} {self.int_expr(d)}"]
        if k <= 3:
            return [f"{ind}{self._f64_var()} {r.choice(['=', '+='])} {self.f64_expr(d)}"]
        if k == 4 and not deep:
            return self._block(ind, f"if {self.cond(d)}:", r.randint(1, 2), loop=False) + (
                self._block(ind, "else:", 1, loop=False) if r.random() < 0.5 else [])
        if k in (5, 6) and not deep:
            self.counter += 1
            kv = f"k{self.counter}"
            bound = r.choice([str(r.randint(0, 4)), f"{self._int_load()} % 4 + 1", f"{self._int_simple()} % 3",
                              f"1, {r.randint(2, 5)}"])
            return self._block(ind, f"for {kv} in range({bound}):", r.randint(1, 3), loop=True, var=kv)
        if k == 7 and not deep:
            self.counter += 1
            w = f"w{self.counter}"
            head = [f"{ind}{w} = 0"]
            body = self._block(ind, f"while {w} < {r.randint(1, 4)}:", r.randint(1, 3), loop=True, var=w,
                               first=f"{w} += 1")
            return head + body
        if k in (8, 9) and self.loops and not self.no_jump:
            word = r.choice(["break", "continue"])
            return [f"{ind}if {self.cond(1)}:", f"{ind}    {word}"]
        if k == 10 and self.no_jump:
            k = 0
        if k == 10 and self.ctx == "kernel" and self.loops == 0 and r.random() < 0.3:
            return [f"{ind}if {self.cond(1)}:", f"{ind}    continue"]  # continue the parallel loop
        if k == 10 and self.ctx == "func" and (self.loops or self.depth):
            return [f"{ind}if {self.cond(1)}:", f"{ind}    return {self._ret()}"]
        if k == 22 and not deep:  # unrolled: no break/continue/return inside (Taichi refuses them)
            self.counter += 1
            kv = f"k{self.counter}"
            saved, self.no_jump = self.no_jump, True
            body = self._block(ind, f"for {kv} in ti.static(range({r.randint(1, 3)})):", r.randint(1, 2),
                               loop=False, var=kv, last=self._accum)
            self.no_jump = saved
            return body
        if k == 23 and not deep:
            self.counter += 1
            kv, jv = f"k{self.counter}", f"j{self.counter}"
            self.loop_vars.append(jv)
            body = self._block(ind, f"for {kv}, {jv} in ti.ndrange({r.randint(1, 3)}, (1, {r.randint(1, 3)})):",
                               r.randint(1, 2), loop=True, var=kv)
            self.loop_vars.pop()
            return body
        if k == 24 and self.ctx == "kernel":  # a slot from a shared counter (stream compaction)
            self.counter += 1
            sv = f"c{self.counter}"
            return [f"{ind}{sv} = ti.atomic_add(tot[11], 1)  # REF: {sv}, tot[11] = tot[11], tot[11] + 1",
                    f"{ind}if {sv} < {CAP}:", f"{ind}    buf[{sv}] = {self.int_expr(1)}"]
        if k == 11:
            return [self._local_atomic(ind)]
        if k == 12 and self.ctx == "kernel":
            return [self._global_atomic(ind)]
        if self.ctx == "func":
            return [f"{ind}{self._int_var()} = {self.int_expr(d)}"]
        if k == 13:
            return [f"{ind}v[{self.idx(3)}] = {self.int_expr(d)}"]
        if k == 14:
            return [f"{ind}vf[{self.idx(2)}] {r.choice(['=', '+='])} {self.f64_expr(d)}"]
        if k == 15:
            return [f"{ind}m[{self.idx(2)}, {self.idx(2)}] = {self.f64_expr(d)}"]
        if k == 16:
            return [f"{ind}" + r.choice(["vf = m @ vf", f"x{r.randrange(gen.N_F64)} = vf.dot(vf)",
                                         f"v = v + ti.Vector([{self.int_expr(1)}, {self.int_expr(0)}, "
                                         f"{self.int_expr(0)}], dt=ti.i32)",
                                         f"m = m * 0.5 + ti.Matrix([[{self.f64_expr(0)}, {self.f64_expr(0)}], "
                                         f"[{self.f64_expr(0)}, {self.f64_expr(0)}]], dt=ti.f64)"])]
        if k == 17:
            return [f"{ind}p.a = {self.int_expr(d)}" if r.random() < 0.5 else f"{ind}p.x += {self.f64_expr(d)}"]
        if k == 18:
            return [f"{ind}sp[{self.idx(NSP)}] += {self.int_expr(d)}"]  # activates (a cell or a block)
        if k == 19:
            return [f"{ind}if ti.length(dy.parent(), t) < {DYN}:",
                    f"{ind}    ti.append(dy.parent(), t, {self.int_expr(d)})"]
        if k == 20:
            return [f"{ind}ndo[{r.choice(['t % 2', self.idx(2)])}] += {self.int_expr(d)}"]
        return [f"{ind}ndo[2 + t] = {self.int_expr(d)}"]

    def _block(self, ind: str, head: str, n: int, loop: bool, var: str | None = None,
               first: str | None = None, last=None) -> list[str]:
        self.depth += 1
        self.loops += loop
        saved = self.no_jump
        if loop:
            self.no_jump = False
        if var is not None and var.startswith("k"):
            self.loop_vars.append(var)
        body = self.stmts(n, ind + "    ")
        if loop:  # what break/continue skip must matter: a guard somewhere, an accumulation after it
            if self.r.random() < 0.7:
                word = self.r.choice(["break", "continue"])
                _at_boundary(self.r, body, ind + "    ", [f"if {self._guard(var)}:", f"    {word}"])
            body.append(f"{ind}    {self._accum(var)}")
        if last is not None:
            body.append(f"{ind}    {last(var)}")
        body = ([f"{ind}    {first}"] if first else []) + body
        self.no_jump = saved
        if var is not None and var.startswith("k"):
            self.loop_vars.pop()
        self.loops -= loop
        self.depth -= 1
        return [f"{ind}{head}", *body]

    def _guard(self, var: str | None) -> str:
        """A condition that changes over the loop's iterations (so break, continue and return differ)."""
        r = self.r
        if var is None or r.random() < 0.3:
            return self.cond(1)
        if r.random() < 0.5:
            return f"{var} {r.choice(['>=', '==', '>'])} {r.randint(1, 3)}"
        return f"({var} + {self._int_simple()}) % {r.randint(2, 3)} == 0"

    def _accum(self, var: str | None) -> str:
        """`a += ...` / `x += ...` using the loop variable: each iteration leaves a trace."""
        lv = var if var is not None else "1"
        if self.r.random() < 0.6:
            return f"{self._int_var()} += {lv} * {self.r.randint(2, 9)} + {self.int_expr(1)}"
        return f"{self._f64_var()} += ti.cast({lv}, ti.f64) * {self.r.uniform(0.1, 2):.2f} + {self.f64_expr(1)}"

    def _int_var(self) -> str:
        return "r" if self.ctx == "func" else f"a{self.r.randrange(gen.N_INT)}"

    def _f64_var(self) -> str:
        return "s" if self.ctx == "func" else f"x{self.r.randrange(gen.N_F64)}"

    def _ret(self) -> str:
        return self.int_expr(1) if self.ret_type == "i32" else self.f64_expr(1)

    def _local_atomic(self, ind: str) -> str:
        """ti.atomic_<op>(local, e) updates the local and returns its old value; the reference spells it out."""
        r = self.r
        if r.random() < 0.7:
            op = r.choice(ATOMIC_INT)
            place, e = self._int_var(), self.int_expr(1)
            other = "r" if self.ctx == "func" else f"a{r.randrange(gen.N_INT)}"
        else:
            op = r.choice(ATOMIC_F64)
            place, e = self._f64_var(), self.f64_expr(1)
            other = "s" if self.ctx == "func" else f"x{r.randrange(gen.N_F64)}"
        if other != place and r.random() < 0.5:
            return (f"{ind}{other} = ti.atomic_{op}({place}, {e})"
                    f"  # REF: {other}, {place} = {place}, ti.op_('{op}', {place}, {e})")
        return f"{ind}ti.atomic_{op}({place}, {e})  # REF: {place} = ti.op_('{op}', {place}, {e})"

    def _global_atomic(self, ind: str) -> str:
        """Atomics into fields from the parallel loop: one kind per cell, so the result has no order."""
        r = self.r
        k = r.randrange(len(ATOMIC_INT) + 2)
        if k < len(ATOMIC_INT):
            op = ATOMIC_INT[k]
            e = self.int_expr(1)
            return f"{ind}ti.atomic_{op}(tot[{k}], {e})  # REF: tot[{k}] = ti.op_('{op}', tot[{k}], {e})"
        if k == len(ATOMIC_INT):
            return f"{ind}tot[7] += {self.int_expr(1)}"
        j = r.randrange(len(ATOMIC_F64))
        op, e = ATOMIC_F64[j], self.f64_expr(1)
        if op == "add" and r.random() < 0.5:
            return f"{ind}totf[0] += {e}"
        return f"{ind}ti.atomic_{op}(totf[{j}], {e})  # REF: totf[{j}] = ti.op_('{op}', totf[{j}], {e})"

    # -- functions ---------------------------------------------------------------------------------
    def func(self, name: str, ret: str, real: bool) -> list[str]:
        """A ti.func / ti.real_func (u: i32, v: f64) -> ret whose body returns from loops and branches."""
        self.ctx, self.ret_type = "func", ret
        head = (["    @ti.real_func", f"    def {name}(u: ti.i32, v: ti.f64) -> ti.{ret}:"] if real else
                ["    @ti.func", f"    def {name}(u, v) -> ti.{ret}:"])
        body = ["        r = u", "        s = v"]
        self.depth = 1
        self.counter += 1
        kv = f"k{self.counter}"
        bound = self.r.choice(["3", "u % 4 + 1", f"{self.r.randint(0, 5)}"])
        self.loops, self.loop_vars = 1, [kv]
        self.depth = 2
        inner = self.stmts(max(1, self.size // 2), "            ")
        # an early return at a statement boundary of the loop body (not between an if and its else)
        guard = self.cond(1) if self.r.random() < 0.5 else f"({kv} + {self.r.choice(['u', 'r'])}) % 3 == 0"
        _at_boundary(self.r, inner, " " * 12, [f"if {guard}:", f"    return {self._ret()}"])
        inner.append(f"            {self._accum(kv)}")
        self.loops, self.loop_vars, self.depth = 0, [], 1
        body += [f"        for {kv} in range({bound}):", *inner]
        body += self.stmts(self.r.randint(0, 2), "        ")
        body += [f"        return {self._ret()}", ""]
        self.ctx, self.depth = "kernel", 0
        return head + body


def _at_boundary(r: random.Random, lines: list[str], ind: str, new: list[str]) -> None:
    """Insert `new` (lines relative to `ind`) between two statements of the block indented by `ind`
    (never between an `if` and its `else`)."""
    n = len(ind)
    cut = [j for j in range(len(lines) + 1)
           if j == len(lines) or (lines[j].startswith(ind) and lines[j][n] != " " and lines[j].strip() != "else:")]
    j = r.choice(cut)
    lines[j:j] = [ind + x for x in new]


DATACLASS = """@ti.dataclass
class P:
    a: ti.i32
    x: ti.f64

    @ti.func
    def mix(self, k):
        return self.x * 0.5 + ti.cast(self.a % 7 + k, ti.f64)

"""

NDARRAYS = ("nd: ti.types.ndarray(dtype=ti.i32, ndim=1), ndf: ti.types.ndarray(dtype=ti.f64, ndim=1), "
            "ndo: ti.types.ndarray(dtype=ti.i32, ndim=1)")

GATHER = """
    @ti.kernel
    def gather():
        for i in sp:
            og[i] = sp[i] + 1
            tot[8] += sp[i] * (i + 1)
        for t, j in dy:
            tot[9] += dy[t, j] ^ (j + 1)
        for t in range(T):
            oi[t, 7] = ti.length(dy.parent(), t)

    return main, gather
"""


def forward_case(seed: int, size: int, all_real: bool = False) -> tuple[str, str]:
    """(module text for simgrad, the same for the reference with its `# REF:` lines) of one program.
    `all_real`: every function a ti.real_func (Taichi 1.7 refuses a ti.func that returns inside a loop or
    branch; taichi_check.py)."""
    r = random.Random(seed ^ 0x5EED)
    g = _Shapes(r, size)
    funcs: list[str] = []
    for j in range(r.randint(1, 3)):
        ret = r.choice(["i32", "f64"])
        real = (ret == "f64" and r.random() < 0.5) or all_real
        name = f"{'rf' if real else 'f'}{j}"
        funcs += g.func(name, ret, real)
        (g.int_funcs if ret == "i32" else g.f64_funcs).append(name)
    ind = " " * 12
    body = [f"{ind}a{k} = ai[(t + {k}) % {T}]" for k in range(gen.N_INT)]
    body += [f"{ind}x{k} = af[(t + {k}) % {T}]" for k in range(gen.N_F64)]
    body += [f"{ind}v = ti.Vector([a0, nd[t], t], dt=ti.i32)", f"{ind}vf = ti.Vector([x0, ndf[t]], dt=ti.f64)",
             f"{ind}m = ti.Matrix([[x1, 0.5], [-0.25, x2]], dt=ti.f64)", f"{ind}p = P(a=a2, x=x0)",
             f"{ind}h = ti.cast(a1, ti.u32)"]
    body += g.stmts(size, ind)
    for name in g.int_funcs:  # every function's result is seen
        body.append(f"{ind}tot[10] += {name}({g.int_expr(1)}, {g.f64_expr(1)})")
    for name in g.f64_funcs:
        body.append(f"{ind}totf[0] += {name}({g.int_expr(1)}, {g.f64_expr(1)})")
    body += [f"{ind}oi[t, {k}] = a{k}" for k in range(gen.N_INT)]
    body += [f"{ind}oi[t, {3 + k}] = v[{k}]" for k in range(3)] + [f"{ind}oi[t, 6] = p.a"]
    body += [f"{ind}of[t, {k}] = x{k}" for k in range(gen.N_F64)]
    body += [f"{ind}of[t, 3] = vf[0]", f"{ind}of[t, 4] = vf[1]", f"{ind}of[t, 5] = m[0, 0]",
             f"{ind}of[t, 6] = m[0, 1]", f"{ind}of[t, 7] = m[1, 0]", f"{ind}of[t, 8] = m[1, 1]",
             f"{ind}of[t, 9] = p.x", f"{ind}ps[t].a = p.a", f"{ind}ps[t].x = p.x", f"{ind}ou[t] = h"]
    text = (f"T = {T}\n\n\n" + DATACLASS + "\ndef make(ai, af, oi, of, tot, totf, sp, dy, og, ps, buf, gv, ga, ou):\n"
            + "\n".join(funcs) + "\n    @ti.kernel\n" + f"    def main({NDARRAYS}):\n        for t in range(T):\n"
            + "\n".join(body) + "\n" + GATHER)
    return text, reference_source(text)


def reference_source(text: str) -> str:
    """Each line with a `# REF: code` comment becomes `code` at the same indentation."""
    out = []
    for line in text.splitlines():
        if "  # REF: " in line:
            code, ref = line.split("  # REF: ", 1)
            line = code[: len(code) - len(code.lstrip())] + ref
        out.append(line)
    return "\n".join(out) + "\n"


# -- the reference: what `ti` means when the program runs as Python ------------------------------------
class _SparseRef:
    """A sparse field: writes activate the cell's block (a cell for bitmasked leaves, 4 cells for a pointer
    over dense); a struct-for visits the cells of active blocks in order; inactive cells read 0."""

    def __init__(self, block: int):
        self.block, self.vals, self.active = block, np.zeros(NSP, np.int32), set()

    def __getitem__(self, i):
        return self.vals[i]

    def __setitem__(self, i, v):
        self.active.add(int(i) // self.block)
        self.vals[i] = v

    def __iter__(self):
        for b in sorted(self.active):
            yield from range(b * self.block, (b + 1) * self.block)


class _DynRef:
    def __init__(self):
        self.lists: list[list] = [[] for _ in range(T)]

    def parent(self):
        return self

    def __getitem__(self, ij):
        return self.lists[ij[0]][ij[1]]

    def __iter__(self):
        for t in range(T):
            for j in range(len(self.lists[t])):
                yield t, j


class _Types:
    @staticmethod
    def ndarray(**kw):
        return None


def _typed(fn):
    """A ti.func as Python: arguments annotated with a type are cast to it, and so is the result."""
    ann = dict(fn.__annotations__)
    rt = ann.pop("return", None)
    names = fn.__code__.co_varnames[: fn.__code__.co_argcount]

    def call(*args):
        args = tuple(ann[n](a) if n in ann else a for n, a in zip(names, args))
        out = fn(*args)
        return rt(out) if rt is not None else out

    return call


class Ref(gen.RefNamespace):
    """`ti` for the reference run (gen.RefNamespace's scalar semantics plus the program-level constructs)."""

    types = _Types
    u32 = np.uint32

    @staticmethod
    def cast(v, t):
        """gen's casts, and integer -> integer keeping the low bits (C's conversion, as LLVM's trunc/zext)."""
        if isinstance(v, (int, np.integer)) and t in (np.int32, np.uint32):
            return np.array(v).astype(t)[()]
        return gen.RefNamespace.cast(v, t)
    func = staticmethod(_typed)
    real_func = staticmethod(_typed)

    @staticmethod
    def kernel(fn):
        return fn

    @staticmethod
    def static(v):
        return v

    @staticmethod
    def ndrange(*dims):
        import itertools

        return itertools.product(*(range(*d) if isinstance(d, tuple) else range(d) for d in dims))

    @staticmethod
    def Vector(xs, dt):
        return np.array([dt(x) for x in xs], dtype=dt)

    @staticmethod
    def Matrix(rows, dt):
        return np.array([[dt(x) for x in row] for row in rows], dtype=dt)

    @staticmethod
    def dataclass(cls):
        members = dict(cls.__annotations__)

        def init(self, **kw):
            for name, tp in members.items():
                setattr(self, name, tp(kw.get(name, 0)))

        def setattr_typed(self, name, value):
            object.__setattr__(self, name, members[name](value) if name in members else value)

        cls.__init__ = init
        cls.__setattr__ = setattr_typed
        cls.field = classmethod(lambda c, shape: [c() for _ in range(shape)])
        return cls

    @staticmethod
    def op_(kind, a, b):
        """The new value of an atomic `kind` (and the meaning of a mutant's swapped kind)."""
        if kind == "add":
            return a + b
        if kind == "sub":
            return a - b
        if kind == "min":
            return gen.RefNamespace.min(a, b)
        if kind == "max":
            return gen.RefNamespace.max(a, b)
        if kind == "and":
            return np.int32(a) & np.int32(b)
        if kind == "or":
            return np.int32(a) | np.int32(b)
        if kind == "xor":
            return np.int32(a) ^ np.int32(b)
        raise ValueError(kind)

    @staticmethod
    def append(node, t, v):
        node.lists[t].append(np.int32(v))

    @staticmethod
    def length(node, t):
        return np.int32(len(node.lists[t]))


# -- mutants: bugs planted in the reference, each must be caught ------------------------------------
MUTANTS = {
    "break_to_continue": lambda s: re.sub(r"^(\s+)break$", r"\1continue", s, flags=re.M),
    "loop_bound_off_by_one": lambda s: re.sub(r"for (k\d+) in range\((\d+)\):", r"for \1 in range(\2 + 1):", s),
    "atomic_max_as_min": lambda s: s.replace("ti.op_('max'", "ti.op_('min'"),
    "atomic_add_as_sub": lambda s: s.replace("ti.op_('add'", "ti.op_('sub'"),
    "static_loop_off_by_one": lambda s: re.sub(r"ti\.static\(range\((\d+)\)\)", r"ti.static(range(\1 + 1))", s),
    "ndrange_lower_bound_0": lambda s: re.sub(r"ti\.ndrange\((\d+), \(1, ", r"ti.ndrange(\1, (0, ", s),
    "select_negated": lambda s: s.replace("ti.select(", "ti.select(not "),
    "struct_for_visits_inactive": lambda s: s.replace("for i in sp:", f"for i in range({NSP}):"),
    "early_return_ignored": lambda s: re.sub(r"^( {12,})return .*$", r"\1pass", s, flags=re.M),
    "atomic_returns_new": lambda s: re.sub(r"(\w+), (\w+) = \2, (ti\.op_\([^\n]*)$", r"\1 = \2 = \3", s, flags=re.M),
}


def _layout(ti, sp, layout: str) -> None:
    if layout == "bitmasked":
        ti.root.bitmasked(ti.i, NSP).place(sp)
    elif layout == "pointer_dense":
        ti.root.pointer(ti.i, NSP // 4).dense(ti.i, 4).place(sp)
    else:
        ti.root.pointer(ti.i, NSP // 4).bitmasked(ti.i, 4).place(sp)


def _exec(path, name: str, text: str, ti):
    import importlib.util

    file = path / f"{name}.py"
    file.write_text(text)
    spec = importlib.util.spec_from_file_location(name, file)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    mod.ti = ti  # type: ignore[attr-defined]
    spec.loader.exec_module(mod)
    return mod


def layout_of(seed: int) -> str:
    return LAYOUTS[seed % len(LAYOUTS)]


def reference_outputs(ref_text: str, seed: int, path, name: str) -> dict:
    """Run the program as Python with `Ref` as ti; the outputs as numpy arrays."""
    import warnings

    ai, af = gen.inputs(seed)
    nd, ndf = _nd_inputs(seed)
    o = {"oi": np.zeros((T, N_OI), np.int32), "of": np.zeros((T, N_OF)), "tot": TOT_INIT.copy(),
         "totf": TOTF_INIT.copy(), "og": np.zeros(NSP, np.int32), "ndo": np.zeros(2 + T, np.int32),
         "buf": np.zeros(CAP, np.int32), "gv": np.zeros((T, 3), np.int32), "ga": np.zeros((T, 3), np.int32),
         "ou": np.zeros(T, np.uint32)}
    block = 4 if layout_of(seed) == "pointer_dense" else 1
    sp, dy = _SparseRef(block), _DynRef()
    mod = _exec(path, name, ref_text, Ref)
    ps = mod.P.field(shape=T)
    main, gather = mod.make(ai, af, o["oi"], o["of"], o["tot"], o["totf"], sp, dy, o["og"], ps, o["buf"],
                            o["gv"], o["ga"], o["ou"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # wrap-around and inf are part of the semantics
        main(nd.copy(), ndf.copy(), o["ndo"])
        gather()
    o["ps_a"] = np.array([q.a for q in ps], np.int32)
    o["ps_x"] = np.array([q.x for q in ps])
    return o


def _nd_inputs(seed: int):
    rng = np.random.default_rng(seed + 1)
    return rng.integers(-40, 40, size=T).astype(np.int32), rng.uniform(-2, 2, size=T)


def simgrad_outputs(text: str, seed: int, path, name: str, ti=None) -> dict:
    """The outputs of the program compiled by simgrad (or by `ti`, real Taichi in taichi_check.py)."""
    if ti is None:
        import simgrad as ti

    ai, af = gen.inputs(seed)
    nd_np, ndf_np = _nd_inputs(seed)
    ti.init(arch=ti.cpu, default_fp=ti.f64, default_ip=ti.i32)
    f = {"ai": ti.field(ti.i32, T), "af": ti.field(ti.f64, T), "oi": ti.field(ti.i32, (T, N_OI)),
         "of": ti.field(ti.f64, (T, N_OF)), "tot": ti.field(ti.i32, len(TOT_INIT)),
         "totf": ti.field(ti.f64, len(TOTF_INIT)), "og": ti.field(ti.i32, NSP), "buf": ti.field(ti.i32, CAP),
         "gv": ti.Vector.field(3, ti.i32, T), "ga": ti.Vector.field(3, ti.i32, T), "ou": ti.field(ti.u32, T)}
    f["ai"].from_numpy(ai)
    f["af"].from_numpy(af)
    f["tot"].from_numpy(TOT_INIT)
    f["totf"].from_numpy(TOTF_INIT)
    sp, dy = ti.field(ti.i32), ti.field(ti.i32)
    _layout(ti, sp, layout_of(seed))
    ti.root.dense(ti.i, T).dynamic(ti.j, DYN, chunk_size=4).place(dy)
    nd, ndf, ndo = ti.ndarray(ti.i32, T), ti.ndarray(ti.f64, T), ti.ndarray(ti.i32, 2 + T)
    nd.from_numpy(nd_np)
    ndf.from_numpy(ndf_np)
    ndo.from_numpy(np.zeros(2 + T, np.int32))
    mod = _exec(path, name, text, ti)
    ps = mod.P.field(shape=T)
    main, gather = mod.make(f["ai"], f["af"], f["oi"], f["of"], f["tot"], f["totf"], sp, dy, f["og"], ps,
                            f["buf"], f["gv"], f["ga"], f["ou"])
    main(nd, ndf, ndo)
    gather()
    out = {k: f[k].to_numpy() for k in ("oi", "of", "tot", "totf", "og", "buf", "gv", "ga", "ou")}
    out["ndo"] = ndo.to_numpy()
    out["ps_a"] = ps.a.to_numpy()
    out["ps_x"] = ps.x.to_numpy()
    return out


def compare(got: dict, want: dict) -> None:
    for k in ("oi", "tot", "og", "ndo", "ps_a", "gv", "ga", "ou"):
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    if want["tot"][11] <= CAP:  # slots are handed out in any order: the same values, in some order
        np.testing.assert_array_equal(np.sort(got["buf"]), np.sort(want["buf"]), err_msg="buf (sorted)")
    for k in ("of", "totf", "ps_x"):
        np.testing.assert_allclose(got[k], want[k], rtol=1e-6, atol=1e-9, equal_nan=True, err_msg=k)


def run_forward(seed: int, size: int, path, mutant: str | None = None) -> None:
    """Compile and run one program under simgrad and as Python; AssertionError (with the program) if they
    differ. `mutant` plants that bug in the reference (the mutation check)."""
    text, ref_text = forward_case(seed, size)
    if mutant is not None:
        ref_text = MUTANTS[mutant](ref_text)
    got = simgrad_outputs(text, seed, path, f"shapes_k{seed}_{size}")
    want = reference_outputs(ref_text, seed, path, f"shapes_r{seed}_{size}{'_' + mutant if mutant else ''}")
    try:
        compare(got, want)
    except AssertionError as e:
        ai, af = gen.inputs(seed)
        nd, ndf = _nd_inputs(seed)
        raise AssertionError(f"seed={seed} size={size} layout={layout_of(seed)}\ninputs ai={ai.tolist()} "
                             f"af={af.tolist()} nd={nd.tolist()} ndf={ndf.tolist()}\n{text}\n{e}") from None


# -- gradient programs ------------------------------------------------------------------------------
GRAD_HEAD = """import simgrad as ti


@ti.dataclass
class Q:
    w: ti.f64
    z: ti.f64


def make(x, y, loss, n):
"""


class _GradShapes:
    """f64 statements of real shapes whose control flow depends on integers only (loop variables, i), so
    the program is smooth in x and finite differences can judge its gradient."""

    def __init__(self, r: random.Random):
        self.r = r
        self.counter = 0
        self.funcs: list[str] = []
        self.loop_vars: list[str] = []

    def sm(self, d: int = 1, extra: tuple[str, ...] = ()) -> str:
        return gen._smooth(self.r, d, ["p", "q", "acc", "st.w", "vec[1]", *extra])

    def ivar(self) -> str:
        return self.r.choice(["i", *self.loop_vars])

    def func(self, name: str, real: bool) -> list[str]:
        r = self.r
        head = (["    @ti.real_func", f"    def {name}(u: ti.f64, c: ti.i32) -> ti.f64:"] if real else
                ["    @ti.func", f"    def {name}(u, c) -> ti.f64:"])
        body = ["        s = u"]
        loop = [f"            s = s * 0.5 + {gen._smooth(r, 1, ['s', 'u'])}",
                f"            if (k + c) % {r.randint(2, 4)} == {r.randint(0, 1)}:",
                f"                return s * {r.uniform(-1, 1):.2f} + {gen._smooth(r, 1, ['u', 's'])}"]
        if r.random() < 0.5:
            loop += [f"            if k + c > {r.randint(2, 5)}:", "                break"]
        loop.append(f"            s += {gen._smooth(r, 1, ['s', 'u'])} * 0.25")
        r.shuffle(loop[1:])  # the guards land anywhere after the first update
        loop = _regroup(loop)
        body += [f"        for k in range({r.randint(1, 4)}):", *loop, f"        return s + {r.uniform(-1, 1):.2f}", ""]
        return head + body

    def stmts(self, n: int, ind: str, depth: int = 0) -> list[str]:
        out: list[str] = []
        for _ in range(n):
            out += self.stmt(ind, depth)
        return out

    def stmt(self, ind: str, depth: int) -> list[str]:
        r = self.r
        k = r.randrange(15)
        if k == 13:
            self.counter += 1
            kv = f"k{self.counter}"
            return [f"{ind}for {kv} in ti.static(range({r.randint(1, 3)})):",
                    f"{ind}    vec[{kv}] = vec[{kv}] * 0.5 + {self.sm(1)}", f"{ind}    acc += vec[{kv}] * 0.3"]
        if k == 14:
            self.counter += 1
            kv, jv = f"k{self.counter}", f"j{self.counter}"
            return [f"{ind}for {kv}, {jv} in ti.ndrange(2, ({r.randint(0, 1)}, 2)):",
                    f"{ind}    if ({kv} + {jv} + i) % 3 == {r.randint(0, 2)}:", f"{ind}        continue",
                    f"{ind}    acc = acc * 0.5 + mat[{kv}, {jv}] * {self.sm(1)}"]
        if k == 0 or (k <= 2 and depth >= 2):
            return [f"{ind}acc = acc * 0.5 + {self.sm(2)}"]
        if k in (1, 2):  # nested loops with integer break/continue
            self.counter += 1
            kv = f"k{self.counter}"
            self.loop_vars.append(kv)
            body = self.stmts(r.randint(1, 2), ind + "    ", depth + 1)
            guard = f"if ({kv} + {self.ivar()}) % {r.randint(2, 3)} == {r.randint(0, 1)}:"
            word = r.choice(["break", "continue"])
            _at_boundary(r, body, ind + "    ", [guard, f"    {word}"])
            body.append(f"{ind}    acc = acc * 0.5 + {self.sm(1)} * ti.cast({kv}, ti.f64)")
            self.loop_vars.pop()
            if r.random() < 0.5:
                return [f"{ind}for {kv} in range({r.randint(1, 3)}):", *body]
            return [f"{ind}{kv} = 0", f"{ind}while {kv} < {r.randint(1, 3)}:", f"{ind}    {kv} += 1", *body]
        if k == 3:
            return [f"{ind}vec[({self.ivar()} + {r.randint(0, 2)}) % 3] = {self.sm(1)}",
                    f"{ind}acc += vec[({self.ivar()} + {r.randint(0, 2)}) % 3] * {r.uniform(-1, 1):.2f}"]
        if k == 4:
            return [f"{ind}mat[{self.ivar()} % 2, ({self.ivar()} + 1) % 2] += {self.sm(1)}",
                    f"{ind}acc += (mat @ ti.Vector([p, q])).dot(ti.Vector([q, 0.5])) * 0.25"]
        if k == 5:
            return [f"{ind}st.w = {self.sm(1, ('st.z',))}", f"{ind}acc += st.z * st.w * 0.5"]
        if k == 6 and self.funcs:
            return [f"{ind}acc += {r.choice(self.funcs)}({self.sm(1)}, {self.ivar()} + {r.randint(0, 3)})"]
        if k == 7:
            return [f"{ind}y[n + ({self.ivar()} + {r.randint(0, 2)}) % n] += {self.sm(1)}"]
        if k == 8:
            return [f"{ind}ti.atomic_add(y[n + ({self.ivar()} + {r.randint(0, 2)}) % n], {self.sm(1)})"]
        if k == 9:
            return [f"{ind}ti.atomic_add(acc, {self.sm(1)})"]
        if k == 10:
            j = f"({self.ivar()} + {r.randint(0, 2)}) % n"
            return [f"{ind}acc += ti.select(x[{j}] > {r.uniform(-1, 1):.2f}, x[{j}] * p, {self.sm(1)})"]
        if k == 11:
            j = f"({self.ivar()} + {r.randint(0, 2)}) % n"
            return [f"{ind}acc += x[{j}] * q if x[{j}] < p else {self.sm(1)} * 0.5"]
        return [f"{ind}acc += {self.sm(2)}"]


def _regroup(lines: list[str]) -> list[str]:
    """Keep each `if ...:` followed by its body line after a shuffle of (header, body) pairs."""
    heads = [k for k, s in enumerate(lines) if s.rstrip().endswith(":")]
    pairs, k = [], 0
    while k < len(lines):
        if k in heads:
            pairs.append(lines[k:k + 2])
            k += 2
        elif lines[k].startswith(" " * 16):  # a body separated from its header by the shuffle
            k += 1
        else:
            pairs.append([lines[k]])
            k += 1
    return [s for p in pairs for s in p]


def gradient_case(seed: int, size: int) -> str:
    """Two f64 kernels on a Tape (the make(x, y, loss, n) of gen.run_gradient; y has 2n cells)."""
    r = random.Random(seed ^ 0x6AD)
    g = _GradShapes(r)
    lines: list[str] = []
    for j in range(r.randint(1, 2)):
        real = r.random() < 0.3
        name = f"{'rh' if real else 'h'}{j}"
        lines += g.func(name, real)
        g.funcs.append(name)
    ind = " " * 12
    lines += ["    @ti.kernel", "    def first():", "        for i in range(n):", f"{ind}p = x[i]",
              f"{ind}q = x[(i + 1) % n]", f"{ind}acc = 0.0", f"{ind}vec = ti.Vector([p, q, p * q])",
              f"{ind}mat = ti.Matrix([[p, q], [q * 0.5, 1.0]])", f"{ind}st = Q(w=p, z=q)"]
    lines += g.stmts(size, ind)
    lines += [f"{ind}y[i] = acc + vec[2] * {r.uniform(-1, 1):.2f} + st.w * {r.uniform(-1, 1):.2f} + mat[1, 0]", "",
              "    @ti.kernel", "    def second():", "        for i in range(n):",
              f"            loss[None] += {gen._smooth(r, 2, ['y[i]', 'x[i]'])} + {gen._smooth(r, 1, ['y[n + i]'])}",
              "", "    return first, second"]
    return GRAD_HEAD + "\n".join(lines) + "\n"


def run_gradient(seed: int, size: int, path) -> None:
    gen.run_gradient(seed, size, path, case=gradient_case)


def run_forward_mode(seed: int, size: int, path) -> None:
    gen.run_forward_mode(seed, size, path, case=gradient_case)
