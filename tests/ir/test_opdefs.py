"""Every op of the elementwise registry (ir/opdefs.py), on every type it takes.

(a) the constant fold (passes/simplify.py `fold`, through the entry's exact value) equals what the compiled
    kernel computes from the same operands at run time, bit for bit (edge values: zeros of both signs,
    negatives, extremes, shift amounts past the width, inf and NaN; a NaN equals any NaN; the sign of a zero
    is not compared where LLVM may choose it: `nsz` instructions and min/max of equal zeros);
(b) its VJP (kernel.grad) and JVP (FwdMode) agree with central differences in f64 at the points of its row;
(c) it lowers: (a) compiles a kernel using it for every type, and codegen reaches it through LOWERING;
(d) the fuzz generator (tests/fuzz/gen.py) draws every op from the registry and writes it correctly.

`ROWS` is the parameter table: one row per registry op; an entry without a row fails
test_every_registry_op_has_a_row. A row holds the f64 points of (b) (None: the op is not differentiable,
integer-only).
"""

from __future__ import annotations

import functools
import math
import os
import sys

import numpy as np
import pytest

import simgrad as ti
from simgrad import dtypes as dt
from simgrad.codegen.llvm import LOWERING, lower_elementwise
from simgrad.ir import context, numeric, vecmath
from simgrad.ir.builder import Builder
from simgrad.ir.opdefs import FLOAT, INT, Instr, Special
from simgrad.ir.ops import OPS, Op
from simgrad.lang.expr import Expr
from simgrad.passes.simplify import fold
from simgrad.runtime import fpenv

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "fuzz"))
import gen  # noqa: E402

INF, NAN = math.inf, math.nan

# the parameter table: per op, the f64 points where (b) checks its derivatives (away from kinks and ties)
ROWS: dict[Op, tuple[tuple[float, ...], ...] | None] = {
    Op.ADD: ((0.3, -1.2), (2.5, 0.7)),
    Op.SUB: ((0.3, -1.2), (2.5, 0.7)),
    Op.MUL: ((0.3, -1.2), (2.5, 0.7)),
    Op.DIV: ((0.3, -1.2), (2.5, 0.7)),
    Op.FLOORDIV: None,
    Op.MOD: None,
    Op.RAW_DIV: None,
    Op.RAW_MOD: None,
    Op.POW: ((0.3, 1.7), (2.5, -0.7), (1.5, 3.0)),
    Op.MIN: ((0.3, -1.2), (0.5, 0.7)),
    Op.MAX: ((0.3, -1.2), (0.5, 0.7)),
    Op.BIT_AND: None,
    Op.BIT_OR: None,
    Op.BIT_XOR: None,
    Op.SHL: None,
    Op.SHR: None,
    Op.NEG: ((0.3,), (-2.5,)),
    Op.BIT_NOT: None,
    Op.LOGICAL_NOT: ((0.3,), (-2.5,)),
    Op.ABS: ((0.3,), (-2.5,)),
    Op.FLOOR: ((0.3,), (-2.5,)),
    Op.CEIL: ((0.3,), (-2.5,)),
    Op.ROUND: ((0.3,), (-2.25,)),
    Op.LT: ((0.3, -1.2), (0.5, 0.7)),
    Op.LE: ((0.3, -1.2), (0.5, 0.7)),
    Op.GT: ((0.3, -1.2), (0.5, 0.7)),
    Op.GE: ((0.3, -1.2), (0.5, 0.7)),
    Op.EQ: ((0.3, -1.2), (0.5, 0.7)),
    Op.NE: ((0.3, -1.2), (0.5, 0.7)),
    Op.SQRT: ((0.3,), (2.5,)),
    Op.RSQRT: ((0.3,), (2.5,)),
    Op.SIN: ((0.3,), (-2.5,)),
    Op.COS: ((0.3,), (-2.5,)),
    Op.TAN: ((0.3,), (-1.2,)),
    Op.ASIN: ((0.3,), (-0.8,)),
    Op.ACOS: ((0.3,), (-0.8,)),
    Op.ATAN2: ((0.3, -1.2), (-2.5, 0.7)),
    Op.EXP: ((0.3,), (-2.5,)),
    Op.LOG: ((0.3,), (2.5,)),
    Op.TANH: ((0.3,), (-1.2,)),
    Op.LOG1P: ((0.3,), (-0.5,)),  # ti.math.log1p: simgrad's own, Taichi 1.7.4 has none
    Op.EXPM1: ((0.3,), (-2.5,)),  # ti.math.expm1: simgrad's own, Taichi 1.7.4 has none
    Op.CBRT: ((0.3,), (-2.5,)),  # ti.math.cbrt: simgrad's own, Taichi 1.7.4 has none
    Op.HYPOT: ((0.3, -1.2), (-2.5, 0.7)),  # ti.math.hypot: simgrad's own, Taichi 1.7.4 has none
}

