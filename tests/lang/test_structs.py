"""Structs as Taichi has them: @ti.dataclass (members, ti.func methods with `self` by reference),
ti.types.struct, ti.Struct.field, struct locals, nested structs, Python-scope element views, dicts in and out
of numpy, user placement with ti.root, and gradients through struct members (checked by finite differences)."""

import numpy as np
import pytest

import simgrad as ti

vec2 = ti.types.vector(2, ti.f64)


@ti.dataclass
class Body:
    pos: vec2
    vel: vec2
    mass: ti.f64

    @ti.func
    def step(self, dt):
        self.pos += self.vel * dt

    @ti.func
    def kinetic(self):
        return 0.5 * self.mass * self.vel.dot(self.vel)


def test_dataclass_fields_methods_and_locals_match_numpy():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    n = 6
    bodies = Body.field(shape=n)
    energy = ti.field(ti.f64, shape=())

    @ti.kernel
    def run(dt: ti.f64):
        for i in bodies:
            bodies[i] = Body(pos=vec2(i, 1.0), vel=vec2(1.0, -i), mass=1.0 + i)
        for i in bodies:
            b = bodies[i]  # a local copy: writing it leaves the field alone until stored back
            b.step(dt)
            b.mass *= 2.0
            bodies[i].pos = b.pos
            energy[None] += b.kinetic()

    run(0.25)
    i = np.arange(n)
    np.testing.assert_allclose(bodies.pos.to_numpy(), np.stack([i + 0.25, 1.0 - 0.25 * i], -1))
    np.testing.assert_allclose(bodies.mass.to_numpy(), 1.0 + i)  # the doubled mass was only local
    assert energy[None] == pytest.approx(np.sum(0.5 * 2 * (1.0 + i) * (1 + i ** 2)))
    assert bodies[2].mass == 3.0 and list(bodies[2].vel) == [1.0, -2.0]
    bodies[2].mass = 9.0  # Python-scope member assignment writes through
    bodies[3].vel[1] = 5.0
    assert bodies.mass.to_numpy()[2] == 9.0 and bodies.vel.to_numpy()[3, 1] == 5.0
    with pytest.raises(AttributeError):
        _ = bodies[0].charge


def test_types_struct_nested_and_struct_field_dicts():
    ti.init(arch=ti.cpu)
    Inner = ti.types.struct(a=ti.i32, b=ti.f32)
    Outer = ti.types.struct(inner=Inner, w=ti.types.vector(3, ti.f32))
    f = Outer.field(shape=(2, 3))
    g = ti.Struct.field({"x": ti.f32, "v": ti.types.vector(2, ti.f32)}, shape=4)

    @ti.kernel
    def fill():
        for i, j in f:
            o = Outer(inner=Inner(a=i * 10 + j, b=0.5), w=ti.Vector([i, j, 1.0]))
            o.inner.b += j
            f[i, j] = o
        for k in g:
            g[k].x = k * 2.0
            g[k].v = ti.Vector([k, -k])

    fill()
    d = f.to_numpy()
    ii, jj = np.meshgrid(np.arange(2), np.arange(3), indexing="ij")
    np.testing.assert_array_equal(d["inner"]["a"], ii * 10 + jj)
    np.testing.assert_array_equal(d["inner"]["b"], 0.5 + jj)
    np.testing.assert_array_equal(d["w"], np.stack([ii, jj, np.ones_like(ii)], -1))
    g.from_numpy({"x": np.arange(4, dtype=np.float32) * 3, "v": np.ones((4, 2), np.float32)})
    assert g[1].x == 3.0 and g.to_numpy()["v"].sum() == 8
    with pytest.raises(ti.SimgradTypeError):
        Outer(nope=1)


def test_user_placed_struct_field_and_gradients_through_members():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    P = ti.types.struct(x=ti.f64, k=ti.f64, tag=ti.i32)
    p = P.field(needs_grad=True)
    ti.root.dense(ti.i, 5).place(p)
    ti.root.lazy_grad()  # placing p does not place its gradients (Taichi's rule: an error at the first kernel)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def compute():
        for i in p:
            loss[None] += p[i].k * ti.sin(p[i].x) * (p[i].tag + 1)

    x0 = np.linspace(0.1, 1.0, 5)
    k0 = np.linspace(2.0, 3.0, 5)
    p.from_numpy({"x": x0, "k": k0, "tag": np.arange(5, dtype=np.int32)})
    with ti.ad.Tape(loss=loss):
        compute()
    t = np.arange(5) + 1
    np.testing.assert_allclose(p.x.grad.to_numpy(), k0 * np.cos(x0) * t, rtol=1e-12)
    np.testing.assert_allclose(p.k.grad.to_numpy(), np.sin(x0) * t, rtol=1e-12)
    eps = 1e-6
    f = lambda x: np.sum(k0 * np.sin(x) * t)  # noqa: E731
    fd = np.array([(f(x0 + eps * np.eye(5)[j]) - f(x0 - eps * np.eye(5)[j])) / (2 * eps) for j in range(5)])
    np.testing.assert_allclose(p.x.grad.to_numpy(), fd, rtol=1e-6)


def test_struct_kernel_arguments_and_returns():
    ti.init(arch=ti.cpu)
    v2 = ti.types.vector(2, ti.f32)
    Inner = ti.types.struct(k=ti.i32, w=ti.f32)
    S = ti.types.struct(p=v2, m=ti.f32, inner=Inner)

    @ti.kernel
    def scale(s: S, f: ti.f32) -> S:
        t = s
        t.p *= f
        t.m += s.inner.w * s.inner.k
        return t

    @ti.kernel
    def total(s: S) -> ti.f32:
        return s.p.sum() + s.m + s.inner.k

    r = scale(S(p=v2(1, 2), m=3.0, inner=Inner(k=2, w=0.5)), 2.0)
    assert list(r.p) == [2.0, 4.0] and r.m == 4.0 and r.inner.k == 2 and r.inner.w == 0.5
    assert total(r) == 12.0
    assert total({"p": [1.0, 1.0], "m": 0.5, "inner": {"k": 3, "w": 0.0}}) == 5.5


def test_struct_values_convert_as_taichi_does():
    """A value given for a struct member goes to its first member (it was dropped: `mystruct(1)` left every
    member 0); a struct of another type given alone is the first member, not a dict of members; struct
    field elements assign from other elements; plain Python methods of a dataclass work on values."""
    vec3f = ti.types.vector(3, float)
    line3f = ti.types.struct(linedir=vec3f, length=float)
    mystruct = ti.types.struct(line=line3f, idx=int)
    s = mystruct(3)
    np.testing.assert_array_equal(s.line.linedir.to_numpy(), 3.0)
    assert s.line.length == 0.0 and s.idx == 0

    @ti.dataclass
    class A:
        i: int
        j: float

        def twice(self):
            return A(self.i * 2, self.j * 2)

    @ti.dataclass
    class B:
        a1: A
        a2: A

    b = B(A(1, 2.0))
    assert (b.a1.i, b.a1.j, b.a2.i) == (1, 2.0, 0)
    assert b.a1.twice().j == 4.0
    x = mystruct.field(shape=4)
    y = line3f.field(shape=4)
    y[2] = line3f(linedir=vec3f(1, 2, 3), length=7.0)
    x[1].line = y[2]
    np.testing.assert_array_equal(x[1].line.linedir.to_numpy(), [1, 2, 3])
    assert x[1].line.length == 7.0
