"""`ti.math`: GLSL-style helpers over scalars and small vectors (both scopes).

Formulas follow Taichi's documented semantics (e.g. sign(0) == 0, step(e, e) == 1, refract returns 0
under total internal reflection, the transform helpers give 4x4 homogeneous matrices); unlike Taichi,
they also work in Python scope. Results keep the precision of their inputs."""

from __future__ import annotations

import math as _m
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from simgrad import dtypes as _dt
from simgrad.lang import operators
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
# unsigned of default_ip's width (u32, or u64 after ti.init(default_ip=ti.i64)), as Taichi's
uvec2, uvec3, uvec4 = _vector(2, _dt.default_up), _vector(3, _dt.default_up), _vector(4, _dt.default_up)
mat2, mat3, mat4 = _matrix(2, 2), _matrix(3, 3), _matrix(4, 4)

# the registry's math functions exported under ti.math (ir/opdefs.py: sqrt, sin, ..., atan2, ...)
globals().update(operators.math_functions("math"))
floor, ceil, round = operators.floor, operators.ceil, operators.round  # noqa: A001
min, max, abs, pow = operators.min, operators.max, operators.abs, operators.pow  # noqa: A001
if TYPE_CHECKING:
    def __getattr__(name: str) -> Callable[..., Any]:
        """The registry's functions set above, for the type checker."""


def dot(a, b):
    return a.dot(b)


def cross(a, b):
    return a.cross(b)


def length(v):
    return v.norm() if isinstance(v, Matrix) else operators.abs(v)


def distance(a, b):
    return length(a - b)


def normalize(v):
    return v / v.norm()


def clamp(x, lo, hi):
    return operators.min(operators.max(x, lo), hi)


def mix(x, y, a):
    return x * (1.0 - a) + y * a


def sign(x):
    return operators.select(operators.gt(x, 0), 1.0, 0.0) - operators.select(operators.lt(x, 0), 1.0, 0.0)


def step(edge, x):
    return operators.select(operators.ge(x, edge), 1.0, 0.0)


def smoothstep(e0, e1, x):
    t = clamp((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def fract(x):
    return x - operators.floor(x)


def mod(x, y):
    return operators.mod(x, y)


def log2(x):
    return operators.log(x) / _m.log(2.0)


def exp2(x):
    return operators.exp(x * _m.log(2.0))


def reflect(i, n):
    return i - 2.0 * n.dot(i) * n


def refract(i, n, eta):
    cos_i = -i.dot(n)
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    refracted = eta * i + (eta * cos_i - operators.sqrt(operators.max(k, 0.0))) * n
    return operators.select(operators.lt(k, 0.0), 0.0 * i, refracted)


def radians(deg):
    return deg * (_m.pi / 180.0)


def degrees(rad):
    return rad * (180.0 / _m.pi)


def isinf(x):
    return operators.eq(operators.abs(x), _m.inf)


def isnan(x):
    return operators.ne(x, x)


def determinant(m):
    return m.determinant()


def inverse(m):
    return m.inverse()


def eye(n):
    return Matrix([[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)])


def rotation2d(ang):
    c, s = operators.cos(ang), operators.sin(ang)
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
    nz = operators.bit_or(operators.ne(z[0], 0), operators.ne(z[1], 0))
    x, y = operators.select(nz, z[0], 1.0), operators.select(nz, z[1], 0.0)
    return nz, x * x + y * y, operators.atan2(y, x)


def cpow(z, n):
    """z**n for a real (not only integer) exponent, in polar form; 0 for z == 0, as Taichi."""
    nz, r2, a = _polar(z)
    r = operators.pow(r2, n / 2.0)
    return Matrix([operators.select(nz, r * operators.cos(a * n), 0.0),
                   operators.select(nz, r * operators.sin(a * n), 0.0)])


def csqrt(z):
    """The principal square root (non-negative real part); csqrt(0) == 0."""
    nz, r2, a = _polar(z)
    r = operators.sqrt(operators.sqrt(r2))
    return Matrix([operators.select(nz, r * operators.cos(a / 2.0), 0.0),
                   operators.select(nz, r * operators.sin(a / 2.0), 0.0)])


def cexp(z):
    r = operators.exp(z[0])
    return Matrix([r * operators.cos(z[1]), r * operators.sin(z[1])])


def clog(z):
    """The principal logarithm: argument in (-pi, pi]."""
    return Matrix([operators.log(z.dot(z)) / 2.0, operators.atan2(z[1], z[0])])


def vdir(ang):
    """The unit 2D vector at angle `ang`."""
    return Matrix([operators.cos(ang), operators.sin(ang)])


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
    c, s = operators.cos(ang), operators.sin(ang)
    x, y, z = a[0], a[1], a[2]
    k = 1.0 - c
    return _homogeneous([
        [c + k * x * x, k * x * y + s * z, k * x * z - s * y],
        [k * x * y - s * z, c + k * y * y, k * y * z + s * x],
        [k * x * z + s * y, k * y * z - s * x, c + k * z * z],
    ])


def _rx(a):
    c, s = operators.cos(a), operators.sin(a)
    return Matrix([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a):
    c, s = operators.cos(a), operators.sin(a)
    return Matrix([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a):
    c, s = operators.cos(a), operators.sin(a)
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
    x = x - operators.bit_and(operators.shr(x, 1), m1 & mask)
    x = operators.bit_and(x, m2 & mask) + operators.bit_and(operators.shr(x, 2), m2 & mask)
    x = operators.bit_and(x + operators.shr(x, 4), m4 & mask)
    return operators.shr(x * (0x0101010101010101 & mask), bits - 8)


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
        y = operators.bit_or(y, operators.shr(y, k))
        k *= 2
    return _as(bits - _popcnt_bits(y, bits), x.dtype)


def _as(x, t):
    return x if x.dtype is t else operators.bit_cast(x, t)
