"""LLVM's SLP vectoriser is off in a kernel whose parallel loop holds a data-dependent (while) loop: it packed the
carried values of such loops (a complex number) into <2 x float> and unpacked them every iteration, which made the
Julia/Mandelbrot examples 1.3-1.4x slower than scalar code (benchmarks/RESULTS.md). Straight-line kernels keep it
(MPM's P2G gains from it). Results are the same either way (no reassociation is involved). A loop that
passes/lanes.py runs in lock step keeps SLP: it vectorises the step's unrolled lane loop."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.runtime.jit import NO_SLP, get_jit


def _text(kernel, *args):
    return kernel._instance_for(args, "").llvm_text


def _optimized(text):
    jit = get_jit()
    return str(jit._optimized(text, 0))


@pytest.mark.parametrize("lanes", [0, 8])
def test_a_while_loop_turns_slp_off_and_the_result_is_the_scalar_one(lanes):
    ti.init(arch=ti.cpu, simt_lanes=lanes)  # 8: the loop runs 8 iterations in lock step (passes/lanes.py)
    n = 64
    out = ti.field(ti.i32, shape=(n, n))

    @ti.kernel
    def julia(cy: ti.f32):
        for i, j in out:
            z = ti.Vector([i / n - 0.5, j / n - 0.5]) * 3
            k = 0
            while z.norm() < 20 and k < 50:
                z = ti.Vector([z[0] ** 2 - z[1] ** 2 - 0.8, 2 * z[0] * z[1] + cy])
                k += 1
            out[i, j] = k

    julia(0.156)
    text = _text(julia, 0.156)
    task = _optimized(text).split("define internal void @sg_kernel_task1")[1].split("\n}")[0]
    if lanes:
        assert NO_SLP not in text and "fmul nsz <8 x float>" in task
    else:
        assert NO_SLP in text and "<2 x float>" not in task
    # numpy in float32, the same operations in the same order
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    zr = ((i / np.float32(n)).astype(np.float32) - np.float32(0.5)) * np.float32(3)
    zi = ((j / np.float32(n)).astype(np.float32) - np.float32(0.5)) * np.float32(3)
    k = np.zeros((n, n), np.int32)
    for _ in range(50):
        live = (np.sqrt(zr * zr + zi * zi) < 20) & (k < 50)
        nr = zr * zr - zi * zi - np.float32(0.8)
        ni = np.float32(2) * zr * zi + np.float32(0.156)
        zr, zi = np.where(live, nr, zr).astype(np.float32), np.where(live, ni, zi).astype(np.float32)
        k += live
    np.testing.assert_array_equal(out.to_numpy(), k)


def test_straight_line_kernels_keep_slp():
    ti.init(arch=ti.cpu)
    x = ti.Vector.field(2, ti.f32, shape=16)

    @ti.kernel
    def rot(c: ti.f32, s: ti.f32):
        for i in x:
            v = x[i]
            x[i] = ti.Vector([c * v[0] - s * v[1], s * v[0] + c * v[1]])

    rot(0.6, 0.8)
    assert NO_SLP not in _text(rot, 0.6, 0.8)
