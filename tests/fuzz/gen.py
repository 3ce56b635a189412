"""Random kernels for differential fuzzing: one program text, run twice.

A generated program is a list of statement lines over typed locals (i32 `a*`, f64 `x*`, f32 `s*`) inside
`for t in range(T)`. The same lines are compiled by simgrad as a kernel and executed by Python as the
reference, with numpy scalars carrying the types (np.int32 wraps like the machine, np.float32 rounds
like it; `//` and `%` are Python's in both) and a small `ref` namespace standing in for `ti`. Only
constructs whose meaning is the same in both are generated: comparisons only as conditions, divisors
that cannot be zero, float->int casts of bounded values, math on arguments inside its domain.

`forward_case` returns (kernel source, reference source); `gradient_case` a differentiable f64 program
whose Tape gradient is compared with central finite differences of the kernel itself.
"""

from __future__ import annotations

import random

import numpy as np

from simgrad import dtypes as dt
from simgrad.ir.ops import OPS, Op

T = 4  # iterations of the outer (parallel) loop
N_INT, N_F64, N_F32 = 3, 3, 2


# the registry's math functions (ir/opdefs.py), every one generated: a new entry needs nothing here
MATH = [d for d in OPS.values() if d.export]
# how kernels (and the reference, on numpy scalars) write the registry's other ops, operands kept where both
# agree (divisors in [8, 14], shift amounts in [0, 3] so literal-only chains stay in i32, a positive
# base); comparisons are written by cond()
SPELLING = {
    Op.ADD: "({a} + {b})", Op.SUB: "({a} - {b})", Op.MUL: "({a} * {b})", Op.DIV: "({a} / ({b} * {b} + 1.0))",
    Op.FLOORDIV: "({a} // ({b} % 7 + 8))", Op.MOD: "({a} % ({b} % 7 + 8))",
    Op.RAW_DIV: "ti.raw_div({a}, {b} % 7 + 8)", Op.RAW_MOD: "ti.raw_mod({a}, {b} % 7 + 8)",
    Op.POW: "((abs({a}) + 0.5) ** ti.tanh({b}))", Op.MIN: "ti.min({a}, {b})", Op.MAX: "ti.max({a}, {b})",
    Op.BIT_AND: "({a} & {b})", Op.BIT_OR: "({a} | {b})", Op.BIT_XOR: "({a} ^ {b})",
    Op.SHL: "({a} << ({b} & 3))", Op.SHR: "({a} >> ({b} & 3))", Op.NEG: "(-{a})", Op.BIT_NOT: "(~{a})",
    Op.LOGICAL_NOT: "ti.cast(not {a}, ti.i32)", Op.ABS: "abs({a})", Op.FLOOR: "ti.floor({a})",
    Op.CEIL: "ti.ceil({a})", Op.ROUND: "ti.round({a})",
}
COMPARISON = {Op.LT: "<", Op.LE: "<=", Op.GT: ">", Op.GE: ">=", Op.EQ: "==", Op.NE: "!="}
# the registry's ops on i32 and on f64 that expressions draw from (math functions by name, the rest as spelled)
INT_OPS = [op for op, d in OPS.items() if op in SPELLING and d.accepts(dt.i32)]
FLOAT_OPS = [op for op, d in OPS.items() if (op in SPELLING or d.export) and d.accepts(dt.f64) and d.result == "same"]


def op_expr(op: Op, a: str, b: str) -> str:
    """The registry op `op` written on the operand texts a, b."""
    d = OPS[op]
    return math_call(d, [a, b]) if d.export else SPELLING[op].format(a=a, b=b)


def math_call(d, args: list[str]) -> str:
    """A call of the math function `d` on `args`, each mapped into the entry's sample range (where it is
    defined and smooth) by a tanh, so any value may come in."""
    inner = [f"({(lo + hi) / 2!r} + {(hi - lo) / 2!r} * ti.tanh({a}))" for (lo, hi), a in zip(d.sample, args)]
    return f"{'ti' if 'ti' in d.export else 'ti.math'}.{d.name}({', '.join(inner)})"


