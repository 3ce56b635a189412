"""Issue 23's "show" benchmarks: ti.algorithms (parallel_sort, PrefixSumExecutor) and quantized fields, side by
side with taichi 1.7.4 (CPU) and numpy, in one run.

    python benchmarks/algorithms_quant.py [--taichi-python PY] [--runs 3] [--markdown] [--tiny]

Like benchmarks/run.py + cases.py: every (framework, case) runs in a fresh process of this same file
(`--child FRAMEWORK --case NAME`), the case text written once against the Taichi API (`ti` is taichi or simgrad;
"numpy" runs the numpy equivalent). The parent runs the cases `--runs` times interleaved and reports medians with
the load average. Each child checks its result against numpy and fails loudly when wrong, so a wrong sort or scan
never shows up as a number. Field memory is the frameworks' own layout report (`SNode._cell_size_bytes`, Taichi's
layout-inspection API), not an estimate.

Taichi 1.7.4's PrefixSumExecutor raises on the CPU ("Arch.x64 is not supported for prefix sum"), so its scan
column shows that instead of a time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time

HERE = os.path.abspath(__file__)
SIZES = {"sort_n": 10_000_000, "scan_n": 100_000_000, "mpm_particles": 262_144, "mpm_grid": 256, "mpm_steps": 10}
TINY = {"sort_n": 50_000, "scan_n": 300_000, "mpm_particles": 2048, "mpm_grid": 32, "mpm_steps": 2}


# ---------------------------------------------------------------------------------------------- child cases
def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def _keys(n):
    import numpy as np

    return np.random.default_rng(0).integers(-(2**31), 2**31 - 1, n, dtype=np.int32)


def _sort(ti, np, size, values: bool):
    """10M random i32 keys (optionally with i32 values = indices) in fields (Taichi 1.7.4's parallel_sort takes
    fields only: its kernels take ti.template()). The first sort compiles for these fields; the keys are then
    loaded again and the second sort is timed."""
    n = size["sort_n"]
    keys_np = _keys(n)
    vals_np = np.arange(n, dtype=np.int32)
    if ti is None and not values:  # np.sort is the reference itself
        return {"ms": 1e3 * _timed(lambda: np.sort(keys_np))}
    expect = np.sort(keys_np)
    if ti is None:  # numpy: np.sort, or a stable argsort and two gathers for keys + values
        out = {}

        def run():
            order = np.argsort(keys_np, kind="stable")
            out["k"], out["v"] = keys_np[order], vals_np[order]
        t = _timed(run)
        got_k, got_v = out["k"], out["v"]
    else:
        k, v = ti.field(ti.i32, n), ti.field(ti.i32, n)

        def load():
            k.from_numpy(keys_np)
            v.from_numpy(vals_np)
            ti.sync()

        def run():
            ti.algorithms.parallel_sort(k, v if values else None)
            ti.sync()
        load()
        run()
        load()
        t = _timed(run)
        got_k, got_v = k.to_numpy(), (v.to_numpy() if values else None)
    if not np.array_equal(got_k, expect):
        raise AssertionError("sorted keys differ from np.sort")
    if got_v is not None:  # a permutation that carries each key's index with it (taichi's sort is not stable)
        seen = np.zeros(n, dtype=bool)
        seen[got_v] = True
        if not seen.all() or not np.array_equal(keys_np[got_v], expect):
            raise AssertionError("values were not moved with their keys")
    return {"ms": 1e3 * t}


def case_sort_keys(ti, np, size):
    return _sort(ti, np, size, values=False)


def case_sort_kv(ti, np, size):
    return _sort(ti, np, size, values=True)


def case_scan(ti, np, size):
    """Inclusive prefix sum of 100M i32 in place (an ndarray; i32 wraps on overflow in all three)."""
    n = size["scan_n"]
    if ti is not None:
        small = ti.ndarray(ti.i32, 1024)  # compiles the kernels: one compile serves every ndarray
        try:
            ti.algorithms.PrefixSumExecutor(1024).run(small)
        except RuntimeError as e:  # taichi 1.7.4 on the CPU
            return {"error": str(e)}
    a_np = np.random.default_rng(1).integers(0, 100, n, dtype=np.int32)
    if ti is None:  # np.cumsum is the reference itself
        return {"ms": 1e3 * _timed(lambda: np.cumsum(a_np, dtype=np.int32))}
    expect = np.cumsum(a_np, dtype=np.int32)
    a = ti.ndarray(ti.i32, n)
    a.from_numpy(a_np)
    ex = ti.algorithms.PrefixSumExecutor(n)
    ti.sync()

    def run():
        ex.run(a)
        ti.sync()
    t = _timed(run)
    got = a.to_numpy()
    if not np.array_equal(got, expect):
        raise AssertionError("prefix sum differs from np.cumsum")
    return {"ms": 1e3 * t}


def case_quant_bytes(ti, np, size):
    """Bytes per cell of the quantized layouts in Taichi's quant.md, as the framework lays them out."""
    q = ti.types.quant
    out = {}
    i16 = q.int(bits=16)
    a, b = ti.field(i16), ti.field(i16)
    pack = ti.BitpackedFields(max_num_bits=32)
    pack.place(a, b)
    d = ti.root.dense(ti.i, 16)
    d.place(pack)
    out["int16x2"] = d._cell_size_bytes
    # quant.md's Q of euler.py: a 4-vector of quant.float(exp=8, frac=14) sharing one exponent, in 64 bits
    Q = ti.Vector.field(4, dtype=q.float(exp=8, frac=14))
    pack = ti.BitpackedFields(max_num_bits=64)
    pack.place(Q, shared_exponent=True)
    d = ti.root.dense(ti.ij, (16, 16))
    d.place(pack)
    out["float_shared4"] = d._cell_size_bytes
    Qf = ti.Vector.field(4, dtype=ti.f32)
    d = ti.root.dense(ti.ij, (16, 16))
    d.place(Qf)
    out["f32x4"] = d._cell_size_bytes
    # a 10-bit fixed (|x| <= 20) and a 5-bit unsigned int with a 15-bit float in one u32
    fx, u5, fl = ti.field(q.fixed(bits=10, max_value=20.0)), ti.field(q.int(5, False)), ti.field(q.float(5, 10))
    pack = ti.BitpackedFields(max_num_bits=32)
    pack.place(fx, u5, fl)
    d = ti.root.dense(ti.i, 16)
    d.place(pack)
    out["fixed_int_float"] = d._cell_size_bytes
    # quant_array: 8 x u4 in one u32 (a histogram's bins); bytes of one dense cell = 8 elements
    bins = ti.field(q.int(bits=4, signed=False))
    d = ti.root.dense(ti.i, 64)
    d.quant_array(ti.i, 8, max_num_bits=32).place(bins)
    out["u4x8_array"] = d._cell_size_bytes

    @ti.kernel
    def fill():
        for i in bins:
            bins[i] = i % 16
        for i in range(16):
            fx[i] = -3.25
            Q[i, 0] = ti.Vector([1.5, -0.25, 1e-3, 2.0])
    fill()
    got = np.array([bins[i] for i in range(0, 512, 7)])  # element access (taichi's to_numpy refuses quant types)
    if not np.array_equal(got, np.arange(0, 512, 7) % 16) or abs(fx[3] + 3.25) > 0.04 or abs(Q[0, 0][0] - 1.5) > 1e-3:
        raise AssertionError("quantized fields do not hold their values")
    return out


