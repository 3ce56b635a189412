"""Quantized values through kernels, written so that the same code runs under real Taichi 1.7.4 and simgrad.

`cases(ti)` stores lists of values into quant fields in one kernel and reads them back (int wrap-around, fixed
rounding, float rounding / flush-to-zero / exponent overflow, shared exponents) and runs atomics. The values
recorded in tests/lang/test_quant.py EXPECTED come from Taichi:

    cd tests/lang && /work/tivenv/bin/python quant_reference.py
"""

import numpy as np


def cases(ti) -> dict:
    """{case name: values read back} (fields are made in the current program: call after ti.init)."""
    out: dict = {}

    def roundtrip(qtype, values, src_dtype=ti.f32, bits=32, other=None):
        n = len(values)
        x = ti.field(dtype=qtype)
        members = [x]
        if other is not None:
            y = ti.field(dtype=other)
            members.append(y)
        bp = ti.BitpackedFields(max_num_bits=bits)
        bp.place(*members)
        ti.root.dense(ti.i, n).place(bp)
        src = ti.field(src_dtype, shape=n)
        dst = ti.field(ti.f64, shape=n)
        src.from_numpy(np.array(values, dtype=np.float32 if src_dtype == ti.f32 else np.int64))

        @ti.kernel
        def go():
            for i in range(n):
                x[i] = src[i]
            for i in range(n):
                dst[i] = x[i]
        go()
        return dst.to_numpy().tolist()

    out["int5"] = roundtrip(ti.types.quant.int(5, True), [0, 1, -1, 15, -16, 16, 20, -17, 100, -100], ti.i32)
    out["uint3"] = roundtrip(ti.types.quant.int(3, False), [0, 1, 7, 8, 9, -1, -8], ti.i32)
    out["int7_f"] = roundtrip(ti.types.quant.int(7, True), [10.3, -10.3, 10.7, -10.7, 63.9, 64.2], ti.f32)
    fx = [0.0, 0.3, -0.3, 1.99, -2.0, 2.5, -2.5, 0.0078125, -0.0078125, 0.0234375, 1.0, -1.0, 0.015625 * 3.5]
    out["fixed8"] = roundtrip(ti.types.quant.fixed(bits=8, max_value=2), fx)
    out["ufixed8"] = roundtrip(ti.types.quant.fixed(bits=8, signed=False, max_value=2),
                               [v for v in fx if v >= 0] + [-0.3])
    out["fixed13s"] = roundtrip(ti.types.quant.fixed(bits=13, scale=0.1),
                                [0.7, 1.2, -0.35, 0.25, -0.25, 409.5, 409.6, -409.6])
    fl = [0.0, 1.0, -1.0, 1.5, 3.14159, -3.14159, 1e-3, 1e-6, 1e-9, 65504.0, 70000.0, 1e10, 0.1, -0.1, 2.0**-14,
          2.0**-15, 1.0009765625, 1.00048828125]
    out["float5_10"] = roundtrip(ti.types.quant.float(exp=5, frac=10), fl, other=ti.types.quant.int(10, True))
    out["ufloat5_11"] = roundtrip(ti.types.quant.float(exp=5, frac=11, signed=False), [abs(v) for v in fl])
    out["float8_24"] = roundtrip(ti.types.quant.float(exp=8, frac=24), fl + [1e30, -1e-30, 3.4e38])

    # shared exponent pairs
    def shared(values_a, values_b, signed_b):
        n = len(values_a)
        a = ti.field(dtype=ti.types.quant.float(exp=6, frac=10, signed=False))
        b = ti.field(dtype=ti.types.quant.float(exp=6, frac=14, signed=signed_b))
        bp = ti.BitpackedFields(max_num_bits=32)
        bp.place(a, b, shared_exponent=True)
        ti.root.dense(ti.i, n).place(bp)
        sa = ti.field(ti.f32, shape=n)
        sb = ti.field(ti.f32, shape=n)
        da = ti.field(ti.f64, shape=n)
        db = ti.field(ti.f64, shape=n)
        da2 = ti.field(ti.f64, shape=n)
        sa.from_numpy(np.array(values_a, np.float32))
        sb.from_numpy(np.array(values_b, np.float32))

        @ti.kernel
        def go():
            for i in range(n):
                a[i] = sa[i]
            for i in range(n):
                da2[i] = a[i]
            for i in range(n):
                b[i] = sb[i]
            for i in range(n):
                da[i] = a[i]
                db[i] = b[i]
        go()
        return [da2.to_numpy().tolist(), da.to_numpy().tolist(), db.to_numpy().tolist()]

    va = [0.0, 1.0, 3.2, 100.0, 0.27, 1000.0, 5.0, 0.001, 7.0, 0.0]
    vb = [0.0, 0.25, 0.25, 0.25, 1e-6, 1000.0, -3.0, 123.0, -0.0001, 5.5]
    out["shared_u"] = shared(va, [abs(v) for v in vb], False)
    out["shared_s"] = shared(va, vb, True)

    # stores to members of one cell in a row are fused (one shared exponent for the new values); a read of the
    # cell between them ends the fusion (each store then recodes the other's rounded digits)
    def fused(read_between: bool):
        vals = np.random.default_rng(3).standard_normal((64, 2)).astype(np.float32) * np.float32(7.0)
        v = ti.Vector.field(2, dtype=ti.types.quant.float(exp=6, frac=9))
        bp = ti.BitpackedFields(max_num_bits=32)
        bp.place(v, shared_exponent=True)
        ti.root.dense(ti.i, 64).place(bp)
        src = ti.Vector.field(2, ti.f32, shape=64)
        seen = ti.field(ti.f32, shape=64)
        back = ti.Vector.field(2, ti.f64, shape=64)
        src.from_numpy(vals)

        @ti.kernel
        def go():
            for i in range(64):
                v[i][0] = src[i][0]
                if ti.static(read_between):
                    seen[i] = v[i][0]
                v[i][1] = src[i][1]
            for i in range(64):
                back[i] = v[i]

        go()
        return back.to_numpy().tolist()

    out["fused"] = fused(False)
    out["not_fused"] = fused(True)

    # atomics: many iterations onto one quant int, neighbours in a quant_array, max/min
    x = ti.field(dtype=ti.types.quant.int(13, True))
    y = ti.field(dtype=ti.types.quant.int(5, True))
    z = ti.field(dtype=ti.types.quant.fixed(bits=14, scale=0.01))
    bp = ti.BitpackedFields(max_num_bits=32)
    bp.place(x, y, z)
    ti.root.place(bp)
    m = ti.field(dtype=ti.types.quant.int(10, True))
    bp2 = ti.BitpackedFields(max_num_bits=16)
    bp2.place(m)
    ti.root.dense(ti.i, 4).place(bp2)
    fl_ = ti.field(dtype=ti.types.quant.float(exp=6, frac=13))
    bp3 = ti.BitpackedFields(max_num_bits=32)
    bp3.place(fl_)
    ti.root.place(bp3)

    @ti.kernel
    def atom():
        for _ in range(1000):
            x[None] += 3
            y[None] -= 1
            z[None] += 0.013
        for i in range(400):
            m[i % 4] += i - 200
        for _ in range(1):
            fl_[None] += 1.5
            fl_[None] -= 0.25
    atom()
    out["atomics"] = [x[None], y[None], z[None], [m[i] for i in range(4)], fl_[None]]

    return out


if __name__ == "__main__":
    import taichi

    taichi.init(arch=taichi.cpu, offline_cache=False)
    print(repr(cases(taichi)))