class _Gen:
    def __init__(self, rng: random.Random, size: int):
        self.r = rng
        self.size = size
        self.loop_depth = 0
        self.counter = 0

    # -- expressions ---------------------------------------------------------------------------
    def int_leaf(self) -> str:
        """An i32 operand (tests/fuzz/shapes.py overrides the leaves and keeps the operators)."""
        r = self.r
        return r.choice([f"a{r.randrange(N_INT)}", str(r.randint(-9, 9)), "t", f"ai[{r.randrange(T)}]"])

    def f64_leaf(self) -> str:
        r = self.r
        return r.choice([f"x{r.randrange(N_F64)}", f"{r.uniform(-3, 3):.3f}", f"af[{r.randrange(T)}]",
                         "ti.cast(t, ti.f64)"])

    def int_expr(self, d: int) -> str:
        r = self.r
        if d <= 0 or r.random() < 0.25:
            return self.int_leaf()
        k = r.randrange(12)
        a, b = self.int_expr(d - 1), self.int_expr(d - 1)
        if k == 11:
            return op_expr(r.choice(INT_OPS), a, b)
        if k == 0:
            return f"({a} + {b})"
        if k == 1:
            return f"({a} - {b})"
        if k == 2:
            return f"({a} * {b})"
        if k == 3:
            return f"({a} // ({b} % 7 + 8))"  # divisor in [8, 14]
        if k == 4:
            return f"({a} % ({b} % 5 + 6))"
        if k == 5:
            return f"ti.min({a}, {b})"
        if k == 6:
            return f"ti.max({a}, {b})"
        if k == 7:
            return f"ti.select({self.cond(d - 1)}, {a}, {b})"
        if k == 8:
            return f"({a} ^ {b})" if r.random() < 0.5 else f"({a} & {b})"
        if k == 9:
            return f"ti.cast(ti.sin({self.f64_expr(d - 1)}) * 100.0, ti.i32)"
        return f"abs({a})"

    def f64_expr(self, d: int) -> str:
        r = self.r
        if d <= 0 or r.random() < 0.25:
            return self.f64_leaf()
        k = r.randrange(13)
        a, b = self.f64_expr(d - 1), self.f64_expr(d - 1)
        if k == 12:
            return op_expr(r.choice(FLOAT_OPS), a, b)
        if k == 0:
            return f"({a} + {b})"
        if k == 1:
            return f"({a} - {b})"
        if k == 2:
            return f"({a} * {b})"
        if k == 3:
            return f"({a} / ({b} * {b} + 1.0))"
        if k == 4:
            return f"ti.sin({a})"
        if k == 5:
            return f"ti.cos({a})"
        if k == 6:
            return f"ti.exp(ti.sin({a}))"
        if k == 7:
            return f"ti.sqrt({a} * {a} + 0.5)"
        if k == 8:
            return f"ti.tanh({a})"
        if k == 9:
            return f"ti.select({self.cond(d - 1)}, {a}, {b})"
        if k == 10:
            return f"ti.cast({self.int_expr(d - 1)}, ti.f64)"
        return f"ti.min({a}, {b})" if r.random() < 0.5 else f"ti.floor({a})"

    def f32_expr(self, d: int) -> str:
        """f32 values: + - * and casts only (libm and LLVM may round transcendental functions differently)."""
        r = self.r
        if d <= 0 or r.random() < 0.3:
            return r.choice([f"s{r.randrange(N_F32)}", f"ti.cast({self.f64_expr(0)}, ti.f32)"])
        a, b = self.f32_expr(d - 1), self.f32_expr(d - 1)
        return r.choice([f"({a} + {b})", f"({a} - {b})", f"({a} * {b})", f"ti.max({a}, {b})"])

    def cond(self, d: int) -> str:
        r = self.r
        op = r.choice([COMPARISON[op] for op in OPS if op in COMPARISON])
        if r.random() < 0.5:
            return f"{self.int_expr(d)} {op} {self.int_expr(d)}"
        return f"{self.f64_expr(d)} {op.replace('==', '<').replace('!=', '>')} {self.f64_expr(d)}"

    # -- statements --------------------------------------------------------------------------
    def stmts(self, n: int, ind: str) -> list[str]:
        out: list[str] = []
        for _ in range(n):
            out += self.stmt(ind)
        return out

    def stmt(self, ind: str) -> list[str]:
        r = self.r
        d = r.randint(1, 3)
        k = r.randrange(10)
        if k <= 2:
            return [f"{ind}a{r.randrange(N_INT)} = {self.int_expr(d)}"]
        if k <= 4:
            return [f"{ind}x{r.randrange(N_F64)} = {self.f64_expr(d)}"]
        if k == 5:
            return [f"{ind}s{r.randrange(N_F32)} = {self.f32_expr(d)}"]
        if k == 6:
            return [f"{ind}if {self.cond(d)}:", *self.stmts(r.randint(1, 2), ind + "    "), f"{ind}else:",
                    *self.stmts(1, ind + "    ")]
        if k == 7 and self.loop_depth < 2:
            self.loop_depth += 1
            bound = r.choice([str(r.randint(0, 4)), f"ai[{r.randrange(T)}] % 4 + 1", "t % 3"])
            self.counter += 1
            body = [f"{ind}for k{self.counter} in range({bound}):",
                    *self.stmts(r.randint(1, 2), ind + "    ")]
            self.loop_depth -= 1
            return body
        if k == 8 and self.loop_depth < 2:
            self.loop_depth += 1
            self.counter += 1
            w = f"w{self.counter}"
            body = [f"{ind}{w} = 0", f"{ind}while {w} < {r.randint(1, 5)}:", f"{ind}    {w} += 1",
                    *self.stmts(r.randint(1, 2), ind + "    "),
                    f"{ind}    if {self.cond(1)}:", f"{ind}        break"]
            self.loop_depth -= 1
            return body
        return [f"{ind}ti.atomic_add(tot[0], {self.int_expr(d)})"]


