"""ti.math (GLSL-style helpers, complex numbers as vec2, 4x4 transforms, bit counts) against numpy
formulas, in Python scope and in kernels. Edge conventions are Taichi 1.7's (checked against it):
sign(0) == 0, step(e, e) == 1, csqrt/cpow(0) == 0, Taichi's orientation of rot_by_axis/rot_yaw_pitch_roll."""

import math

import numpy as np
import pytest

import simgrad as ti
import simgrad.lang.mathlib as tm


def _np(m):
    return np.array(m.to_numpy(), dtype=np.float64)


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rodrigues(axis, ang):
    """Right-handed rotation about a unit axis (numpy reference)."""
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K


def _h(r3):
    out = np.eye(4)
    out[:3, :3] = r3
    return out


def test_constants_and_constructors():
    assert ti.math.pi == math.pi and ti.math.e == math.e
    assert ti.math.inf == float("inf") and math.isnan(ti.math.nan)
    assert _np(ti.math.vec3(1, 2, 3)).tolist() == [1.0, 2.0, 3.0]
    assert _np(ti.math.vec2(0.5)).tolist() == [0.5, 0.5]
    assert _np(ti.math.vec3(ti.math.vec2(1, 2), 3)).tolist() == [1.0, 2.0, 3.0]
    assert ti.math.ivec2(1.7, -2.2).to_list() == [1, -2]
    m = ti.math.mat3(1, 2, 3, 4, 5, 6, 7, 8, 9)
    assert m.to_list() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]
    assert ti.math.mat2([[1, 2], [3, 4]]).to_list() == [[1.0, 2.0], [3.0, 4.0]]
    assert ti.math.mat3(ti.math.vec3(1, 0, 0), ti.math.vec3(0, 2, 0), ti.math.vec3(0, 0, 3)).trace() == 6.0
    with pytest.raises(ValueError):
        ti.math.vec3(1, 2)
    np.testing.assert_array_equal(_np(ti.math.eye(3)), np.eye(3))


def test_scalar_helpers_python_scope():
    xs = np.array([-2.5, -1.0, -0.25, 0.0, 0.3, 1.0, 1.75, 4.0])
    for x in xs:
        assert tm.sign(x) == np.sign(x)
        assert tm.step(1.0, x) == (1.0 if x >= 1.0 else 0.0)
        assert tm.fract(x) == pytest.approx(x - np.floor(x))
        assert tm.clamp(x, -1.0, 1.5) == np.clip(x, -1.0, 1.5)
        t = np.clip((x + 1.0) / 3.0, 0, 1)
        assert tm.smoothstep(-1.0, 2.0, x) == pytest.approx(t * t * (3 - 2 * t))
        assert tm.mix(2.0, -4.0, x) == pytest.approx(2.0 * (1 - x) + -4.0 * x)
        assert tm.mod(x, 1.5) == pytest.approx(np.mod(x, 1.5))
    assert tm.step(2.0, 2.0) == 1.0 and tm.sign(0.0) == 0.0 and tm.sign(-3) == -1.0
    assert tm.smoothstep(1.0, 0.0, 0.25) == pytest.approx(0.84375)  # reversed edges, Taichi's value
    assert tm.log2(8.0) == pytest.approx(3.0) and tm.degrees(math.pi) == pytest.approx(180.0)
    assert tm.radians(90.0) == pytest.approx(math.pi / 2)
    assert tm.isinf(math.inf) and not tm.isinf(1.0) and tm.isnan(math.nan) and not tm.isnan(1.0)
    assert tm.mod(-7, 3) == 2 and tm.mod(7, -3) == -2


