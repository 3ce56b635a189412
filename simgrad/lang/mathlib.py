"""`ti.math`: GLSL-style helpers over scalars and small vectors (both scopes)."""

from __future__ import annotations

import math as _m

from simgrad.lang import ops
from simgrad.lang.matrix import Matrix
from simgrad.lang.types import matrix as _matrix
from simgrad.lang.types import vector as _vector

pi = _m.pi
e = _m.e
inf = _m.inf
nan = _m.nan

vec2, vec3, vec4 = _vector(2), _vector(3), _vector(4)
ivec2, ivec3, ivec4 = _vector(2, int), _vector(3, int), _vector(4, int)
uvec2, uvec3, uvec4 = _vector(2, "u32"), _vector(3, "u32"), _vector(4, "u32")
mat2, mat3, mat4 = _matrix(2, 2), _matrix(3, 3), _matrix(4, 4)

sqrt, sin, cos, tan, asin, acos, atan2 = ops.sqrt, ops.sin, ops.cos, ops.tan, ops.asin, ops.acos, ops.atan2
exp, log, tanh, floor, ceil, round = ops.exp, ops.log, ops.tanh, ops.floor, ops.ceil, ops.round  # noqa: A001
min, max, abs, pow = ops.min, ops.max, ops.abs, ops.pow  # noqa: A001


def dot(a, b):
    return a.dot(b)


def cross(a, b):
    return a.cross(b)


def length(v):
    return v.norm() if isinstance(v, Matrix) else ops.abs(v)


def distance(a, b):
    return length(a - b)


def normalize(v):
    return v.normalized()


def clamp(x, lo, hi):
    return ops.min(ops.max(x, lo), hi)


def mix(x, y, a):
    return x * (1.0 - a) + y * a


def sign(x):
    return ops.select(ops.gt(x, 0), 1.0, 0.0) - ops.select(ops.lt(x, 0), 1.0, 0.0)


def step(edge, x):
    return ops.select(ops.lt(x, edge), 0.0, 1.0)


def smoothstep(e0, e1, x):
    t = clamp((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def fract(x):
    return x - ops.floor(x)


def mod(x, y):
    return ops.mod(x, y)


def log2(x):
    return ops.log(x) * (1.0 / _m.log(2.0))


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


def cpow(z, n):
    r = z
    for _ in range(n - 1):
        r = cmul(r, z)
    return r