def _program(rng: random.Random, size: int) -> list[str]:
    g = _Gen(rng, size)
    ind = " " * 12
    lines = [f"{ind}a{k} = ai[(t + {k}) % {T}]" for k in range(N_INT)]
    lines += [f"{ind}x{k} = af[(t + {k}) % {T}]" for k in range(N_F64)]
    lines += [f"{ind}s{k} = ti.cast(af[(t + {k}) % {T}], ti.f32)" for k in range(N_F32)]
    lines += g.stmts(size, ind)
    lines += [f"{ind}oi[t, {k}] = a{k}" for k in range(N_INT)]
    lines += [f"{ind}of[t, {k}] = x{k}" for k in range(N_F64)]
    lines += [f"{ind}os[t, {k}] = s{k}" for k in range(N_F32)]
    return lines


KERNEL_HEAD = f"""import simgrad as ti

T = {T}


def make(ai, af, oi, of, os, tot):
    @ti.kernel
    def fuzz():
        for t in range(T):
"""

REF_HEAD = f"""T = {T}


def run(ti, ai, af, oi, of, os, tot):
    if True:
        for t in range(T):
"""

KERNEL_TAIL = "\n    return fuzz\n"


def forward_case(seed: int, size: int) -> tuple[str, str]:
    """(kernel module source, reference module source) of one random program."""
    lines = _program(random.Random(seed), size)
    body = "\n".join(lines) + "\n"
    return KERNEL_HEAD + body + KERNEL_TAIL, REF_HEAD + body