def test_vector_helpers_python_scope():
    a, b = np.array([1.0, -2.0, 2.0]), np.array([0.5, 4.0, -1.0])
    va, vb = ti.Vector(a.tolist()), ti.Vector(b.tolist())
    assert tm.dot(va, vb) == pytest.approx(a @ b)
    np.testing.assert_allclose(_np(tm.cross(va, vb)), np.cross(a, b))
    assert tm.length(va) == pytest.approx(3.0) and tm.length(-2.0) == 2.0
    assert tm.distance(va, vb) == pytest.approx(np.linalg.norm(a - b))
    np.testing.assert_allclose(_np(tm.normalize(va)), a / 3.0)
    np.testing.assert_allclose(_np(tm.clamp(va, -1.0, 1.5)), np.clip(a, -1.0, 1.5))
    np.testing.assert_allclose(_np(tm.mix(va, vb, 0.25)), a * 0.75 + b * 0.25)
    np.testing.assert_allclose(_np(tm.sign(va)), np.sign(a))
    np.testing.assert_allclose(_np(tm.step(0.0, va)), (a >= 0).astype(float))
    np.testing.assert_allclose(_np(tm.fract(va * 0.7)), a * 0.7 - np.floor(a * 0.7))
    n = np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(_np(tm.reflect(va, ti.Vector(n.tolist()))), a - 2 * (a @ n) * n)
    # refract: GLSL formula; total internal reflection gives the zero vector
    i = np.array([1.0, -1.0, 0.0]) / np.sqrt(2)
    eta = 0.6
    k = 1 - eta**2 * (1 - (n @ i) ** 2)
    want = eta * i - (eta * (n @ i) + np.sqrt(k)) * n
    np.testing.assert_allclose(_np(tm.refract(ti.Vector(i.tolist()), ti.Vector(n.tolist()), eta)), want)
    np.testing.assert_allclose(_np(tm.refract(ti.Vector(i.tolist()), ti.Vector(n.tolist()), 2.0)), 0.0)
    c, s = np.cos(0.3), np.sin(0.3)
    np.testing.assert_allclose(_np(tm.rotation2d(0.3)), [[c, -s], [s, c]])
    M = np.array([[2.0, 1.0], [1.0, 3.0]])
    assert tm.determinant(ti.Matrix(M)) == pytest.approx(5.0)
    np.testing.assert_allclose(_np(tm.inverse(ti.Matrix(M))), np.linalg.inv(M))


def test_complex_python_scope():
    zs = [1.5 - 2.0j, -4.0 + 0.0j, 0.3 + 0.7j, -1.0 - 1e-3j]
    for z in zs:
        v = ti.Vector([z.real, z.imag])
        w = ti.Vector([0.5, 1.0])
        for got, want in [
            (tm.cmul(v, w), z * (0.5 + 1j)), (tm.cdiv(v, w), z / (0.5 + 1j)), (tm.cconj(v), z.conjugate()),
            (tm.cinv(v), 1 / z), (tm.cexp(v), np.exp(z)), (tm.clog(v), np.log(z)), (tm.csqrt(v), np.sqrt(z)),
            (tm.cpow(v, 3), z**3), (tm.cpow(v, 0.5), np.sqrt(z)), (tm.cpow(v, -1.5), z**-1.5),
        ]:
            np.testing.assert_allclose(_np(got), [want.real, want.imag], rtol=1e-12, atol=1e-12)
    zero = ti.Vector([0.0, 0.0])
    assert _np(tm.csqrt(zero)).tolist() == [0.0, 0.0] and _np(tm.cpow(zero, 2)).tolist() == [0.0, 0.0]
    assert _np(tm.cpow(zero, -1)).tolist() == [0.0, 0.0]  # Taichi's convention, no error
    np.testing.assert_allclose(_np(tm.vdir(0.5)), [np.cos(0.5), np.sin(0.5)])


