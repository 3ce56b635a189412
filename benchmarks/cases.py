"""Benchmark cases, written once against the Taichi API and run under either framework.

    python benchmarks/cases.py --framework simgrad|taichi [--case NAME] [--threads N] [--cache DIR]

Prints one JSON object of measurements. benchmarks/run.py runs this for both frameworks and compares.
"""


import argparse
import json
import os
import time


def _best(fn, repeat=5, number=1):
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t) / number)
    return best


def case_launch(ti):
    x = ti.field(ti.f32, shape=())

    @ti.kernel
    def tiny(a: ti.f32):
        x[None] = a

    tiny(1.0)
    n = 20000
    return {"launch_us": 1e6 * _best(lambda: tiny(1.0), repeat=5, number=n)}


def case_pyscope(ti):
    x = ti.field(ti.f32, shape=())
    x[None] = 1.0
    n = 20000

    def rw():
        x[None] = x[None] + 1.0

    return {"pyscope_rw_us": 1e6 * _best(rw, repeat=5, number=n) / 2}


def case_saxpy(ti):
    n = 10_000_000
    a = ti.field(ti.f32, shape=n)
    b = ti.field(ti.f32, shape=n)

    @ti.kernel
    def saxpy(s: ti.f32):
        for i in a:
            b[i] = s * a[i] + b[i]

    saxpy(2.0)
    ti.sync()

    def run():
        saxpy(2.0)
        ti.sync()

    t = _best(run, repeat=10)
    return {"saxpy_GBps": 3 * 4 * n / t / 1e9}