class RefNamespace:
    """What `ti.*` means in the reference: numpy scalar semantics that match the compiled code."""

    i32, f32, f64 = np.int32, np.float32, np.float64
    sin, cos, tanh, floor = staticmethod(np.sin), staticmethod(np.cos), staticmethod(np.tanh), staticmethod(np.floor)

    @staticmethod
    def exp(v):
        return np.exp(v)

    @staticmethod
    def sqrt(v):
        return np.sqrt(v)

    @staticmethod
    def select(c, a, b):
        return a if c else b

    @staticmethod
    def min(a, b):
        return _minmax(np.fmin, a, b)

    @staticmethod
    def max(a, b):
        return _minmax(np.fmax, a, b)

    @staticmethod
    def cast(v, t):
        if t is np.int32:
            return np.int32(np.trunc(v)) if isinstance(v, (float, np.floating)) else np.int32(v)
        return t(v)

    @staticmethod
    def atomic_add(ref, v):  # tot[0] += v, with the reference's array as the place
        raise NotImplementedError  # replaced by the rewrite in reference_source


def _reference_math(d):
    """The registry function on f64 values: the same libm call the kernel makes."""
    return staticmethod(lambda *v: np.float64(d.fold(dt.f64, *(float(x) for x in v))))


def _reference_int(d):
    return staticmethod(lambda a, b: np.int32(d.fold(dt.i32, int(a), int(b))))


for _d in MATH + [OPS[Op.CEIL], OPS[Op.ROUND]]:
    setattr(RefNamespace, _d.name, _reference_math(_d))
for _d in (OPS[Op.RAW_DIV], OPS[Op.RAW_MOD]):
    setattr(RefNamespace, _d.name, _reference_int(_d))
RefNamespace.math = RefNamespace  # type: ignore[attr-defined]  # ti.math.<name> in the reference


def _minmax(fn, a, b):
    """min/max as compiled: integers stay i32 (a Python literal does not widen them), floats drop a NaN."""
    if isinstance(a, (float, np.floating)) or isinstance(b, (float, np.floating)):
        return fn(a, b)
    return fn(np.int32(a), np.int32(b))


def reference_source(src: str) -> str:
    """Atomics in the reference: `ti.atomic_add(tot[0], e)` becomes `tot[0] += e` (int32 addition wraps)."""
    out = []
    for line in src.splitlines():
        s = line.strip()
        if s.startswith("ti.atomic_add(tot[0], "):
            ind = line[: len(line) - len(line.lstrip())]
            out.append(f"{ind}tot[0] += {s[len('ti.atomic_add(tot[0], '):-1]}")
        else:
            out.append(line)
    return "\n".join(out) + "\n"


def inputs(seed: int):
    rng = np.random.default_rng(seed)
    ai = rng.integers(-50, 50, size=T).astype(np.int32)
    af = rng.uniform(-2, 2, size=T)
    return ai, af


# -- gradients -------------------------------------------------------------------------------------
def _smooth(r: random.Random, d: int, names: list[str]) -> str:
    if d <= 0 or r.random() < 0.25:
        return r.choice(names + [f"{r.uniform(-2, 2):.3f}"])
    a, b = _smooth(r, d - 1, names), _smooth(r, d - 1, names)
    return r.choice([f"({a} + {b})", f"({a} - {b})", f"({a} * {b})", f"({a} / ({b} * {b} + 1.0))",
                     f"ti.sin({a})", f"ti.cos({a})", f"ti.exp(ti.sin({a}))", f"ti.tanh({a})",
                     f"ti.sqrt({a} * {a} + 0.5)", f"({a}) ** 2", f"ti.atan2({a}, {b} * {b} + 1.0)"])


GRAD_HEAD = """import simgrad as ti


def make(x, y, loss, n):
"""


