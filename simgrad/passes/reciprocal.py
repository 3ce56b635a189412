"""fast_math's division by a constant (ti.init(fast_math=True), Taichi's default): `a / c` for a float constant
c != 0 becomes `a * (1 / c)`, the reciprocal rounded once at the division's type, as taichi 1.7.4's alg_simp
rewrites it (transforms/alg_simp.cpp, `a / const -> a * (1 / const)`). A multiply is several times cheaper than a
division, in a vector loop most (snow_phaseField's `grad / (2 * dx)`), and the results are taichi's to the bit; an
exact division is fast_math=False. f32 and f64 only (taichi implements no other). Run after the autodiff
transform, so an adjoint's `g / c` is rewritten as taichi's is."""

from __future__ import annotations

from simgrad.ir.builder import Builder
from simgrad.ir.nodes import Kernel, walk
from simgrad.ir.ops import OPS, Op


def reciprocal(kernel: Kernel) -> bool:
    changed = False
    for s in walk(kernel.body):
        if s.op is not Op.DIV or s.vtype.bits not in (32, 64) or not s.vtype.is_float:
            continue
        a, c = s.operands
        if c.op is not Op.CONST or c.attrs["value"] == 0:
            continue
        inverse = OPS[Op.DIV].fold(c.vtype, 1.0, c.attrs["value"])
        if inverse is None:
            continue
        s.op = Op.MUL
        s.operands = (a, Builder.constant(inverse, c.vtype))
        changed = True
    return changed