def _mpm(ti, quant: bool, n_particles: int, n_grid: int):
    """mpm88 (Taichi's example: weakly compressible fluid, MLS-MPM, APIC) with its particle state in one dense
    AoS node: f32 fields, or quantized as Taichi's quant.md / QuanTaichi's MPM do: positions as 21-bit fixed
    point and J as a 22-bit fixed point in one u64, velocity as two 13-bit floats sharing a 6-bit exponent in a
    u64, the affine matrix C as four 14-bit floats sharing an 8-bit exponent in a u64: 24 bytes a particle
    against 36 (three u64 cells; 20 bytes of state would still be padded to 24 by the u64s' alignment). The grid
    stays f32 (its atomic adds would be non-atomic on quant floats, as Taichi demotes them)."""
    dx, inv_dx = 1.0 / n_grid, float(n_grid)
    dt = 2e-4 * 128 / n_grid
    p_vol, p_rho = (dx * 0.5) ** 2, 1.0
    p_mass, E, gravity = p_vol * p_rho, 400.0, 9.8
    particles = ti.root.dense(ti.i, n_particles)
    if quant:
        q = ti.types.quant
        x = ti.Vector.field(2, dtype=q.fixed(bits=21, signed=False, max_value=1.0))
        J = ti.field(dtype=q.fixed(bits=22, signed=False, max_value=4.0))
        v = ti.Vector.field(2, dtype=q.float(exp=8, frac=24))
        C = ti.Matrix.field(2, 2, dtype=q.float(exp=8, frac=14))
        xj = ti.BitpackedFields(max_num_bits=64)
        xj.place(x)
        xj.place(J)
        vb = ti.BitpackedFields(max_num_bits=64)
        vb.place(v, shared_exponent=True)
        cb = ti.BitpackedFields(max_num_bits=64)
        cb.place(C, shared_exponent=True)
        particles.place(xj, vb, cb)
    else:
        x, v = ti.Vector.field(2, ti.f32), ti.Vector.field(2, ti.f32)
        C, J = ti.Matrix.field(2, 2, ti.f32), ti.field(ti.f32)
        particles.place(x, v, C, J)
    grid_v = ti.Vector.field(2, ti.f32, shape=(n_grid, n_grid))
    grid_m = ti.field(ti.f32, shape=(n_grid, n_grid))

    out_x, out_J = ti.Vector.field(2, ti.f32, shape=n_particles), ti.field(ti.f32, shape=n_particles)

    @ti.kernel
    def init():  # from out_x: the same start in both frameworks (ti.random's streams differ)
        for p in range(n_particles):
            x[p] = out_x[p]
            v[p] = [0.0, -1.0]
            J[p] = 1.0
            C[p] = ti.Matrix.zero(ti.f32, 2, 2)

    @ti.kernel
    def substep():
        for i, j in grid_m:
            grid_v[i, j] = [0.0, 0.0]
            grid_m[i, j] = 0.0
        for p in range(n_particles):
            Xp = x[p] * inv_dx
            base = ti.cast(Xp - 0.5, ti.i32)
            fx = Xp - ti.cast(base, ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            stress = -dt * 4 * E * p_vol * (J[p] - 1) * inv_dx * inv_dx
            affine = ti.Matrix([[stress, 0.0], [0.0, stress]]) + p_mass * C[p]
            vp = v[p]
            for i, j in ti.static(ti.ndrange(3, 3)):
                offset = ti.Vector([i, j])
                dpos = (ti.cast(offset, ti.f32) - fx) * dx
                weight = w[i][0] * w[j][1]
                grid_v[base + offset] += weight * (p_mass * vp + affine @ dpos)
                grid_m[base + offset] += weight * p_mass
        for i, j in grid_m:
            if grid_m[i, j] > 0:
                grid_v[i, j] /= grid_m[i, j]
            grid_v[i, j][1] -= dt * gravity
            if i < 3 and grid_v[i, j][0] < 0:
                grid_v[i, j][0] = 0.0
            if i > n_grid - 3 and grid_v[i, j][0] > 0:
                grid_v[i, j][0] = 0.0
            if j < 3 and grid_v[i, j][1] < 0:
                grid_v[i, j][1] = 0.0
            if j > n_grid - 3 and grid_v[i, j][1] > 0:
                grid_v[i, j][1] = 0.0
        for p in range(n_particles):
            Xp = x[p] * inv_dx
            base = ti.cast(Xp - 0.5, ti.i32)
            fx = Xp - ti.cast(base, ti.f32)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.Vector.zero(ti.f32, 2)
            new_C = ti.Matrix.zero(ti.f32, 2, 2)
            for i, j in ti.static(ti.ndrange(3, 3)):
                offset = ti.Vector([i, j])
                dpos = (ti.cast(offset, ti.f32) - fx) * dx
                weight = w[i][0] * w[j][1]
                g_v = grid_v[base + offset]
                new_v += weight * g_v
                new_C += 4 * weight * g_v.outer_product(dpos) * inv_dx * inv_dx
            new_x = x[p] + dt * new_v
            new_J = J[p] * (1 + dt * new_C.trace())
            v[p] = new_v
            x[p] = new_x
            J[p] = new_J
            C[p] = new_C

    @ti.kernel
    def read_back():  # to f32 fields (taichi's to_numpy refuses quant types)
        for p in range(n_particles):
            out_x[p] = x[p]
            out_J[p] = J[p]

    return particles, out_x, out_J, read_back, init, substep


def _mpm_case(ti, np, size, quant: bool):
    n, g, steps = size["mpm_particles"], size["mpm_grid"], size["mpm_steps"]
    particles, out_x, out_J, read_back, init, substep = _mpm(ti, quant, n, g)
    out_x.from_numpy((np.random.default_rng(2).random((n, 2)) * 0.4 + 0.2).astype(np.float32))
    init()
    substep()  # compiles
    ti.sync()
    times = []
    for _ in range(steps):
        times.append(_timed(lambda: (substep(), ti.sync())))
    read_back()
    pos = out_x.to_numpy()
    if not (np.isfinite(pos).all() and (pos > 0).all() and (pos < 1).all()):
        raise AssertionError("particles left the box or became NaN")
    per_particle = particles._cell_size_bytes
    grid_bytes = g * g * 3 * 4  # grid_v, grid_m: f32 in both variants
    return {"ms": 1e3 * statistics.median(times), "particle_bytes": per_particle,
            "field_MB": (per_particle * n + grid_bytes) / 2**20, "mean_y": float(pos[:, 1].mean()),
            "mean_J": float(out_J.to_numpy().mean())}


def case_mpm_quant(ti, np, size):
    return _mpm_case(ti, np, size, quant=True)


def case_mpm_f32(ti, np, size):
    return _mpm_case(ti, np, size, quant=False)


CASES = {name[5:]: fn for name, fn in globals().items() if name.startswith("case_")}
NUMPY_CASES = ("sort_keys", "sort_kv", "scan")


def child(framework: str, case: str, tiny: bool) -> None:
    import numpy as np

    if framework == "numpy":
        ti = None
    else:
        if framework == "taichi":
            import taichi as ti
        else:
            import simgrad as ti
        ti.init(arch=ti.cpu, offline_cache=False, random_seed=0)
    out = CASES[case](ti, np, TINY if tiny else SIZES)
    print("RESULT " + json.dumps(out))


# ---------------------------------------------------------------------------------------------- parent
def _env() -> dict:
    env = dict(os.environ, TI_LOG_LEVEL="error")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def run_child(python: str, framework: str, case: str, tiny: bool) -> dict:
    cmd = [python, HERE, "--child", framework, "--case", case] + (["--tiny"] if tiny else [])
    proc = subprocess.run(cmd, capture_output=True, text=True, env=_env(), timeout=900)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"{framework}/{case} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")