def gradient_case(seed: int, size: int) -> str:
    """A Tape of two kernels over f64 fields: y[i] = f(x[i], x[i+1]) with local temporaries, a serial loop,
    data-independent branches and a ti.func; then loss += g(y[i], x[i]) through an atomic add."""
    r = random.Random(seed)
    lines = ["    @ti.func", "    def helper(u, v):", f"        return {_smooth(r, 2, ['u', 'v'])}", "",
             "    @ti.kernel", "    def first():", "        for i in range(n):",
             "            p = x[i]", "            q = x[(i + 1) % n]", "            acc = 0.0"]
    names = ["p", "q", "acc"]
    for _ in range(size):
        k = r.randrange(5)
        if k == 0:
            lines.append(f"            acc += {_smooth(r, 2, names)}")
        elif k == 1:
            lines += [f"            for m in range({r.randint(1, 3)}):",
                      f"                acc = acc * 0.5 + {_smooth(r, 2, names)}"]
        elif k == 2:
            lines += ["            if i % 2 == 0:", f"                acc += {_smooth(r, 2, names)}",
                      "            else:", f"                acc -= {_smooth(r, 1, names)}"]
        elif k == 3:
            lines.append(f"            acc += helper({_smooth(r, 1, names)}, {_smooth(r, 1, names)})")
        else:  # a run-time-bound loop reading the field under select/ternary, inside a while with break
            lines += ["            w = 0", "            while w < 3:", "                w += 1",
                      "                for m in range(ti.cast(ti.floor(p * 0.0) + 2.0, ti.i32)):",
                      f"                    acc += ti.select(x[m] > {r.uniform(-1, 1):.2f}, x[m] * q, "
                      f"{_smooth(r, 1, ['x[m]', 'p'])})",
                      f"                    acc += x[m] if x[m] < p else {_smooth(r, 1, ['acc', 'q'])} * 0.5",
                      f"                if w >= {r.randint(1, 3)}:", "                    break"]
    lines += ["            y[i] = acc", "",
              "    @ti.kernel", "    def second():", "        for i in range(n):",
              f"            loss[None] += {_smooth(r, 2, ['y[i]', 'x[i]'])}", "",
              "    return first, second"]
    return GRAD_HEAD + "\n".join(lines) + "\n"


class Inconclusive(Exception):
    """Central differences of this program disagree with each other across step sizes (values of 1e8 inside
    sin, say): finite differences cannot judge its gradient, so the case is neither a pass nor a failure."""


# -- running one case -----------------------------------------------------------------------------
def _load(path, name: str, text: str):
    import importlib.util

    file = path / f"{name}.py"
    file.write_text(text)
    spec = importlib.util.spec_from_file_location(name, file)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run_forward(seed: int, size: int, path) -> None:
    """Compile and run one random program under simgrad and in the reference; raise AssertionError (with
    the program) when they differ."""
    import warnings

    import simgrad as ti

    kernel_src, ref_src = forward_case(seed, size)
    ai, af = inputs(seed)
    ti.init(arch=ti.cpu, default_fp=ti.f64, default_ip=ti.i32)
    f = {"ai": ti.field(ti.i32, T), "af": ti.field(ti.f64, T), "oi": ti.field(ti.i32, (T, N_INT)),
         "of": ti.field(ti.f64, (T, N_F64)), "os": ti.field(ti.f32, (T, N_F32)), "tot": ti.field(ti.i32, 1)}
    f["ai"].from_numpy(ai)
    f["af"].from_numpy(af)
    mod = _load(path, f"fuzz_k{seed}_{size}", kernel_src)
    mod.make(**f)()
    out = {k: np.zeros((T, n), dt) for k, n, dt in (("oi", N_INT, np.int32), ("of", N_F64, np.float64),
                                                      ("os", N_F32, np.float32))}
    tot = np.zeros(1, np.int32)
    ref = _load(path, f"fuzz_r{seed}_{size}", reference_source(ref_src))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # wrap-around and inf are part of the semantics
        ref.run(RefNamespace, ai, af, out["oi"], out["of"], out["os"], tot)
    try:
        np.testing.assert_array_equal(f["oi"].to_numpy(), out["oi"])
        np.testing.assert_array_equal(f["tot"].to_numpy(), tot)
        np.testing.assert_allclose(f["of"].to_numpy(), out["of"], rtol=1e-6, atol=1e-9, equal_nan=True)
        np.testing.assert_allclose(f["os"].to_numpy(), out["os"], rtol=1e-5, atol=1e-6, equal_nan=True)
    except AssertionError as e:
        raise AssertionError(f"seed={seed} size={size}\ninputs ai={ai.tolist()} af={af.tolist()}\n"
                             f"{kernel_src}\n{e}") from None


