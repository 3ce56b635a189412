"""benchmarks/originals.py on a stand-in DiffTaichi checkout: the child serves `import taichi` with simgrad,
keeps the GUI headless, applies a program's patches, and the parent reads losses, times and errors."""

import argparse
import importlib.util
import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("originals", os.path.join(HERE, "..", "..", "benchmarks", "originals.py"))
originals = importlib.util.module_from_spec(spec)
sys.modules["originals"] = originals  # dataclasses look their module up
spec.loader.exec_module(originals)

TOY = """\
import taichi as ti
import sys
ti.init(arch=ti.cuda, default_fp=ti.f32)
x = ti.field(ti.f32, shape=())
loss = ti.field(ti.f32, shape=(), needs_grad=True)
w = ti.field(ti.f32, shape=(), needs_grad=True)
gui = ti.GUI("toy", (64, 64))

@ti.kernel
def f():
    loss[None] = (w[None] - 3.0) ** 2

w[None] = 0.0
for it in range(100):
    with ti.ad.Tape(loss):
        f()
    print('Iter=', it, 'Loss=', loss[None])
    w[None] -= 0.25 * w.grad[None]
    gui.line((0.1, 0.1), ((0.5,), (0.5,)), radius=1, color=0xFFFFFF)
    gui.show()
if len(sys.argv) > 1:
    raise ValueError("asked to fail")
"""


@pytest.fixture
def checkout(tmp_path):
    (tmp_path / "examples").mkdir()
    (tmp_path / "examples" / "toy.py").write_text(TOY)
    return str(tmp_path)


def _args(checkout, iters=4):
    return argparse.Namespace(difftaichi=checkout, iters=iters, timeout=120, nice=0, keep=False, taichi_init={},
                              arch="cpu", simgrad_path=os.path.dirname(originals.HERE))


def test_runs_a_patched_program_under_simgrad(checkout):
    prog = originals.Program("toy", "toy.py", patches=[(r"range\(100\)", "range({iters})", "iterations")])
    r = originals.run_one(sys.executable, "simgrad", prog, _args(checkout), [])
    assert r["rc"] == 0, r.get("stderr_tail")
    assert r["losses"] == pytest.approx([9.0, 2.25, 0.5625, 0.140625])  # w: 0, 1.5, 2.25, 2.625
    assert r["times"] == sorted(r["times"]) and r["first_s"] > 0 and r["sec_per_iter"] >= 0


def test_reports_the_error_and_the_program_frame(checkout):
    prog = originals.Program("toy", "toy.py", ["fail"], patches=[(r"range\(100\)", "range({iters})", "iterations")])
    r = originals.run_one(sys.executable, "simgrad", prog, _args(checkout, iters=2), [])
    assert r["rc"] == 1 and len(r["losses"]) == 2
    assert r["error"].startswith("ValueError: asked to fail")
    assert "toy.py" in r["at_program"]


def test_a_patch_that_no_longer_applies_is_an_error(checkout):
    prog = originals.Program("toy", "toy.py", patches=[(r"range\(25\)", "range({iters})", "iterations")])
    with pytest.raises(RuntimeError, match="matched 0 times"):
        originals.prepare(prog, checkout, 3)


@pytest.mark.parametrize("line, value", [
    ("Iter= 3 Loss= 0.0051", 0.0051),
    ("Iter 0  Loss = 0.24659", 0.24659),
    ("loss= -0.25 grad= (0.1, 0.2)", -0.25),
    ("i= 1 loss= 1.5e-05  per iter 1.00s", 1.5e-05),
    ("0 loss 2.43", 2.43),
])
def test_loss_lines_of_every_print_format(line, value):
    assert float(originals.LOSS.search(line).group(1)) == value


def test_no_loss_in_kernel_names_or_norms():
    assert originals.LOSS.search("  12.5%  compute_loss_c80_0 1.0 ms") is None
    assert originals.LOSS.search("0.31234") is None
