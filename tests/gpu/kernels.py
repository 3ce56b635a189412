"""A representative set of kernels (arith, math, atomics, loops, while/break, local matrices, a Tape adjoint with
a serial inner loop, f16, ndarray args, sparse SNodes, a tape deeper than local memory, recursive real functions)
for the GPU tests: each `case` compiles and runs its kernels and returns (result, numpy reference)."""

from __future__ import annotations

import numpy as np

import simgrad as ti

N = 300


def arith_math():
    x = ti.field(ti.f32, shape=N)
    y = ti.field(ti.i32, shape=N)

    @ti.kernel
    def k(a: ti.f32):
        for i in x:
            v = i * a
            x[i] = (ti.sin(v) + ti.cos(v) * ti.exp(-v) + ti.sqrt(v + 1.0) + ti.tanh(v) + ti.atan2(v, 2.0)
                    + ti.tan(v * 0.1))
            y[i] = (i * 7) // 3 - i % 5 + (i << 2) ^ 9

    k(0.01)
    v = np.arange(N, dtype=np.float32) * np.float32(0.01)
    ref = (np.sin(v) + np.cos(v) * np.exp(-v) + np.sqrt(v + 1) + np.tanh(v) + np.arctan2(v, 2)
           + np.tan(v * np.float32(0.1)))
    i = np.arange(N)
    return [(x.to_numpy(), ref, 1e-5), (y.to_numpy(), ((i * 7) // 3 - i % 5 + (i << 2)) ^ 9, 0)]


def registry_math():
    """The registry's C math calls (ir/opdefs.py Libm) map to libdevice on the GPU: f32 and f64."""
    x = ti.field(ti.f32, shape=N)
    y = ti.field(ti.f64, shape=N)

    @ti.kernel
    def k():
        for i in x:
            v = i * 0.01 + 0.1
            x[i] = ti.math.log1p(v) + ti.math.expm1(v) + ti.math.cbrt(v) + ti.math.hypot(v, 2.0) + ti.asin(v * 0.2)
            w = ti.cast(v, ti.f64)
            y[i] = ti.math.log1p(w) + ti.math.cbrt(w) + ti.acos(w * 0.2) + ti.tanh(w)

    k()
    v = np.arange(N, dtype=np.float32) * np.float32(0.01) + np.float32(0.1)
    w = v.astype(np.float64)  # v is computed at f32 in the kernel, then widened
    rx = np.log1p(v) + np.expm1(v) + np.cbrt(v) + np.hypot(v, 2) + np.arcsin(v * np.float32(0.2))
    ry = np.log1p(w) + np.cbrt(w) + np.arccos(w * 0.2) + np.tanh(w)
    return [(x.to_numpy(), rx, 1e-5), (y.to_numpy(), ry, 1e-12)]


def atomics():
    s = ti.field(ti.f32, shape=())
    m = ti.field(ti.f32, shape=())
    mi = ti.field(ti.i32, shape=())
    h = ti.field(ti.i32, shape=7)

    @ti.kernel
    def k():
        m[None] = -1e9
        mi[None] = 1 << 30
        for i in range(N):
            s[None] += i * 0.5
            ti.atomic_max(m[None], ti.sin(i * 1.0))
            ti.atomic_min(mi[None], (i * 37) % 101)
            h[i % 7] += 1

    k()
    i = np.arange(N)
    return [(s[None], (i * 0.5).sum(), 1e-5), (m[None], np.sin(i.astype(np.float32)).max(), 1e-6),
            (mi[None], ((i * 37) % 101).min(), 0), (h.to_numpy(), np.bincount(i % 7), 0)]


def loops_while():
    out = ti.field(ti.i32, shape=N)

    @ti.kernel
    def k():
        for i in range(N):
            n, steps = i + 1, 0
            while True:
                if n == 1:
                    break
                n = n // 2 if n % 2 == 0 else 3 * n + 1
                steps += 1
            acc = 0
            for j in range(i % 5):
                if j == 3:
                    continue
                acc += j
            out[i] = steps * 10 + acc

    def collatz(n):
        s = 0
        while n != 1:
            n = n // 2 if n % 2 == 0 else 3 * n + 1
            s += 1
        return s

    ref = np.array([collatz(i + 1) * 10 + sum(j for j in range(i % 5) if j != 3) for i in range(N)])
    k()
    return [(out.to_numpy(), ref, 0)]


def local_matrix():
    v = ti.Vector.field(3, ti.f32, shape=N)

    @ti.kernel
    def k():
        for i in v:
            A = ti.Matrix([[1.0, 2.0, 0.0], [0.0, 1.0, i * 0.01], [0.5, 0.0, 1.0]])
            b = ti.Vector([i * 1.0, 1.0, 2.0])
            c = A @ b
            for r in ti.static(range(3)):
                c[r] += A.determinant()
            v[i] = c

    k()
    out = []
    for i in range(N):
        A = np.array([[1, 2, 0], [0, 1, i * 0.01], [0.5, 0, 1]], np.float64)
        out.append(A @ np.array([i, 1.0, 2.0]) + np.linalg.det(A))
    return [(v.to_numpy(), np.array(out), 1e-4)]


def tape_adjoint():
    """A Tape adjoint whose parallel loop has a serial inner loop (the adstack), f64, against central
    differences."""
    x = ti.field(ti.f64, shape=16, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            v = x[i]
            for _ in range(i % 4 + 1):
                v = ti.sin(v) * 1.5 + v * v * 0.1
            loss[None] += v

    xs = np.linspace(-1, 1, 16)
    x.from_numpy(xs)
    with ti.ad.Tape(loss=loss):
        f()
    g = x.grad.to_numpy()

    def F(a):
        tot = 0.0
        for i in range(16):
            v = a[i]
            for _ in range(i % 4 + 1):
                v = np.sin(v) * 1.5 + v * v * 0.1
            tot += v
        return tot

    eps = 1e-6
    fd = np.array([(F(xs + eps * np.eye(16)[i]) - F(xs - eps * np.eye(16)[i])) / (2 * eps) for i in range(16)])
    return [(g, fd, 1e-6)]


def half_and_ndarray():
    h = ti.field(ti.f16, shape=N)
    m = ti.field(ti.f16, shape=N)

    @ti.kernel
    def k(a: ti.types.ndarray(dtype=ti.f32, ndim=1), b: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in range(a.shape[0]):
            b[i] = a[i] * 2.0 + 1.0
            h[i] = ti.cast(a[i], ti.f16)
            x16 = ti.cast(a[i], ti.f16)
            m[i] = ti.sqrt(x16) + ti.sin(x16) + ti.sin(a[i]) * 0.0  # f16 and f32 math in one kernel

    a = np.linspace(0, 3, N).astype(np.float32)
    b = np.zeros(N, np.float32)
    k(a, b)
    x16 = a.astype(np.float16).astype(np.float32)
    m_ref = (np.sqrt(x16).astype(np.float16).astype(np.float32) + np.sin(x16).astype(np.float16).astype(np.float32))
    return [(b, a * 2 + 1, 1e-6), (h.to_numpy().astype(np.float32), x16, 0),
            (m.to_numpy().astype(np.float32), m_ref, 4e-3)]


def serial_and_return():
    x = ti.field(ti.f32, shape=N)

    @ti.kernel
    def k(n: ti.i32) -> ti.f32:
        t = 0.0
        for j in range(n):
            x[j] = j * 1.0
        for j in range(3):
            t += x[j + 1]
        t2 = t * 2.0
        for i in range(N):
            x[i] += t2
        return t2

    r = k(N)
    return [(r, 12.0, 0), (x.to_numpy(), np.arange(N, dtype=np.float32) + 12.0, 0)]


def sparse_nodes():
    """pointer / bitmasked / dynamic: activation by writes, struct-fors, deactivation (the pool allocator)."""
    p = ti.field(ti.f32)
    ti.root.pointer(ti.i, 64).dense(ti.i, 4).place(p)
    b = ti.field(ti.i32)
    ti.root.bitmasked(ti.i, N).place(b)
    d = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).dynamic(ti.j, 32).place(d)

    @ti.kernel
    def k() -> ti.types.vector(3, ti.f64):
        for i in range(128):  # distinct cells
            p[i * 2] = i * 1.0
            b[i * 3 % N] = 1
        for i in range(40):
            ti.append(d.parent(), i % 4, i)
        for i in range(16):
            ti.deactivate(p.parent(2), i * 4)
        t = ti.Vector([0.0, 0.0, 0.0], ti.f64)
        for i in p:
            t[0] += p[i]
        for i in b:
            t[1] += b[i]
        for i, j in d:
            t[2] += d[i, j]
        return t

    i = np.arange(128)
    pv = np.zeros(256)
    pv[i * 2] = i
    pv = pv.reshape(64, 4)
    pv[np.arange(64) % 4 == 0] = 0
    want = [pv.sum(), len(set(i * 3 % N)), np.arange(40).sum()]
    return [(k().to_numpy(), want, 0)]


def sin_chain(xs):
    """y = sin(sin(...sin(x))) n times per element, n a run-time argument (so the tape's depth is not static):
    (x, y, f, reference(n) -> (y, dy/dx)) in float64."""
    x = ti.field(ti.f64, shape=len(xs), needs_grad=True)
    y = ti.field(ti.f64, shape=len(xs), needs_grad=True)

    @ti.kernel
    def f(n: ti.i32):
        for i in x:
            v = x[i]
            for _ in range(n):
                v = ti.sin(v)
            y[i] = v

    def reference(n):
        v, d = np.array(xs, np.float64), np.ones(len(xs))
        for _ in range(n):
            d *= np.cos(v)
            v = np.sin(v)
        return v, d

    x.from_numpy(np.asarray(xs, np.float64))
    return x, y, f, reference


def deep_tape():
    """A tape deeper than a GPU thread's local memory (codegen/nvptx.py GPU_TAPE_LIMIT): the device-buffer tape."""
    x, y, f, reference = sin_chain(np.linspace(0.2, 1.0, 8))
    f(1500)
    y.grad.fill(1.0)
    f.grad(1500)
    return [(x.grad.to_numpy(), reference(1500)[1], 1e-9)]


def recursion():
    """Recursive real functions (device functions that call themselves): from a parallel loop, with an atomic
    update and a matrix result, and from serial code (Taichi's test_recursion)."""
    out = ti.field(ti.i32, shape=N)
    calls = ti.field(ti.i32, shape=())
    pw = ti.Vector.field(2, ti.f32, shape=N)
    f = ti.field(ti.i32, shape=100)
    f.from_numpy(np.arange(100, dtype=np.int32))

    @ti.real_func
    def fib(k: ti.i32) -> ti.i32:
        calls[None] += 1
        r = k
        if k >= 2:
            r = fib(k - 1) + fib(k - 2)
        return r

    @ti.real_func
    def power(v: ti.math.vec2, k: ti.i32) -> ti.math.vec2:
        r = ti.math.vec2(1.0, 1.0)
        if k > 0:
            r = v * power(v, k - 1)
        return r

    @ti.real_func
    def total(g: ti.template(), lo: ti.i32, hi: ti.i32) -> ti.i32:
        if lo == hi:
            return g[lo]
        else:
            return total(g, lo, (lo + hi) // 2) + total(g, (lo + hi) // 2 + 1, hi)

    @ti.kernel
    def k() -> ti.i32:
        for i in out:
            out[i] = fib(i % 10)
            pw[i] = power(ti.math.vec2(1.0 + i % 8 * 0.5, 0.5), i % 5)
        return total(f, 0, 99)

    s = k()
    i = np.arange(N)
    fibs = [0, 1]
    ncalls = [1, 1]
    for _ in range(8):
        fibs.append(fibs[-1] + fibs[-2])
        ncalls.append(1 + ncalls[-1] + ncalls[-2])
    base = np.stack([1.0 + i % 8 * 0.5, np.full(N, 0.5)], 1)
    return [(s, 4950, 0), (out.to_numpy(), np.array(fibs)[i % 10], 0),
            (calls[None], np.array(ncalls)[i % 10].sum(), 0), (pw.to_numpy(), base ** (i % 5)[:, None], 1e-6)]


CASES = [arith_math, registry_math, atomics, loops_while, local_matrix, tape_adjoint, half_and_ndarray,
         serial_and_return, sparse_nodes, deep_tape, recursion]
