"""Golden adjoint IR for each construct the reverse transform handles, and tangent IR for two in forward
mode: tests/autodiff/golden/<case>.txt holds the kernel right after the transform and its clean-up
(passes/manager.py: autodiff, then simplify; before hoisting, strategies and access lowering, so it reads
as the transform wrote it). Each file was read by hand; golden/README.md says what each one shows and why
it is right. Each case also checks its gradient (or tangent) against central differences in f64, so a
golden file is only ever rewritten for a kernel that still differentiates correctly.

Rewrite after a deliberate change with `pytest tests/autodiff/test_ad_golden_constructs.py --update-golden`,
then review the diff."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import fd_grad
from conftest import normalise_ir

import simgrad as ti

N = 6


def _ir_after_transform(out: str, kernel_name: str, transform: str) -> str:
    """The IR SIMGRAD_DEBUG=2 printed after the simplify that follows `transform` in `kernel_name`'s
    pipeline (each pass is announced as `[simgrad] <kernel>: <pass>`, its IR printed after it)."""
    chunks = out.split("[simgrad] ")
    steps = [(c.split("\n", 1)[0], c.split("\n", 1)[1] if "\n" in c else "") for c in chunks[1:]]
    mine = [(head.split(": ", 1)[1], ir) for head, ir in steps if head.startswith(kernel_name + ":")]
    names = [n for n, _ in mine]
    k = names.index(transform)
    simplify = names.index("simplify", k)
    return normalise_ir(mine[simplify][1])


# -- the cases: each returns (kernel, inputs, outputs); the loss is sum(c * outputs) -------------------------

def _serial_loop_recomputed():
    """A serial loop inside the parallel one that stores no local declared outside it: not taped, each
    reversed iteration recomputes its body."""
    x = ti.field(ti.f64, N, name="x", needs_grad=True)
    w = ti.field(ti.f64, 3, name="w", needs_grad=True)
    y = ti.field(ti.f64, N, name="y", needs_grad=True)

    @ti.kernel
    def serial_loop_recomputed():
        for i in x:
            for j in range(3):
                y[i] += ti.sin(x[i] * w[j])

    return serial_loop_recomputed, [x, w], [y]


def _nested_loops_tape():
    """A value a nonlinear op needs, overwritten in a serial loop: every iteration's value is pushed on the
    tape and popped in reverse; the loop itself nests in another serial loop."""
    x = ti.field(ti.f64, N, name="x", needs_grad=True, needs_dual=True)
    y = ti.field(ti.f64, N, name="y", needs_grad=True, needs_dual=True)

    @ti.kernel
    def nested_loops_tape():
        for i in x:
            v = x[i]
            for _a in range(2):
                for _b in range(2):
                    v = ti.sin(v) * 1.5
            y[i] = v

    return nested_loops_tape, [x], [y]


def _if_else():
    x = ti.field(ti.f64, N, name="x", needs_grad=True, needs_dual=True)
    y = ti.field(ti.f64, N, name="y", needs_grad=True, needs_dual=True)

    @ti.kernel
    def if_else():
        for i in x:
            v = 0.0
            if x[i] > 0:
                v = x[i] * x[i]
            else:
                v = ti.exp(x[i])
            y[i] = v

    return if_else, [x], [y]


def _while_break_continue():
    x = ti.field(ti.f64, N, name="x", needs_grad=True)
    y = ti.field(ti.f64, N, name="y", needs_grad=True)

    @ti.kernel
    def while_break_continue():
        for i in x:
            v = x[i]
            k = 0
            while k < 4:
                k += 1
                if k == 2:
                    continue
                v = v * x[i]
                if v > 50.0:
                    break
            y[i] = v

    return while_break_continue, [x], [y]


def _atomics():
    """An atomic add on a local (`s += ...` on a loop-body local) and on a global element shared by all
    iterations (`total[None] += ...`)."""
    x = ti.field(ti.f64, N, name="x", needs_grad=True)
    total = ti.field(ti.f64, (), name="total", needs_grad=True)

    @ti.kernel
    def atomics():
        for i in x:
            s = 0.0
            s += x[i] * x[i]
            ti.atomic_add(total[None], s * x[i])

    return atomics, [x], [total]


def _local_matrix_dynamic_index():
    """A local vector indexed by a run-time value: the adjoint accumulates into the entry that index picks."""
    x = ti.field(ti.f64, N, name="x", needs_grad=True)
    y = ti.field(ti.f64, N, name="y", needs_grad=True)

    @ti.kernel
    def local_matrix_dynamic_index():
        for i in x:
            m = ti.Vector([x[i], x[i] * x[i], ti.sin(x[i])])
            y[i] = m[i % 3] * 2.0

    return local_matrix_dynamic_index, [x], [y]


REVERSE = {
    "serial_loop_recomputed": _serial_loop_recomputed,
    "nested_loops_tape": _nested_loops_tape,
    "if_else": _if_else,
    "while_break_continue": _while_break_continue,
    "atomics": _atomics,
    "local_matrix_dynamic_index": _local_matrix_dynamic_index,
}
FORWARD = {"if_else": _if_else, "nested_loops_tape": _nested_loops_tape}


def _setup(case):
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    kernel, inputs, outputs = case()
    rng = np.random.default_rng(7)
    for f in inputs:
        f.from_numpy(rng.uniform(-1.2, 1.2, f.shape))
    coeffs = [rng.uniform(0.5, 1.5, f.shape) for f in outputs]

    def forward():
        for f in outputs:
            f.fill(0)
        kernel()

    def loss() -> float:
        forward()
        return float(sum(np.sum(c * f.to_numpy()) for c, f in zip(coeffs, outputs)))

    return kernel, inputs, outputs, coeffs, forward, loss


@pytest.mark.parametrize("name", sorted(REVERSE))
def test_adjoint_golden_and_finite_differences(name, golden, monkeypatch, capsys):
    kernel, inputs, outputs, coeffs, forward, loss = _setup(REVERSE[name])
    expected = [fd_grad(loss, f) for f in inputs]
    forward()
    for c, f in zip(coeffs, outputs):
        f.grad.from_numpy(c)
    for f in inputs:
        f.grad.fill(0)
    capsys.readouterr()
    monkeypatch.setenv("SIMGRAD_DEBUG", "2")
    kernel.grad()
    monkeypatch.delenv("SIMGRAD_DEBUG")
    text = _ir_after_transform(capsys.readouterr().out, f"{name}_grad", "check_and_adjoint")
    for f, e in zip(inputs, expected):
        np.testing.assert_allclose(f.grad.to_numpy(), e, rtol=1e-6, atol=1e-8, err_msg=f"{name}: {f.name}.grad")
    golden.check(f"{name}.txt", text)


@pytest.mark.parametrize("name", sorted(FORWARD))
def test_tangent_golden_and_finite_differences(name, golden, monkeypatch, capsys):
    kernel, inputs, outputs, _coeffs, forward, _loss = _setup(FORWARD[name])
    (x,), (y,) = inputs, outputs
    seed = np.random.default_rng(3).uniform(-1, 1, x.shape)
    base = x.to_numpy()
    x.from_numpy(base + 1e-6 * seed)
    forward()
    hi = y.to_numpy()
    x.from_numpy(base - 1e-6 * seed)
    forward()
    lo = y.to_numpy()
    x.from_numpy(base)
    capsys.readouterr()
    monkeypatch.setenv("SIMGRAD_DEBUG", "2")
    with ti.ad.FwdMode(loss=y, param=x, seed=list(seed)):
        forward()
    monkeypatch.delenv("SIMGRAD_DEBUG")
    text = _ir_after_transform(capsys.readouterr().out, f"{name}_fwd", "make_forward")
    np.testing.assert_allclose(y.dual.to_numpy(), (hi - lo) / 2e-6, rtol=1e-6, atol=1e-8)
    golden.check(f"{name}_forward.txt", text)


def test_ir_after_transform_picks_the_simplify_after_it():
    out = ("[simgrad] k_grad: simplify\nA\n[simgrad] k_grad: make_adjoint\nB\n[simgrad] other: simplify\nX\n"
           "[simgrad] k_grad: verify\nC\n[simgrad] k_grad: simplify\nkernel k_grad {\n}\n")
    assert _ir_after_transform(out, "k_grad", "make_adjoint") == "kernel k_grad {\n}\n"