def test_transforms_python_scope():
    np.testing.assert_array_equal(_np(tm.translate(1.0, 2.0, 3.0))[:, 3], [1, 2, 3, 1])
    np.testing.assert_array_equal(_np(tm.scale(2.0, 3.0, 4.0)), np.diag([2.0, 3.0, 4.0, 1.0]))
    axis = np.array([1.0, 2.0, 2.0])
    R = _np(tm.rot_by_axis(ti.Vector(axis.tolist()), 0.7))
    np.testing.assert_allclose(R, _h(_rodrigues(axis, -0.7)), atol=1e-14)  # Taichi's orientation
    np.testing.assert_allclose(R[0, :3], [0.790971, 0.481736, -0.377221], atol=1e-6)  # Taichi's numbers
    Y = _np(tm.rot_yaw_pitch_roll(0.3, 0.5, 0.7))
    np.testing.assert_allclose(Y, _h((_ry(0.3) @ _rx(0.5) @ _rz(0.7)).T), atol=1e-14)
    np.testing.assert_allclose(Y[1, :3], [-0.507082, 0.671212, 0.540687], atol=1e-6)
    np.testing.assert_allclose(_np(tm.rotation3d(0.3, 0.5, 0.7)), _h((_ry(0.7) @ _rx(0.3) @ _rz(0.5)).T),
                               atol=1e-14)


def test_bit_counts_python_scope():
    for x in [0, 1, 7, 255, 65536, -1, -2, 2**31 - 1, -(2**31)]:
        u = x & 0xFFFFFFFF
        assert tm.popcnt(x) == bin(u).count("1")
        assert tm.clz(x) == 32 - u.bit_length()