def run_gradient(seed: int, size: int, path, n: int = 3, case=None) -> None:
    """The Tape gradient of a random differentiable program against central finite differences. `case`
    (seed, size) -> source makes the program (default gradient_case); `make(x, y, loss, n)` gets a y of 2n
    cells (shapes.py accumulates into y[n:] with atomics), zeroed before every run."""
    import simgrad as ti

    src = (case or gradient_case)(seed, size)
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, n, needs_grad=True)
    y = ti.field(ti.f64, 2 * n, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    x0 = np.random.default_rng(seed).uniform(-1.5, 1.5, n)
    x.from_numpy(x0)
    first, second = _load(path, f"fuzz_g{'s' if case else ''}{seed}_{size}", src).make(x, y, loss, n)

    def value(v):
        x.from_numpy(v)
        y.fill(0)
        loss[None] = 0
        first()
        second()
        return loss[None]

    y.fill(0)
    with ti.ad.Tape(loss=loss):
        first()
        second()
    got = x.grad.to_numpy()

    def central(eps: float) -> np.ndarray:
        out = np.zeros(n)
        for k in range(n):
            hi, lo = x0.copy(), x0.copy()
            hi[k] += eps
            lo[k] -= eps
            out[k] = (value(hi) - value(lo)) / (2 * eps)
        return out

    # A random program can be badly conditioned (intermediate values of 1e8): its central difference is
    # then off at one step size by truncation and at another by cancellation. AD must agree with FD at
    # one of three steps; a wrong derivative agrees with none.
    tried = []
    for eps in (1e-6, 1e-4, 1e-8):
        want = central(eps)
        tried.append(want)
        scale = max(1.0, float(np.max(np.abs(want))))
        if np.allclose(got, want, rtol=1e-5, atol=1e-6 * scale):
            return
    text = f"seed={seed} size={size} x={x0.tolist()}\n{src}\nAD {got}\nFD (eps 1e-6, 1e-4, 1e-8) {tried}"
    if not np.allclose(tried[0], tried[1], rtol=1e-4, atol=1e-6 * max(1.0, float(np.max(np.abs(tried[1]))))):
        raise Inconclusive(text)  # FD itself is unstable across steps: this program cannot be checked by FD
    raise AssertionError(text)


def run_forward_mode(seed: int, size: int, path, n: int = 3, case=None) -> None:
    """FwdMode against reverse mode on a random differentiable program: loss.dual (= J v) must equal
    <x.grad, v> (= (J^T 1) . v) for a random direction v; no finite differences, so no tolerance games."""
    import simgrad as ti

    src = (case or gradient_case)(seed, size)
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, n, needs_grad=True, needs_dual=True)
    y = ti.field(ti.f64, 2 * n, needs_grad=True, needs_dual=True)
    loss = ti.field(ti.f64, (), needs_grad=True, needs_dual=True)
    rng = np.random.default_rng(seed)
    x.from_numpy(rng.uniform(-1.5, 1.5, n))
    v = rng.standard_normal(n)
    first, second = _load(path, f"fuzz_f{'s' if case else ''}{seed}_{size}", src).make(x, y, loss, n)
    y.fill(0)
    with ti.ad.Tape(loss=loss):
        first()
        second()
    reverse = float(np.dot(x.grad.to_numpy(), v))
    y.fill(0)
    with ti.ad.FwdMode(loss=loss, param=x, seed=list(v)):
        loss[None] = 0
        first()
        second()
    forward = loss.dual[None]
    if not np.isclose(forward, reverse, rtol=1e-9, atol=1e-12 * max(1.0, abs(reverse))):
        raise AssertionError(f"seed={seed} size={size}\n{src}\nforward J v = {forward}, reverse (J^T 1).v = "
                             f"{reverse}")
