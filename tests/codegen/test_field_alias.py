"""Field memory facts (codegen/alias.py): stores of distinct dense places carry scoped noalias metadata
(plain loads do not: see the advect test), tree roots are dereferenceable and 64-byte aligned. With them LLVM
hoists a uniform `s[None]` out of a masked loop body and keeps one store per element; without them it gathered
`s[None]` per lane. Results are unchanged where places share a tree or a cell (AoS members, vector
components)."""

import re

import numpy as np

import simgrad as ti
import simgrad.codegen.alias as alias
import simgrad.codegen.llvm as llvm
from simgrad.runtime.jit import get_jit


def _masked_update():
    n = 1024
    m = ti.field(ti.f32, shape=n)
    v = ti.field(ti.f32, shape=n)
    s = ti.field(ti.f32, shape=())
    t = ti.field(ti.f32, shape=())

    @ti.kernel
    def k():
        for i in m:
            if m[i] > 0:
                v[i] = v[i] * s[None]
                v[i] += t[None]

    return k, m, v, s, t


def _task(kernel) -> str:
    opt = str(get_jit()._optimized(kernel._instance_for((), "").llvm_text, 0))
    return opt.split("define internal void @sg_kernel_task1")[1].split("\n}")[0]


def test_uniform_loads_are_hoisted_and_stores_merged(monkeypatch):
    ti.init(arch=ti.cpu, offline_cache=False)
    k, m, v, s, t = _masked_update()
    task = _task(k)
    assert "masked.gather" not in task and "masked.scatter" not in task
    text = k._instance_for((), "").llvm_text
    assert "!alias.scope" in text and "!noalias" in text and "!dereferenceable !{i64 4096}" in text
    ms = np.linspace(-1, 1, 1024, dtype=np.float32)
    vs = np.arange(1024, dtype=np.float32)
    m.from_numpy(ms)
    v.from_numpy(vs)
    s[None], t[None] = 0.5, 3.0
    k()
    np.testing.assert_array_equal(v.to_numpy(), np.where(ms > 0, vs * np.float32(0.5) + np.float32(3), vs))
    # the same kernel without the facts: LLVM gathers s[None] and t[None] per lane (what the facts fix)
    monkeypatch.setattr(alias.MemoryFacts, "access", lambda self, p, ty: "")
    monkeypatch.setattr(llvm, "root_facts", lambda n: "")
    ti.init(arch=ti.cpu, offline_cache=False)
    k2 = _masked_update()[0]
    assert "masked.gather" in _task(k2)


def test_places_sharing_a_tree_and_cells_keep_their_values():
    """AoS members of one dense node, a vector's components, a field and its gradient: each write is seen by
    the reads of the same place after it and by no other place."""
    ti.init(arch=ti.cpu, offline_cache=False)
    n = 64
    a = ti.field(ti.f32)
    b = ti.field(ti.f32)
    ti.root.dense(ti.i, n).place(a, b)
    w = ti.Vector.field(3, ti.f32, shape=n)
    out = ti.field(ti.f32, shape=n)

    @ti.kernel
    def k():
        for i in a:
            a[i] = b[i] + 1.0
            b[i] = a[i] * 2.0
            w[i][0] = a[i]
            w[i][1] = w[i][0] + b[i]
            w[i][2] = w[i][1] - w[i][0]
            out[i] = w[i][2] + a[i] + b[i]

    bs = np.arange(n, dtype=np.float32)
    b.from_numpy(bs)
    k()
    a_ = bs + 1
    b_ = a_ * 2
    np.testing.assert_array_equal(a.to_numpy(), a_)
    np.testing.assert_array_equal(b.to_numpy(), b_)
    np.testing.assert_array_equal(w.to_numpy(), np.stack([a_, a_ + b_, b_], axis=1))
    np.testing.assert_array_equal(out.to_numpy(), b_ + a_ + b_)