# -- kernels ----------------------------------------------------------------------------------------------
def test_kernel_helpers_against_numpy():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    xs = np.array([-2.5, -1.0, -0.25, 0.0, 0.3, 1.0, 1.75, 4.0])
    x = ti.field(ti.f64, shape=len(xs))
    x.from_numpy(xs)
    s = ti.field(ti.f64, shape=(len(xs), 8))
    out = ti.field(ti.f64, shape=64)

    @ti.kernel
    def scalars():
        for i in x:
            v = x[i]
            vals = [ti.math.sign(v), ti.math.step(1.0, v), ti.math.fract(v), ti.math.clamp(v, -1.0, 1.5),
                    ti.math.smoothstep(-1.0, 2.0, v), ti.math.mix(2.0, -4.0, v), ti.math.mod(v, 1.5),
                    ti.math.length(v)]
            for j in ti.static(range(8)):
                s[i, j] = vals[j]

    @ti.kernel
    def vectors():
        a = ti.math.vec3(1.0, -2.0, 2.0)
        b = ti.math.vec3(0.5, 4.0, -1.0)
        z = ti.math.vec2(1.5, -2.0)
        w = ti.math.vec2(0.5, 1.0)
        m = ti.math.mat3(2.0, 0.0, 1.0, 1.0, 3.0, 0.0, 0.0, 1.0, 4.0)
        c = ti.math.cross(a, b)
        nrm = ti.math.normalize(a)
        cm, cd, cs, cp = ti.math.cmul(z, w), ti.math.cdiv(z, w), ti.math.csqrt(z), ti.math.cpow(z, 3)
        ce, cl, ci = ti.math.cexp(z), ti.math.clog(z), ti.math.cinv(z)
        R = ti.math.rot_by_axis(ti.math.vec3(1.0, 2.0, 2.0), 0.7)
        Y = ti.math.rot_yaw_pitch_roll(0.3, 0.5, 0.7)
        T = ti.math.translate(1.0, 2.0, 3.0) @ ti.Vector([1.0, 1.0, 1.0, 1.0])
        vals = [ti.math.dot(a, b), c[0], c[1], c[2], ti.math.length(a), ti.math.distance(a, b), nrm[1],
                ti.math.mix(a, b, 0.25)[2], ti.math.clamp(a, -1.0, 1.5)[1], ti.math.sign(a)[1],
                ti.math.step(0.0, a)[1], cm[0], cm[1], cd[0], cd[1], cs[0], cs[1], cp[0], cp[1], ce[0], ce[1],
                cl[0], cl[1], ci[0], ci[1], R[0, 1], R[2, 0], Y[1, 0], Y[1, 2], T[2],
                ti.math.determinant(m), ti.math.inverse(m)[0, 2], ti.math.pi, ti.math.e,
                ti.math.isinf(ti.math.inf), ti.math.isnan(ti.math.nan), ti.math.isinf(m[0, 0]),
                ti.math.log2(8.0), ti.math.radians(180.0), ti.math.degrees(ti.math.pi / 2),
                ti.math.reflect(a, ti.math.vec3(0.0, 1.0, 0.0))[1], ti.math.vdir(0.5)[1],
                ti.math.csqrt(ti.math.vec2(0.0, 0.0))[0], ti.math.rotation2d(0.3)[1, 0]]
        for j in ti.static(range(len(vals))):
            out[j] = vals[j]

    scalars()
    vectors()
    t = np.clip((xs + 1.0) / 3.0, 0, 1)
    want_s = np.stack([np.sign(xs), (xs >= 1.0) * 1.0, xs - np.floor(xs), np.clip(xs, -1.0, 1.5),
                       t * t * (3 - 2 * t), 2.0 * (1 - xs) - 4.0 * xs, np.mod(xs, 1.5), np.abs(xs)], axis=1)
    np.testing.assert_allclose(s.to_numpy(), want_s, rtol=1e-13, atol=1e-13)

    a, b = np.array([1.0, -2.0, 2.0]), np.array([0.5, 4.0, -1.0])
    z, w = 1.5 - 2.0j, 0.5 + 1.0j
    m = np.array([[2.0, 0.0, 1.0], [1.0, 3.0, 0.0], [0.0, 1.0, 4.0]])
    R = _rodrigues(np.array([1.0, 2.0, 2.0]), -0.7)
    Y = (_ry(0.3) @ _rx(0.5) @ _rz(0.7)).T
    want = [a @ b, *np.cross(a, b), 3.0, np.linalg.norm(a - b), a[1] / 3, 0.75 * a[2] + 0.25 * b[2],
            np.clip(a, -1, 1.5)[1], -1.0, 0.0, (z * w).real, (z * w).imag, (z / w).real, (z / w).imag,
            np.sqrt(z).real, np.sqrt(z).imag, (z**3).real, (z**3).imag, np.exp(z).real, np.exp(z).imag,
            np.log(z).real, np.log(z).imag, (1 / z).real, (1 / z).imag, R[0, 1], R[2, 0], Y[1, 0], Y[1, 2],
            4.0,
            np.linalg.det(m), np.linalg.inv(m)[0, 2], math.pi, math.e, 1.0, 1.0, 0.0, 3.0, math.pi, 90.0,
            2.0, np.sin(0.5), 0.0, np.sin(0.3)]
    np.testing.assert_allclose(out.to_numpy()[: len(want)], want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("t", [ti.i32, ti.u32, ti.i64], ids=str)
def test_kernel_bit_counts(t):
    vals = [0, 1, 7, 255, 65536, -1, -2, 2**31 - 1, -(2**31), 12345678]
    bits = 64 if t is ti.i64 else 32
    mask = (1 << bits) - 1
    src = np.array([v & mask for v in vals], dtype=np.uint64).astype(t.np)
    x = ti.field(t, shape=len(vals))
    pc, lz = ti.field(ti.i64, shape=len(vals)), ti.field(ti.i64, shape=len(vals))
    x.from_numpy(src)

    @ti.kernel
    def k():
        for i in x:
            pc[i] = ti.math.popcnt(x[i])
            lz[i] = ti.math.clz(x[i])

    k()
    us = [v & mask for v in vals]
    assert pc.to_numpy().tolist() == [bin(u).count("1") for u in us]
    assert lz.to_numpy().tolist() == [bits - u.bit_length() for u in us]
