"""The real-GPU runtime of arch=cuda (runtime/gpu_launch.py over CudaDriver, fields in managed memory), run on a
GPU by benchmarks/gpu/run_on_device.sh with SIMGRAD_CUDA_RUNTIME=1: a few kernels against numpy (fields, an
ndarray, a returned reduction, a Tape gradient, sparse pointer and bitmasked fields), then launch overhead and a
1M-element saxpy in us per launch, the figures to put beside taichi's CUDA backend; then asynchronous launches,
staged numpy arguments and the profiler from CUDA events. Prints one line per check; exits non-zero on any failure.
On the simulated GPU: SIMGRAD_GPU_SIM=async SIMGRAD_RUNTIME_N=20000 python benchmarks/gpu/runtime_on_device.py"""

from __future__ import annotations

import os
import sys
import time
import traceback

import numpy as np

import simgrad as ti

N = int(os.environ.get("SIMGRAD_RUNTIME_N", 1 << 20))  # smaller for a run on the simulated GPU


def checks() -> list[tuple[str, bool, str]]:
    out = []
    x = ti.field(ti.f32, shape=N)
    y = ti.field(ti.f32, shape=N)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)
    w = ti.field(ti.f32, shape=1000, needs_grad=True)
    a = ti.ndarray(ti.f32, 1000)

    @ti.kernel
    def saxpy(s: ti.f32):
        for i in x:
            y[i] = s * x[i] + y[i]

    @ti.kernel
    def total() -> ti.f32:
        t = 0.0
        for i in y:
            t += y[i]
        return t

    @ti.kernel
    def fill_nd(arr: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(1000):
            arr[i] = ti.sin(ti.cast(i, ti.f32))

    @ti.kernel
    def energy():
        for i in w:
            loss[None] += w[i] * w[i] * 0.5 + ti.exp(0.001 * w[i])

    xs = np.random.default_rng(0).random(N).astype(np.float32)
    x.from_numpy(xs)
    y.fill(1.0)
    saxpy(2.0)
    out.append(("saxpy on fields", np.allclose(y.to_numpy(), 2 * xs + 1, rtol=1e-6), ""))
    got, want = total(), float((2 * xs.astype(np.float64) + 1).sum())
    out.append(("returned reduction", abs(got - want) / want < 1e-4, f"{got} vs {want}"))
    fill_nd(a)
    out.append(("ndarray argument", np.allclose(a.to_numpy(), np.sin(np.arange(1000, dtype=np.float32)), atol=1e-6),
                ""))
    ws = np.linspace(-1, 1, 1000).astype(np.float32)
    w.from_numpy(ws)
    with ti.ad.Tape(loss=loss):
        energy()
    out.append(("Tape gradient", np.allclose(w.grad.to_numpy(), ws + 0.001 * np.exp(0.001 * ws), rtol=1e-5), ""))
    out += sparse_checks()
    out += async_checks(x, y, xs)
    return out


def sparse_checks() -> list[tuple[str, bool, str]]:
    """Pools in device memory (Device.reserve), blocks zeroed by the GPU allocator, activation from 100k threads."""
    n = 100_000
    p = ti.field(ti.f32)
    ti.root.pointer(ti.i, n // 8).dense(ti.i, 8).place(p)
    b = ti.field(ti.i32)
    ti.root.bitmasked(ti.i, n).place(b)

    @ti.kernel
    def fill():
        for i in range(n):
            if i % 3 == 0:
                p[i] = 1.0
                b[i] = 2

    @ti.kernel
    def count() -> ti.types.vector(2, ti.f64):
        sp, sb = 0.0, 0.0
        for i in p:
            sp += 1.0 + 0 * p[i]
        for i in b:
            sb += b[i]
        return ti.Vector([sp, sb])

    @ti.kernel
    def drop():
        for i in range(n // 8):
            if i % 2 == 0:
                ti.deactivate(p.parent(2), i)

    fill()
    got = count().to_numpy()
    blocks = (np.arange(n) % 3 == 0).reshape(-1, 8).any(axis=1)
    want = [blocks.sum() * 8, 2 * (n + 2) // 3]
    out = [("sparse activation and struct-for", np.allclose(got, want), f"{got} vs {want}")]
    drop()
    fill()
    vals = p.to_numpy()
    out.append(("sparse deactivate, reuse, to_numpy", np.array_equal(vals, (np.arange(n) % 3 == 0).astype(np.float32)),
                ""))
    return out


def async_checks(x, y, xs) -> list[tuple[str, bool, str]]:
    """Asynchronous launches (cuMemcpyHtoDAsync of the context, cuLaunchKernel, no wait) and Taichi's
    synchronisation at Python-scope access; numpy arguments staged (cuMemAlloc, cuMemcpyHtoDAsync,
    cuCtxSynchronize, cuMemcpyDtoH, cuMemFree)."""
    from simgrad.lang.program import get_program

    out = []
    dev = get_program().device

    @ti.kernel
    def slow(s: ti.f32):
        for i in x:
            v = x[i]
            for _ in range(200):
                v = ti.sin(v) * s + 0.5
            y[i] = v

    @ti.kernel
    def bump(a: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(a.shape[0]):
            a[i] = a[i] * 2.0 + y[i]

    slow(1.0)
    queued = dev.pending or not dev.asynchronous  # (a synchronous simulated GPU never queues)
    ref = xs.copy()
    for _ in range(200):
        ref = np.sin(ref) * np.float32(1.0) + np.float32(0.5)
    got = y.to_numpy()
    out.append(("launch does not wait; to_numpy synchronizes", queued and not dev.pending and
                np.allclose(got, ref, rtol=1e-4, atol=1e-5), f"pending after launch: {queued}"))
    slow(1.0)
    y[0] = -1.0  # after the queued kernel's write
    out.append(("element write after a queued kernel", y[0] == -1.0, ""))
    h = np.ones(1000, np.float32)
    bump(h)
    want = 2.0 + got[:1000]
    want[0] = 1.0  # y[0] = -1 above
    out.append(("numpy argument copied in and back", np.allclose(h, want, rtol=1e-5), ""))
    slow(1.0)
    ti.sync()
    out.append(("ti.sync", not dev.pending, ""))
    return out


def profiler_checks() -> list[tuple[str, bool, str]]:
    """ti.profiler from CUDA events (cuEventCreate, cuEventRecord, cuEventSynchronize, cuEventElapsedTime,
    cuEventDestroy); the profiled launches do not wait."""
    from simgrad.lang.program import get_program

    ti.init(arch=ti.cuda, kernel_profiler=True)
    dev = get_program().device
    x = ti.field(ti.f32, shape=N)

    @ti.kernel
    def heavy():
        for i in x:
            v = 0.0
            for j in range(100):
                v += ti.sin(v + j)
            x[i] = v

    for _ in range(5):
        heavy()
    queued = dev.pending or not dev.asynchronous  # (a synchronous simulated GPU never queues)
    r = ti.profiler.query_kernel_profiler_info("heavy")
    ti.profiler.print_kernel_profiler_info()
    ti.profiler.clear_kernel_profiler_info()
    return [("profiler from CUDA events", queued and r.counter == 5 and 0 < r.min <= r.avg <= r.max,
             f"counter {r.counter}, avg {r.avg:.4f} ms, pending after launches: {queued}")]


def timings() -> list[str]:
    x = ti.field(ti.f32, shape=N)
    y = ti.field(ti.f32, shape=N)

    @ti.kernel
    def saxpy(s: ti.f32):
        for i in x:
            y[i] = s * x[i] + ti.sin(y[i])

    @ti.kernel
    def tiny():
        y[0] += 1.0

    lines = []
    for k, args in ((saxpy, (2.0,)), (tiny, ())):
        k(*args)
        ti.sync()
        t = time.perf_counter()
        for _ in range(1000):
            k(*args)
        ti.sync()
        lines.append(f"simgrad cuda {k.__name__}: {(time.perf_counter() - t) * 1e3:.4f} us/launch (1000 launches)")
    return lines


def main() -> int:
    ti.init(arch=ti.cuda)
    arch = ti.lang.impl.current_cfg().arch
    print(f"arch: {arch}; device: {ti.lang.program.get_program().device.name}")
    if arch is not ti.cuda:
        print("FAIL: arch=cuda fell back (is SIMGRAD_CUDA_RUNTIME=1 set and cuda-python installed?)")
        return 1
    failed = 0
    try:
        for name, ok, detail in checks():
            failed += not ok
            print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")
        for line in timings():
            print(line)
        for name, ok, detail in profiler_checks():
            failed += not ok
            print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")
    except Exception:
        traceback.print_exc()
        return 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