def test_ndarray_and_sparse_accesses_get_no_scope():
    """An ndarray may be passed twice and a sparse element is an address a walk computed: no metadata."""
    ti.init(arch=ti.cpu, offline_cache=False)
    x = ti.field(ti.f32)
    ti.root.pointer(ti.i, 4).dense(ti.i, 4).place(x)

    @ti.kernel
    def k(a: ti.types.ndarray(dtype=ti.f32, ndim=1), c: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in a:
            c[i] = a[i] + 1.0
            x[i] = c[i]

    arr = np.arange(16, dtype=np.float32)
    k(arr, arr)  # one array as both arguments
    np.testing.assert_array_equal(arr, np.arange(16, dtype=np.float32) + 1)
    np.testing.assert_array_equal(x.to_numpy(), arr)
    assert "!alias.scope" not in k._instance_for((arr, arr), "").llvm_text


def test_empty_field_root_claims_no_bytes():
    ti.init(arch=ti.cpu, offline_cache=False)
    e = ti.field(ti.f32, shape=0)
    f = ti.Vector.field(2, ti.f32, shape=(3, 5))

    @ti.kernel
    def k():
        for i in e:
            e[i] = 1.0
        for i, j in f:
            f[i, j][1] = 2.0

    k()
    assert alias.field_end(e.ref()) == 0
    assert [alias.field_end(c.ref()) for c in f._components()] == [15 * 8 - 4, 15 * 8]  # AoS: (x, y) per cell
    assert "!dereferenceable !{i64 0}" not in k._instance_for((), "").llvm_text


def test_a_particle_loop_over_a_few_uniform_places_stays_vectorised():
    # vortex_rings' advect: each particle sums over four vortices read from small fields (uniform loads, unrolled)
    # and exp of each. With alias scopes on those plain loads LLVM vectorised the inner sums across vortices instead
    # of the particle loop (advect 4.9 -> 9.8 ms); the particle loop must keep its vector body
    ti.init(arch=ti.cpu, offline_cache=False)
    n_vortex, n = 4, 4096
    pos = ti.Vector.field(2, ti.f32, shape=n_vortex)
    vort = ti.field(ti.f32, shape=n_vortex)
    tracer = ti.Vector.field(2, ti.f32, shape=n)

    @ti.func
    def velocity(p):
        u = ti.Vector([0.0, 0.0])
        for i in range(n_vortex):
            r2 = (p - pos[i]).norm() ** 2
            uv = ti.Vector([pos[i].y - p.y, p.x - pos[i].x])
            u += vort[i] * uv / r2 * (1.0 - ti.exp(-r2 / 0.01))
        return u

    @ti.kernel
    def advect():
        for i in range(n):  # Ralston's third-order step, as vortex_rings takes it
            p = tracer[i]
            v1 = velocity(p)
            v2 = velocity(p + v1 * 0.05)
            v3 = velocity(p + v2 * 0.075)
            tracer[i] += (2 / 9 * v1 + 1 / 3 * v2 + 4 / 9 * v3) * 0.1

    task = _task(advect)
    assert re.search(r"x float> @(llvm\.exp\.v|sg_vm_expf_v)", task), "the particle loop is not vectorised"
    rng = np.random.default_rng(0)
    ps = rng.random((n_vortex, 2)).astype(np.float32)
    vs = rng.random(n_vortex).astype(np.float32)
    ts = (rng.random((n, 2)) + 2.0).astype(np.float32)
    pos.from_numpy(ps)
    vort.from_numpy(vs)
    tracer.from_numpy(ts)
    advect()
    def velocity_np(p):
        u = np.zeros_like(p)
        for k in range(n_vortex):
            r2 = ((p - ps[k]) ** 2).sum(1)
            uv = np.stack([ps[k, 1] - p[:, 1], p[:, 0] - ps[k, 0]], 1)
            u += vs[k] * uv / r2[:, None] * (1.0 - np.exp(-r2 / 0.01))[:, None]
        return u

    p = ts.astype(np.float64)
    v1 = velocity_np(p)
    v2 = velocity_np(p + v1 * 0.05)
    v3 = velocity_np(p + v2 * 0.075)
    np.testing.assert_allclose(tracer.to_numpy(), p + (2 / 9 * v1 + 1 / 3 * v2 + 4 / 9 * v3) * 0.1, rtol=1e-5)