def _p2g_kernel(ti, n_particles, n_grid):
    dx = 1.0 / n_grid
    inv_dx = float(n_grid)
    x = ti.Vector.field(2, ti.f32, shape=n_particles)
    v = ti.Vector.field(2, ti.f32, shape=n_particles)
    grid_v = ti.Vector.field(2, ti.f32, shape=(n_grid, n_grid))
    grid_m = ti.field(ti.f32, shape=(n_grid, n_grid))

    @ti.kernel
    def p2g():
        for p in x:
            base = ti.cast(x[p] * inv_dx - 0.5, ti.i32)
            fx = x[p] * inv_dx - ti.cast(base, ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    offset = ti.Vector([i, j])
                    weight = w[i][0] * w[j][1]
                    grid_v[base + offset] += weight * v[p]
                    grid_m[base + offset] += weight

    return x, v, grid_v, grid_m, p2g, dx


def case_scatter(ti):
    import numpy as np

    n, g = 1_000_000, 256
    x, v, grid_v, grid_m, p2g, dx = _p2g_kernel(ti, n, g)
    rng = np.random.default_rng(0)
    x.from_numpy((rng.random((n, 2)) * 0.8 + 0.1).astype(np.float32))
    v.from_numpy(rng.standard_normal((n, 2)).astype(np.float32))
    p2g()
    ti.sync()

    def run():
        p2g()
        ti.sync()

    return {"scatter_ms": 1e3 * _best(run, repeat=5)}


def _mpm_p2g(ti, n_particles=8192, n_grid=128, steps=4, needs_grad=True):
    """A diffmpm-sized p2g kernel (MLS-MPM with polar decomposition, per-step particle state)."""
    dt, dx, inv_dx = 1e-4, 1.0 / n_grid, float(n_grid)
    p_vol, p_mass, mu, la = 1.0, 1.0, 10.0, 10.0
    x = ti.Vector.field(2, ti.f32, shape=(steps, n_particles), needs_grad=needs_grad)
    v = ti.Vector.field(2, ti.f32, shape=(steps, n_particles), needs_grad=needs_grad)
    C = ti.Matrix.field(2, 2, ti.f32, shape=(steps, n_particles), needs_grad=needs_grad)
    F = ti.Matrix.field(2, 2, ti.f32, shape=(steps, n_particles), needs_grad=needs_grad)
    grid_v = ti.Vector.field(2, ti.f32, shape=(n_grid, n_grid), needs_grad=needs_grad)
    grid_m = ti.field(ti.f32, shape=(n_grid, n_grid), needs_grad=needs_grad)

    @ti.kernel
    def p2g(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_F = (ti.Matrix.diag(dim=2, val=1) + dt * C[f, p]) @ F[f, p]
            J = new_F.determinant()
            F[f + 1, p] = new_F
            r, s = ti.polar_decompose(new_F)
            cauchy = 2 * mu * (new_F - r) @ new_F.transpose() + ti.Matrix.diag(2, la * (J - 1) * J)
            stress = -(dt * p_vol * 4 * inv_dx * inv_dx) * cauchy
            affine = stress + p_mass * C[f, p]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    offset = ti.Vector([i, j])
                    dpos = (ti.cast(offset, ti.f32) - fx) * dx
                    weight = w[i][0] * w[j][1]
                    grid_v[base + offset] += weight * (p_mass * v[f, p] + affine @ dpos)
                    grid_m[base + offset] += weight * p_mass

    return x, v, C, F, grid_v, grid_m, p2g


def case_compile(ti):
    fields = _mpm_p2g(ti)
    p2g = fields[-1]
    _init_mpm(fields)
    t = time.perf_counter()
    p2g(0)
    ti.sync()
    first = time.perf_counter() - t
    t = time.perf_counter()
    p2g.grad(0)
    ti.sync()
    grad_first = time.perf_counter() - t
    return {"compile_p2g_s": first, "compile_p2g_grad_s": grad_first}


def _init_mpm(fields):
    import numpy as np

    x, v, C, F = fields[:4]
    steps, n = x.shape
    rng = np.random.default_rng(0)
    x.from_numpy((rng.random((steps, n, 2)) * 0.5 + 0.25).astype(np.float32))
    v.from_numpy(rng.standard_normal((steps, n, 2)).astype(np.float32))
    F.from_numpy(np.broadcast_to(np.eye(2, dtype=np.float32), (steps, n, 2, 2)).copy())


def case_mpm_step(ti):
    fields = _mpm_p2g(ti, n_particles=100_000, n_grid=256)
    p2g = fields[-1]
    _init_mpm(fields)
    p2g(0)
    p2g.grad(0)
    ti.sync()

    def fwd():
        p2g(0)
        ti.sync()

    def bwd():
        p2g.grad(0)
        ti.sync()

    tf, tb = _best(fwd, repeat=5), _best(bwd, repeat=5)
    return {"p2g_fwd_ms": 1e3 * tf, "p2g_bwd_ms": 1e3 * tb, "p2g_bwd_over_fwd": tb / tf}


def case_threads(ti):
    n = 4_000_000
    y = ti.field(ti.f32, shape=n)

    @ti.kernel
    def heavy():
        for i in y:
            s = 0.0
            t = ti.cast(i, ti.f32) * 1e-6
            for k in range(64):
                s += ti.sin(t + k * 0.01)
            y[i] = s

    heavy()
    ti.sync()

    def run():
        heavy()
        ti.sync()

    return {"compute_ms": 1e3 * _best(run, repeat=3)}


CASES = {name[5:]: fn for name, fn in globals().items() if name.startswith("case_")}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--framework", choices=["simgrad", "taichi"], required=True)
    p.add_argument("--case", action="append")
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--cache", default=None, help="offline cache folder (enables the cache)")
    args = p.parse_args()
    if args.framework == "taichi":
        import taichi as ti
    else:
        import simgrad as ti
    kw = {"arch": ti.cpu, "offline_cache": args.cache is not None}
    if args.cache:
        kw["offline_cache_file_path"] = args.cache
    if args.threads:
        kw["cpu_max_num_threads"] = args.threads
    out = {}
    for name in args.case or list(CASES):
        ti.init(**kw)
        t0 = time.perf_counter()
        out.update(CASES[name](ti))
        out[f"{name}_total_s"] = time.perf_counter() - t0
    print("RESULT " + json.dumps(out))


if __name__ == "__main__":
    os.environ.setdefault("TI_LOG_LEVEL", "warn")
    main()
