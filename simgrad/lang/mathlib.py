"""`ti.math`: GLSL-style helpers over scalars and small vectors (both scopes).

Formulas follow Taichi's documented semantics (e.g. sign(0) == 0, step(e, e) == 1, refract returns 0
under total internal reflection, the transform helpers give 4x4 homogeneous matrices); unlike Taichi,
they also work in Python scope. Results keep the precision of their inputs."""

from __future__ import annotations

import math as _m
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from simgrad import dtypes as _dt
from simgrad.lang import ops
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix
from simgrad.lang.types import matrix as _matrix
from simgrad.lang.types import vector as _vector

pi = _m.pi
e = _m.e
inf = _m.inf
nan = _m.nan

vec2, vec3, vec4 = _vector(2), _vector(3), _vector(4)
ivec2, ivec3, ivec4 = _vector(2, int), _vector(3, int), _vector(4, int)
uvec2, uvec3, uvec4 = _vector(2, _dt.u32), _vector(3, _dt.u32), _vector(4, _dt.u32)
mat2, mat3, mat4 = _matrix(2, 2), _matrix(3, 3), _matrix(4, 4)

# the registry's math functions exported under ti.math (ir/opdefs.py: sqrt, sin, ..., atan2, ...)
globals().update(ops.math_functions("math"))
floor, ceil, round = ops.floor, ops.ceil, ops.round  # noqa: A001
min, max, abs, pow = ops.min, ops.max, ops.abs, ops.pow  # noqa: A001
if TYPE_CHECKING:
    def __getattr__(name: str) -> Callable[..., Any]:
        """The registry's functions set above, for the type checker."""


def dot(a, b):
    return a.dot(b)


def cross(a, b):
    return a.cross(b)


def length(v):
    return v.norm() if isinstance(v, Matrix) else ops.abs(v)


def distance(a, b):
    return length(a - b)


def normalize(v):
    return v / v.norm()


def clamp(x, lo, hi):
    return ops.min(ops.max(x, lo), hi)


def mix(x, y, a):
    return x * (1.0 - a) + y * a


def sign(x):
    return ops.select(ops.gt(x, 0), 1.0, 0.0) - ops.select(ops.lt(x, 0), 1.0, 0.0)


def step(edge, x):
    return ops.select(ops.ge(x, edge), 1.0, 0.0)