INT_TYPES = [dt.i8, dt.i16, dt.i32, dt.i64, dt.u8, dt.u16, dt.u32, dt.u64]
FLOAT_TYPES = [dt.f16, dt.f32, dt.f64]
_INTS = [0, 1, -1, 2, -2, 3, 7, -7, 8, 9, 13, -100, 31, 32, 33, 63, 64, 65, 1000, -12345, 2**31 - 1, -2**31,
         2**63 - 1, -2**63, 2**62 + 5, 255, 128]
_FLOATS = [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 1.5, -2.75, 3.0, 0.1, 1e-3, 100.0, -1e5, 0.7853981633974483,
           2.0, 1e30, -1e-40, 65504.0, 1e-8, INF, -INF, NAN]


def _values(t: dt.DataType) -> list:
    """The edge values at type `t` (wrapped or rounded to it), without repeats."""
    out: list = []
    for v in (_FLOATS if t.is_float else _INTS):
        w = numeric.const_value(v, t)
        if not any(_same_bits(w, o) for o in out):
            out.append(w)
    return out


def _same_bits(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (a != a and b != b) or (a == b and math.copysign(1, a) == math.copysign(1, b))
    return a == b


def _operands(op: Op, t: dt.DataType) -> list[tuple]:
    """Every edge value (pair), then 200 random ones (a fixed seed): libm's f32 functions differ from
    numpy's and from f64 libm rounded to f32 on a few percent of random arguments."""
    vals = _values(t)
    arity = OPS[op].arity
    rows = [(a,) for a in vals] if arity == 1 else [(a, b) for a in vals for b in vals]
    rng = np.random.default_rng(7)
    if t.is_float:
        wide = rng.uniform(-12.0, 12.0, (200, arity)) * 10.0 ** rng.integers(-3, 3, (200, arity))
    else:
        wide = rng.integers(-(1 << 40), 1 << 40, (200, arity))
    rows += [tuple(numeric.const_value(v.item(), t) for v in row) for row in wide]
    return rows


def _types(op: Op) -> list[dt.DataType]:
    d = OPS[op]
    return (FLOAT_TYPES if d.domain != INT else []) + (INT_TYPES if d.domain != FLOAT else [])


def _cases():
    return [pytest.param(op, t, id=f"{op.name}-{t.name}") for op in OPS for t in _types(op)]


def _emit(op: Op, t: dt.DataType, *operands: Expr) -> Expr:
    """The op itself on operands converted to `t` (no promotion, no frontend rewriting)."""
    b = context.builder()
    s = [b.cast(e.stmt, t) for e in operands]
    return Expr(b.binary(op, *s) if len(s) == 2 else b.unary(op, s[0]))


@functools.cache
def _machine(t: dt.DataType) -> dict[Op, np.ndarray]:
    """What compiled kernels compute for every op taking `t`, on _operands(op, t): one kernel per result
    type (the type itself, i32 for comparisons)."""
    results: dict[Op, np.ndarray] = {}
    ti.init(arch=ti.cpu)
    for i32_result in (False, True):
        ops = [op for op in OPS if OPS[op].accepts(t) and (OPS[op].result == "i32") == i32_result]
        rows = [_operands(op, t) for op in ops]
        n = max(len(r) for r in rows)
        data = np.zeros((len(ops), n, 2), dtype=t.np)
        for k, r in enumerate(rows):
            for j, vals in enumerate(r):
                data[k, j, : len(vals)] = [t.np.type(v) for v in vals]
        x = ti.field(t, (len(ops), n, 2))
        out = ti.field(ti.i32 if i32_result else t, (len(ops), n))
        x.from_numpy(data)
        arity = [OPS[op].arity for op in ops]
        nops = len(ops)

        def apply(k, a, b):
            return _emit(ops[k], t, a, b) if arity[k] == 2 else _emit(ops[k], t, a)

        @ti.kernel
        def run():
            for k in ti.static(range(nops)):
                for j in range(n):
                    out[k, j] = apply(k, x[k, j, 0], x[k, j, 1])

        run()
        got = out.to_numpy()
        for k, op in enumerate(ops):
            results[op] = got[k, : len(rows[k])]
    ti.reset()
    return results


FLUSHED = frozenset({32, 64}) if fpenv.switchable() else frozenset()  # what a CPU kernel flushes by default
# Ops that return an operand or its bits: no arithmetic, no underflow, no flush of a subnormal operand (in a
# compile that operand, a constant, was flushed when it was made); every other subnormal result is a zero. (Math
# through libm with a subnormal operand or result is not folded in flush-to-zero mode: ir/numeric.py libm.)
PASS_THROUGH = {Op.MIN, Op.MAX, Op.NEG, Op.ABS}


def _vector_version(op: Op, t: dt.DataType, vals, got) -> bool:
    """The row's loop vectorised: a math function's lanes are codegen/vecmath.py's vector version (its numpy
    model, ir/vecmath.py), not libm's scalar call that constants fold as (both within 1 ulp)."""
    table = vecmath.FUNCTIONS if t is dt.f32 else vecmath.FUNCTIONS64 if t is dt.f64 else {}
    if op not in table:
        return False
    model = vecmath.evaluate(table[op][1], *([v] for v in vals), f64=t is dt.f64)[0]
    return _same_bits(float(model), float(got)) or (model != model and got != got)


def _sign_free(op: Op) -> bool:
    """Ops whose zero results may carry either sign: `nsz` instructions, and llvm.minnum/maxnum of equal
    zeros (LangRef: either operand)."""
    low = OPS[op].lower_float
    return op in (Op.MIN, Op.MAX) or isinstance(low, Instr) or low in (Special("neg"), Special("rsqrt"))


@pytest.mark.parametrize("op,t", _cases())
def test_fold_equals_the_compiled_op(op, t):
    """(a) and (c): simplify's fold of constant operands is bit for bit what the kernel computes at run time, in
    the default flush-to-zero mode (runtime/fpenv.py: a subnormal result is a zero, folded as the constant the
    compile makes of it)."""
    d = OPS[op]
    machine = _machine(t)[op]
    result_t = d.result_type(t)
    bad = []
    folded_any = False
    for vals, got in zip(_operands(op, t), machine):
        stmt = Builder.detached(op, result_t, tuple(Builder.constant(v, t) for v in vals))
        with numeric.flushing(FLUSHED if result_t.is_float and op not in PASS_THROUGH else frozenset()):
            want = fold(stmt)
            if want is not None and result_t.is_float:
                want = Builder.constant(want, result_t).attrs["value"]  # what the compile makes of it
        if want is None:
            continue  # not folded (integer division by zero, libm at subnormals): the instruction stays
        folded_any = True
        got = got.item()
        if result_t.is_float:
            if want != want and got != got:
                continue
            if want == got and (want != 0 or _sign_free(op) or _same_bits(want, float(got))):
                continue
            if _vector_version(op, t, vals, got):
                continue
        elif want == got:
            continue
        bad.append(f"{op.name}{vals}: folds to {want!r}, runs to {got!r}")
    assert folded_any
    assert not bad, f"{len(bad)} mismatches at {t}:\n" + "\n".join(bad[:20])


def test_every_registry_op_has_a_row():
    assert set(ROWS) == set(OPS), f"registry ops without a test row: {set(OPS) - set(ROWS)}"


@pytest.mark.parametrize("op", list(OPS), ids=lambda op: op.name)
def test_lowering_is_declared_for_every_type_it_takes(op):
    """(c) codegen lowers the op through its registry entry for floats and/or integers, as its domain says."""
    d = OPS[op]
    assert LOWERING[op] is lower_elementwise
    assert (d.lower_float is not None) == (d.domain != INT)
    assert (d.lower_int is not None) == (d.domain != FLOAT)


def _differentiable() -> list[Op]:
    return [op for op, row in ROWS.items() if row is not None]


@functools.cache
def _derivatives() -> dict[Op, tuple[np.ndarray, np.ndarray]]:
    """Per differentiable op, d result / d operand at its row's points: (reverse, forward), each
    (points, operands), from one f64 kernel over all ops."""
    ops = _differentiable()
    rows = [ROWS[op] for op in ops]
    n = max(len(r) for r in rows)  # type: ignore[arg-type]
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    xs = [ti.field(ti.f64, (len(ops), n), needs_grad=True, needs_dual=True) for _ in range(2)]
    y = ti.field(ti.f64, (len(ops), n), needs_grad=True, needs_dual=True)
    data = np.ones((2, len(ops), n))
    for k, r in enumerate(rows):
        for j, vals in enumerate(r):  # type: ignore[arg-type]
            data[: len(vals), k, j] = vals
    for i in range(2):
        xs[i].from_numpy(data[i])
    arity = [OPS[op].arity for op in ops]
    nops = len(ops)

    def apply(k, a, b):
        r = _emit(ops[k], dt.f64, a, b) if arity[k] == 2 else _emit(ops[k], dt.f64, a)
        return Expr(context.builder().cast(r.stmt, dt.f64))

    @ti.kernel
    def run():
        for k in ti.static(range(nops)):
            for j in range(n):
                y[k, j] = apply(k, xs[0][k, j], xs[1][k, j])

    run()
    y.grad.fill(1.0)
    run.grad()
    reverse = np.stack([x.grad.to_numpy() for x in xs], axis=-1)
    forward = []
    for i in range(2):
        with ti.ad.FwdMode(loss=y, param=xs[i], seed=[1.0] * (len(ops) * n)):
            run()
        forward.append(y.dual.to_numpy())
    fwd = np.stack(forward, axis=-1)
    ti.reset()
    return {op: (reverse[k], fwd[k]) for k, op in enumerate(ops)}


@pytest.mark.parametrize("op", _differentiable(), ids=lambda op: op.name)
def test_vjp_and_jvp_match_central_differences(op):
    """(b) in f64: both derivative modes against central differences of the exact (machine) function."""
    d = OPS[op]
    reverse, forward = _derivatives()[op]
    for j, point in enumerate(ROWS[op]):  # type: ignore[arg-type]
        for i in range(d.arity):
            h = 1e-6 * max(1.0, abs(point[i]))
            hi, lo = list(point), list(point)
            hi[i] += h
            lo[i] -= h
            fd = (float(d.fold(dt.f64, *hi)) - float(d.fold(dt.f64, *lo))) / (2 * h)
            assert reverse[j, i] == pytest.approx(fd, rel=1e-6, abs=1e-8), f"VJP {op.name}{point} d/dx{i}"
            assert forward[j, i] == pytest.approx(fd, rel=1e-6, abs=1e-8), f"JVP {op.name}{point} d/dx{i}"


@pytest.mark.parametrize("op", list(OPS), ids=lambda op: op.name)
def test_fuzz_generator_generates_every_op(op, tmp_path):
    """(d) tests/fuzz/gen.py draws its ops from the registry (math functions by name, the rest as it spells
    them, comparisons as conditions): each appears in generated programs, and what it writes compiles and
    matches the reference namespace (numpy scalars, the registry's libm) on i32 and f64 operands."""
    if op in gen.COMPARISON:
        texts = "".join(gen.forward_case(seed, 8)[0] for seed in range(40))
        assert f" {gen.COMPARISON[op]} " in texts
        return
    assert op in gen.INT_OPS or op in gen.FLOAT_OPS, f"the fuzz generator cannot write {op.name}"
    d = OPS[op]
    texts = "".join(gen.forward_case(seed, 8)[0] for seed in range(300))
    if d.export:
        assert f".{d.name}((" in texts, f"the generator never wrote {d.name}"
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    for ty, pairs in (("i32", ((7, -3), (-12345, 9), (2**31 - 1, 2))), ("f64", ((0.3, -1.7), (-2.0, 0.6)))):
        if op not in (gen.INT_OPS if ty == "i32" else gen.FLOAT_OPS):
            continue
        call = gen.op_expr(op, "a", "b")
        src = f"import simgrad as ti\n\n\ndef make(o):\n    @ti.kernel\n    def k(a: ti.{ty}, b: ti.{ty}):\n" \
              f"        o[None] = {call}\n\n    return k\n"
        o = ti.field(getattr(ti, ty), ())
        mod = gen._load(tmp_path, f"opdefs_{op.name}_{ty}", src)
        for a, b in pairs:
            mod.make(o)(a, b)
            scalar = np.int32 if ty == "i32" else np.float64
            with np.errstate(all="ignore"):
                want = eval(call, {"ti": gen.RefNamespace, "a": scalar(a), "b": scalar(b)})
            assert o[None] == pytest.approx(float(want), rel=1e-12), f"{call} at {a}, {b}"


@pytest.mark.parametrize("name", sorted(ti.lang.operators.MATH), ids=str)
def test_math_functions_are_named_for_the_kernel_cache(name):
    """The kernel cache describes a library function by module and qualified name: each generated math
    function must be findable under its own (they were all `_math.<locals>.f`, so a kernel calling a global
    `fn = ti.cos` got the cached kernel of `fn = ti.sin`)."""
    fn = ti.lang.operators.MATH[name]
    assert getattr(sys.modules[fn.__module__], fn.__qualname__) is fn
