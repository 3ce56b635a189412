"""Golden dump of the adjoint IR of `for i in x: y[i] = ti.sin(x[i] * x[i])` (after the whole pipeline).

Statement ids are renumbered in order of appearance, field reprs reduced to their names and source
locations dropped, so the dump only changes when the shape of the adjoint changes. Rewrite it with
`pytest tests/autodiff/test_ad_golden_ir.py --update-golden` and review the diff."""

from __future__ import annotations

import os
import re

import numpy as np

import simgrad as ti
from simgrad.ir.printer import print_kernel

GOLDEN = os.path.join(os.path.dirname(__file__), "golden", "sin_sq_adjoint.txt")


def normalise(text: str) -> str:
    text = re.sub(r"<(?:Scalar|Matrix)Field (\S+)[^>]*>", r"\1", text)
    text = re.sub(r"[ \t]+#[^\n]*", "", text)  # source locations
    ids: dict[str, str] = {}

    def renumber(m):
        return ids.setdefault(m.group(0), f"%{len(ids)}")

    text = re.sub(r"%\d+", renumber, text)
    return "\n".join(line.rstrip() for line in text.strip().splitlines()) + "\n"


def _adjoint_text():
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    x = ti.field(ti.f32, shape=16, name="x", needs_grad=True)
    y = ti.field(ti.f32, shape=16, name="y", needs_grad=True)

    @ti.kernel
    def sin_sq():
        for i in x:
            y[i] = ti.sin(x[i] * x[i])

    xs = np.linspace(-1, 1, 16).astype(np.float32)
    x.from_numpy(xs)
    sin_sq()
    y.grad.fill(1)
    sin_sq.grad()
    # the dump is of the kernel that actually ran: check its result
    np.testing.assert_allclose(x.grad.to_numpy(), 2 * xs * np.cos(xs * xs), rtol=1e-5, atol=1e-6)
    insts = list(sin_sq._caches["grad"].values())
    assert len(insts) == 1
    return normalise(print_kernel(insts[0].ir))


def test_normalise_renumbers_and_strips():
    raw = ("%12:f32 = global_ptr %7 [target=<ScalarField x.grad f32 shape=(16,)>]  # a.py:3\n"
           "%13:f32 = atomic %12, %40 [kind=add]  # a.py:3\n")
    assert normalise(raw) == ("%0:f32 = global_ptr %1 [target=x.grad]\n"
                              "%2:f32 = atomic %0, %3 [kind=add]\n")


def test_sin_sq_adjoint_golden(request):
    text = _adjoint_text()
    lines = text.splitlines()

    # its shape, independent of the golden file: one parallel loop; forward replay (loads of x, mul,
    # no store to y); adjoint accumulation (y.grad read, cos); atomic adds into x.grad
    loops = [ln for ln in lines if "range_for" in ln]
    assert len(loops) == 1 and "parallel=True" in loops[0]
    # the only global store is the one that consumes y.grad (zeroes it after reading it)
    stores = [ln for ln in lines if "global_store" in ln]
    ygrad_ptrs = {ln.split(":")[0].strip() for ln in lines if "target=y.grad," in ln}
    assert len(stores) == 1 and stores[0].split("global_store")[1].split(",")[0].strip() in ygrad_ptrs, \
        "the adjoint must not replay global writes"
    first = {key: next(k for k, ln in enumerate(lines) if key in ln)
             for key in ("target=x,", "f32 = mul", "target=y.grad,", "cos", "target=x.grad,")}
    order = [first[key] for key in ("target=x,", "f32 = mul", "target=y.grad,", "cos", "target=x.grad,")]
    assert order == sorted(order), f"unexpected statement order {first}"
    xgrad_ptrs = {ln.split(":")[0].strip() for ln in lines if "target=x.grad," in ln}
    adds = [ln for ln in lines if "atomic" in ln and "kind=add" in ln and
            ln.split("atomic")[1].split(",")[0].strip() in xgrad_ptrs]
    assert adds, "no atomic add into x.grad"
    assert not any("target=y," in ln for ln in lines), "y itself is never read by the adjoint"

    if request.config.getoption("--update-golden"):
        os.makedirs(os.path.dirname(GOLDEN), exist_ok=True)
        with open(GOLDEN, "w") as fh:
            fh.write(text)
    assert os.path.exists(GOLDEN), f"{GOLDEN} is missing: run pytest with --update-golden"
    with open(GOLDEN) as fh:
        golden = fh.read()
    assert text == golden, ("the adjoint IR changed; review and rerun with --update-golden:\n" + text)
