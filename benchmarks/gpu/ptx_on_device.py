"""Run simgrad-generated PTX on a real GPU through runtime/device.py CudaDriver (issue 22, the H100 check of the
first stage): each kernel is compiled for the CPU (which gives the reference and the context layout), lowered
with GpuCodegen(sim=False) to PTX, loaded, and launched in its launch sequence on device copies of its data.
Prints one line per kernel and exits non-zero on any mismatch. Kernels use ndarray arguments and one field
tree (the roots table is copied to the device)."""

from __future__ import annotations

import sys

import numpy as np

import simgrad as ti
from simgrad.codegen import nvptx
from simgrad.compiler.driver import compile_kernel
from simgrad.lang.program import get_program
from simgrad.runtime import abi, device

N = 1 << 20


def run_on_gpu(dev, kernel, args):
    """Launch `kernel` on the GPU with its numpy array arguments in device memory. Returns ({id(array): the
    GPU's result}, error code, ms); the arrays themselves hold the CPU's result afterwards."""
    prog = get_program()
    prog.jit.cache_enabled = False
    arrays = [a for a in args if isinstance(a, np.ndarray)]
    dptr = {}
    for a in arrays:  # the inputs, before the CPU run changes them in place
        p = dev.alloc(a.nbytes)
        dev.to_device(p, a)
        dptr[a.ctypes.data] = (p, a)
    ck = compile_kernel(kernel, prog, args)
    ptx, launches = nvptx.kernel_ptx(ck.ir, "k")
    fns = dev.load_module(ptx, [ln.symbol for ln in launches])
    ck.launch(*args)  # the CPU result, and the context buffer filled for these arguments
    buf = np.array([dptr[int(w)][0] if int(w) in dptr else w for w in ck.launcher.buf], dtype=np.int64)
    buf = np.concatenate([buf, np.zeros(64, np.int64)])  # the GPU kernels' scratch words (the CPU has none)
    err = dev.alloc(8 * abi.ERR_WORDS)
    dev.to_device(err, np.zeros(abi.ERR_WORDS, np.int64))
    buf[abi.CTX_ERR] = err
    ctx = dev.alloc(buf.nbytes)
    dev.to_device(ctx, buf)
    t0 = dev.event()
    for ln in launches:
        grid = ln.grid if ln.grid is not None else device.saturating_grid(dev, ln.block)
        dev.launch(fns[ln.symbol], grid, ln.block, ctx)
    t1 = dev.event()
    dev.synchronize()
    ms = dev.elapsed_ms(t0, t1)
    out = {}
    for p, a in dptr.values():
        b = np.empty_like(a)
        dev.to_host(b, p)
        out[id(a)] = b
    e = np.zeros(abi.ERR_WORDS, np.int64)
    dev.to_host(e, err)
    return out, int(e[0]), ms


def main() -> int:
    ti.init(arch=ti.cpu, offline_cache=False)
    dev = device.CudaDriver()
    print(f"device: compute capability {dev.compute_capability}, {dev.sm_count} SMs")
    ok = True

    @ti.kernel
    def saxpy(a: ti.f32, x: ti.types.ndarray(dtype=ti.f32, ndim=1), y: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(x.shape[0]):
            y[i] = a * x[i] + ti.sin(y[i])

    @ti.kernel
    def reduce(x: ti.types.ndarray(dtype=ti.f32, ndim=1), s: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(x.shape[0]):
            s[0] += x[i]
            ti.atomic_max(s[1], x[i])

    rng = np.random.default_rng(0)
    x = rng.random(N, dtype=np.float32)
    y = rng.random(N, dtype=np.float32)
    out, code, ms = run_on_gpu(dev, saxpy, (2.0, x, y))
    good = code == 0 and np.allclose(out[id(y)], y, rtol=1e-5, atol=1e-6)
    ok &= good
    print(f"saxpy+sin  n={N}: {'OK' if good else 'MISMATCH'} err={code} {ms:.3f} ms")
    s = np.zeros(2, np.float32)
    out, code, ms = run_on_gpu(dev, reduce, (x, s))
    good = code == 0 and np.allclose(out[id(s)], s, rtol=1e-3)
    ok &= good
    print(f"sum/max    n={N}: {'OK' if good else 'MISMATCH'} err={code} gpu={out[id(s)]} cpu={s} {ms:.3f} ms")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
