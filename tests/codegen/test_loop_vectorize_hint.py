"""ti.loop_config(vectorize=True) (simgrad's, not Taichi's) before an inner loop of a few known trips: LLVM leaves
loops of fewer than 16 trips scalar (its tiny-trip-count threshold), the hint (`llvm.loop.vectorize.enable`) makes
them vector code. render2d's short strokes and small circles use it. Results are the scalar loop's bit for bit."""

import numpy as np

import simgrad as ti
from simgrad.runtime.jit import get_jit


def _kernel(hint: bool):
    n = 300
    x = ti.field(ti.f64, shape=(n, 8))
    out = ti.field(ti.f64, shape=(n, 8))

    @ti.kernel
    def k(lo: ti.f64):
        for i in range(n):
            if ti.static(hint):
                ti.loop_config(vectorize=True)
            for d in range(8):
                v = x[i, d]
                out[i, d] = ti.select(v > lo, ti.sqrt(v) * (i + 1.0), v * 0.5 - d)

    x.from_numpy(np.random.default_rng(3).uniform(-1, 4, (n, 8)))
    k(0.5)
    text = k._instance_for((0.5,), "").llvm_text
    return out.to_numpy(), x.to_numpy(), text


def test_the_hint_marks_the_loop_and_keeps_every_bit():
    ti.init(arch=ti.cpu)
    got, xs, text = _kernel(True)
    i = np.arange(300, dtype=np.float64)[:, None]
    d = np.arange(8, dtype=np.float64)[None, :]
    want = np.where(xs > 0.5, np.sqrt(np.maximum(xs, 0)) * (i + 1.0), xs * 0.5 - d)
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    assert '!"llvm.loop.vectorize.enable", i1 true' in text
    opt = str(get_jit()._optimized(text, 0))
    assert "x double>" in opt.split("define internal void @sg_kernel_task1")[1].split("\n}")[0]
    ti.init(arch=ti.cpu)
    plain, _, plain_text = _kernel(False)
    assert "llvm.loop.vectorize.enable" not in plain_text
    np.testing.assert_array_equal(plain.view(np.uint64), got.view(np.uint64))