def smoothstep(e0, e1, x):
    t = clamp((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def fract(x):
    return x - ops.floor(x)


def mod(x, y):
    return ops.mod(x, y)


def log2(x):
    return ops.log(x) / _m.log(2.0)


def exp2(x):
    return ops.exp(x * _m.log(2.0))


def reflect(i, n):
    return i - 2.0 * n.dot(i) * n


def refract(i, n, eta):
    cos_i = -i.dot(n)
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    return ops.select(ops.lt(k, 0.0), 0.0 * i, eta * i + (eta * cos_i - ops.sqrt(ops.max(k, 0.0))) * n)


def radians(deg):
    return deg * (_m.pi / 180.0)


def degrees(rad):
    return rad * (180.0 / _m.pi)


def isinf(x):
    return ops.eq(ops.abs(x), _m.inf)


def isnan(x):
    return ops.ne(x, x)


def determinant(m):
    return m.determinant()


def inverse(m):
    return m.inverse()


def eye(n):
    return Matrix([[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)])


def rotation2d(ang):
    c, s = ops.cos(ang), ops.sin(ang)
    return Matrix([[c, -s], [s, c]])


def cmul(a, b):
    return Matrix([a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0]])


def cconj(a):
    return Matrix([a[0], -a[1]])


def cdiv(a, b):
    d = b.dot(b)
    return Matrix([(a[0] * b[0] + a[1] * b[1]) / d, (a[1] * b[0] - a[0] * b[1]) / d])


def cinv(z):
    return cconj(z) / z.dot(z)


def _polar(z):
    """(z != 0, |z|^2, arg z), with z == 0 replaced by 1 inside so that neither the value nor the
    derivative of the untaken branch is infinite (pow(0, -k), atan2(0, 0)'s 0/0)."""
    nz = ops.bit_or(ops.ne(z[0], 0), ops.ne(z[1], 0))
    x, y = ops.select(nz, z[0], 1.0), ops.select(nz, z[1], 0.0)
    return nz, x * x + y * y, ops.atan2(y, x)


def cpow(z, n):
    """z**n for a real (not only integer) exponent, in polar form; 0 for z == 0, as Taichi."""
    nz, r2, a = _polar(z)
    r = ops.pow(r2, n / 2.0)
    return Matrix([ops.select(nz, r * ops.cos(a * n), 0.0), ops.select(nz, r * ops.sin(a * n), 0.0)])


def csqrt(z):
    """The principal square root (non-negative real part); csqrt(0) == 0."""
    nz, r2, a = _polar(z)
    r = ops.sqrt(ops.sqrt(r2))
    return Matrix([ops.select(nz, r * ops.cos(a / 2.0), 0.0), ops.select(nz, r * ops.sin(a / 2.0), 0.0)])


def cexp(z):
    r = ops.exp(z[0])
    return Matrix([r * ops.cos(z[1]), r * ops.sin(z[1])])


def clog(z):
    """The principal logarithm: argument in (-pi, pi]."""
    return Matrix([ops.log(z.dot(z)) / 2.0, ops.atan2(z[1], z[0])])


def vdir(ang):
    """The unit 2D vector at angle `ang`."""
    return Matrix([ops.cos(ang), ops.sin(ang)])


# -- 4x4 homogeneous transforms --------------------------------------------------------------------------
def _homogeneous(r3):
    return Matrix([[*r3[0], 0.0], [*r3[1], 0.0], [*r3[2], 0.0], [0.0, 0.0, 0.0, 1.0]])


def translate(dx, dy, dz):
    return Matrix([[1.0, 0.0, 0.0, dx], [0.0, 1.0, 0.0, dy], [0.0, 0.0, 1.0, dz], [0.0, 0.0, 0.0, 1.0]])


def scale(sx, sy, sz):
    return Matrix([[sx, 0.0, 0.0, 0.0], [0.0, sy, 0.0, 0.0], [0.0, 0.0, sz, 0.0], [0.0, 0.0, 0.0, 1.0]])


def rot_by_axis(axis, ang):
    """Rotation about `axis` (normalised here) by `ang`, with Taichi's orientation: the transpose of the
    right-handed Rodrigues matrix, i.e. c I + (1 - c) a a^T - s [a]x."""
    a = axis / axis.norm()
    c, s = ops.cos(ang), ops.sin(ang)
    x, y, z = a[0], a[1], a[2]
    k = 1.0 - c
    return _homogeneous([
        [c + k * x * x, k * x * y + s * z, k * x * z - s * y],
        [k * x * y - s * z, c + k * y * y, k * y * z + s * x],
        [k * x * z + s * y, k * y * z - s * x, c + k * z * z],
    ])


def _rx(a):
    c, s = ops.cos(a), ops.sin(a)
    return Matrix([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a):
    c, s = ops.cos(a), ops.sin(a)
    return Matrix([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a):
    c, s = ops.cos(a), ops.sin(a)
    return Matrix([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_yaw_pitch_roll(yaw, pitch, roll):
    """Euler rotation, Taichi's convention: (Ry(yaw) Rx(pitch) Rz(roll))^T as a 4x4 matrix."""
    r = (_ry(yaw) @ _rx(pitch) @ _rz(roll)).transpose()
    return _homogeneous([[r[i, j] for j in range(3)] for i in range(3)])


def rotation3d(ang_x, ang_y, ang_z):
    """Taichi's rotation3d: rot_yaw_pitch_roll(ang_z, ang_x, ang_y)."""
    return rot_yaw_pitch_roll(ang_z, ang_x, ang_y)


# -- bit counting -----------------------------------------------------------------------------------------
_UNSIGNED = {_dt.i8: _dt.u8, _dt.i16: _dt.u16, _dt.i32: _dt.u32, _dt.i64: _dt.u64}


def _popcnt_bits(x, bits):
    """SWAR population count of an unsigned kernel value of `bits` (32 or 64) bits."""
    m1, m2, m4 = (0x5555555555555555, 0x3333333333333333, 0x0F0F0F0F0F0F0F0F)
    mask = (1 << bits) - 1
    x = x - ops.bit_and(ops.shr(x, 1), m1 & mask)
    x = ops.bit_and(x, m2 & mask) + ops.bit_and(ops.shr(x, 2), m2 & mask)
    x = ops.bit_and(x + ops.shr(x, 4), m4 & mask)
    return ops.shr(x * (0x0101010101010101 & mask), bits - 8)


def _bits_of(x):
    if isinstance(x, Expr):
        if x.dtype.is_float or x.dtype.bits not in (32, 64):
            raise TypeError(f"popcnt/clz take a 32- or 64-bit integer, got {x.dtype}")
        return x.dtype.bits
    return _dt.Defaults.ip.bits


def popcnt(x):
    """Number of set bits (of the two's complement pattern), in x's type."""
    if isinstance(x, Matrix):
        return x._like([popcnt(e) for e in x.entries])
    bits = _bits_of(x)
    if not isinstance(x, Expr):
        return bin(int(x) & ((1 << bits) - 1)).count("1")
    return _as(_popcnt_bits(_as(x, _UNSIGNED.get(x.dtype, x.dtype)), bits), x.dtype)


def clz(x):
    """Number of leading zero bits (32 for 0 in 32 bits), in x's type."""
    if isinstance(x, Matrix):
        return x._like([clz(e) for e in x.entries])
    bits = _bits_of(x)
    if not isinstance(x, Expr):
        return bits - (int(x) & ((1 << bits) - 1)).bit_length()
    y = _as(x, _UNSIGNED.get(x.dtype, x.dtype))
    k = 1
    while k < bits:  # smear the highest set bit downwards; then clz = bits - popcount
        y = ops.bit_or(y, ops.shr(y, k))
        k *= 2
    return _as(bits - _popcnt_bits(y, bits), x.dtype)


def _as(x, t):
    return x if x.dtype is t else ops.bit_cast(x, t)