ROWS = [  # (label, case, metric, lower is better)
    ("parallel_sort 10M i32 keys (ms)", "sort_keys", "ms"),
    ("parallel_sort 10M i32 keys + i32 values (ms)", "sort_kv", "ms"),
    ("PrefixSumExecutor 100M i32 (ms)", "scan", "ms"),
    ("quantized MPM step, 262k particles, 256^2 grid (ms)", "mpm_quant", "ms"),
    ("same step, f32 fields (ms)", "mpm_f32", "ms"),
    ("quantized MPM particle (bytes)", "mpm_quant", "particle_bytes"),
    ("f32 MPM particle (bytes)", "mpm_f32", "particle_bytes"),
    ("quantized MPM fields, particles + grid (MiB)", "mpm_quant", "field_MB"),
    ("f32 MPM fields, particles + grid (MiB)", "mpm_f32", "field_MB"),
    ("quantized MPM mean y after the steps", "mpm_quant", "mean_y"),
    ("f32 MPM mean y after the steps", "mpm_f32", "mean_y"),
    ("quant.int(16) x2 bit struct (bytes/cell)", "quant_bytes", "int16x2"),
    ("fixed(10) + int(5) + float(5, 10) in a u32 (bytes/cell)", "quant_bytes", "fixed_int_float"),
    ("4 x quant.float(8, 14), shared exponent (bytes/cell)", "quant_bytes", "float_shared4"),
    ("4 x f32 (bytes/cell)", "quant_bytes", "f32x4"),
    ("quant_array 8 x u4 in a u32 (bytes per 8 elements)", "quant_bytes", "u4x8_array"),
]


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--child", choices=["simgrad", "taichi", "numpy"])
    p.add_argument("--case", action="append", help=f"one of {sorted(CASES)} (repeatable; default all)")
    p.add_argument("--taichi-python", default=os.environ.get("TAICHI_PYTHON"))
    p.add_argument("--frameworks", default="simgrad,taichi,numpy")
    p.add_argument("--runs", type=int, default=3, help="interleaved runs of every case; medians are reported")
    p.add_argument("--tiny", action="store_true", help="small sizes (a smoke test, not a benchmark)")
    p.add_argument("--markdown", action="store_true", help="the table is always markdown (as run.py takes it)")
    p.add_argument("--json", help="write every run's raw results here")
    args = p.parse_args()
    if args.child:
        return child(args.child, args.case[0], args.tiny)
    cases = args.case or list(CASES)
    pythons = {"simgrad": sys.executable, "taichi": args.taichi_python, "numpy": sys.executable}
    fws = [f for f in args.frameworks.split(",") if pythons.get(f)]
    raw: dict[str, list] = {}
    loads = [os.getloadavg()[0]]
    t0 = time.time()
    for _ in range(args.runs):
        for case in cases:
            for fw in fws:
                if fw == "numpy" and case not in NUMPY_CASES:
                    continue
                try:
                    res = run_child(pythons[fw], fw, case, args.tiny)
                except Exception as e:  # a failing framework must not hide the others' numbers
                    print(f"warning: {e}", file=sys.stderr)
                    res = {"error": str(e).splitlines()[0]}
                raw.setdefault(f"{fw}/{case}", []).append(res)
                loads.append(os.getloadavg()[0])
    if args.json:
        with open(args.json, "w") as f:
            json.dump(raw, f, indent=1)

    def med(fw, case, metric):
        vals = [r[metric] for r in raw.get(f"{fw}/{case}", []) if metric in r]
        return statistics.median(vals) if vals else None

    def cell(fw, case, metric):
        v = med(fw, case, metric)
        if v is not None:
            return f"{v:.4g}"
        errs = [r["error"] for r in raw.get(f"{fw}/{case}", []) if "error" in r]
        return f"raises: {errs[0]}" if errs else "-"

    def ratio(a, b):
        return f"{a / b:.3g}" if a is not None and b else "-"

    print(f"{time.strftime('%Y-%m-%d %H:%M')} on {platform.machine()} {os.cpu_count()} cores, python "
          f"{platform.python_version()}; {args.runs} interleaved runs, medians; load average (1 min) "
          f"{min(loads):.1f}-{max(loads):.1f}; {time.time() - t0:.0f} s")
    print("| case | simgrad | taichi 1.7.4 | numpy | simgrad/taichi | simgrad/numpy |\n|---|---|---|---|---|---|")
    for label, case, metric in ROWS:
        if case not in cases:
            continue
        s, t, n = (med(fw, case, metric) if fw in fws else None for fw in ("simgrad", "taichi", "numpy"))
        numpy_cell = cell("numpy", case, metric) if case in NUMPY_CASES and "numpy" in fws else "-"
        print(f"| {label} | {cell('simgrad', case, metric)} | {cell('taichi', case, metric)} | {numpy_cell} "
              f"| {ratio(s, t)} | {ratio(s, n)} |")
    failed = [k for k, rs in raw.items() if any("error" in r and "not supported for prefix sum" not in r["error"]
                                                 for r in rs)]
    if failed:
        print(f"FAILED: {', '.join(failed)}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
