"""The software renderer behind ``canvas.scene(scene)``: simgrad kernels rasterise particles, triangles
and lines into a z-buffer, then shade every covered pixel.

Visibility is one packed 64-bit key per pixel, ``depth bits << 32 | primitive id``, lowered with
``ti.atomic_min``: a positive float32's bits order like the float, so the smallest key is the nearest
primitive (ties go to the lower id, so the picture does not depend on thread timing).  Primitive ids
are global over the frame: particles first, then triangles, then line segments.  Shading reads the
winner's attributes back through its id, so each pixel is lit once however many primitives overlap.

Lighting follows Taichi's GGUI shaders: colour * (ambient + sum over point lights of light colour *
max(n . l, 0)), |n . l| for two-sided meshes, unlit lines; normals are interpolated per pixel.

Every kernel takes ndarrays only (no fields), so nothing lands in the user's SNode tree and the kernels
re-instantiate themselves on whatever program ``ti.init`` made last.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

import simgrad as ti

__all__ = ["EMPTY", "Frame", "depth_buffer", "nonempty", "render"]

EMPTY = np.iinfo(np.int64).max
_ID_MASK = 0xFFFFFFFF

if TYPE_CHECKING:  # kernel parameter annotations are simgrad types, opaque to mypy
    vec3: TypeAlias = Any
    _F1: TypeAlias = Any
    _F2: TypeAlias = Any
    _V1: TypeAlias = Any
    _V2: TypeAlias = Any
    _P1: TypeAlias = Any
    _T1: TypeAlias = Any
    _S1: TypeAlias = Any
    _D2: TypeAlias = Any
    _I1D: TypeAlias = Any
    _I32: TypeAlias = Any
    _F32: TypeAlias = Any
else:
    vec3 = ti.types.vector(3, ti.f32)
    _F1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
    _F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    _V1 = ti.types.ndarray(dtype=vec3, ndim=1)
    _V2 = ti.types.ndarray(dtype=vec3, ndim=2)
    _P1 = ti.types.ndarray(dtype=ti.types.vector(4, ti.f32), ndim=1)
    _T1 = ti.types.ndarray(dtype=ti.types.vector(3, ti.i32), ndim=1)
    _S1 = ti.types.ndarray(dtype=ti.types.vector(2, ti.i32), ndim=1)
    _D2 = ti.types.ndarray(dtype=ti.i64, ndim=2)
    _I1D = ti.types.ndarray(dtype=ti.i32, ndim=1)
    _I32 = ti.i32
    _F32 = ti.f32

# Layout of the camera array (float32): view matrix rows 0-2 (world -> camera space, camera looks
# down -z), then screen mapping px = SX * x / w + OX, py = SY * y / w + OY with w = depth for a
# perspective camera and 1 for an orthographic one, then the clip range, then Taichi's particle scale: a
# sphere of radius r at distance d from the camera is a disc of r * PSCALE / d pixels.
CAM_SX, CAM_OX, CAM_SY, CAM_OY, CAM_ORTHO, CAM_NEAR, CAM_FAR, CAM_PSCALE = 12, 13, 14, 15, 16, 17, 18, 19
CAM_SIZE = 20


@ti.func
def _to_view(cam, p):
    """World point -> camera space (x right, y up, looking down -z)."""
    return ti.Vector([
        cam[0] * p[0] + cam[1] * p[1] + cam[2] * p[2] + cam[3],
        cam[4] * p[0] + cam[5] * p[1] + cam[6] * p[2] + cam[7],
        cam[8] * p[0] + cam[9] * p[1] + cam[10] * p[2] + cam[11],
    ])


@ti.func
def _to_screen(cam, v):
    """Camera-space point -> (pixel x, pixel y, depth)."""
    d = -v[2]
    w = 1.0
    if cam[CAM_ORTHO] == 0.0:
        w = ti.max(d, 1e-20)
    return ti.Vector([cam[CAM_SX] * v[0] / w + cam[CAM_OX], cam[CAM_SY] * v[1] / w + cam[CAM_OY], d])


@ti.func
def _disc_radius(cam, v, r):
    """Screen radius in pixels of a sphere of radius ``r`` at camera-space ``v``, as Taichi's particle shader
    sizes it: ``r / (tan(fov / 2) * distance)`` of half the window's width, distance measured from the camera
    position (not the depth), in orthographic mode too."""
    return r * cam[CAM_PSCALE] / ti.max(v.norm(), 1e-20)


@ti.func
def _box(lo, hi, size):
    """Pixel index range [first, last] whose centres can lie in [lo, hi] (clamped to the image; floats are
    clamped before the cast so far-away primitives cannot overflow it)."""
    first = ti.cast(ti.floor(ti.min(ti.max(lo, -1.0), size + 1.0) - 0.5) + 1.0, ti.i32)
    last = ti.cast(ti.floor(ti.min(ti.max(hi, -1.0), size + 1.0) - 0.5), ti.i32)
    return ti.max(first, 0), ti.min(last, ti.cast(size, ti.i32) - 1)


@ti.func
def _key(depth, prim):
    bits = ti.bit_cast(ti.cast(ti.max(depth, 0.0), ti.f32), ti.i32)
    return (ti.cast(bits, ti.i64) << 32) | ti.cast(prim, ti.i64)


@ti.kernel
def project(points: _V1, cam: _F1, out: _P1):
    """Screen position, depth and 1 / depth of every vertex (depth <= near marks it clipped)."""
    for p in range(points.shape[0]):
        s = _to_screen(cam, _to_view(cam, points[p]))
        out[p] = ti.Vector([s[0], s[1], s[2], 1.0 / ti.max(s[2], 1e-20)])


@ti.kernel
def splat_particles(centers: _V1, radii: _F1, cam: _F1, depth: _D2, base: _I32):
    """Sphere impostors: each covered pixel gets the depth of the sphere's front surface there."""
    W = ti.cast(depth.shape[0], ti.f32)
    H = ti.cast(depth.shape[1], ti.f32)
    for p in range(centers.shape[0]):
        v = _to_view(cam, centers[p])
        s = _to_screen(cam, v)
        r = radii[p]
        R = _disc_radius(cam, v, r)
        # (NaN or far-off centres fail the bounds test: an exploded simulation draws nothing, fast)
        if s[2] > cam[CAM_NEAR] and s[2] < cam[CAM_FAR] and R > 0.0 and ti.abs(s[0]) < 1e9 and ti.abs(s[1]) < 1e9:
            x0, x1 = _box(s[0] - R, s[0] + R, W)
            y0, y1 = _box(s[1] - R, s[1] + R, H)
            inv = 1.0 / R
            for i in range(x0, x1 + 1):
                u = (i + 0.5 - s[0]) * inv
                for j in range(y0, y1 + 1):
                    t = (j + 0.5 - s[1]) * inv
                    q = u * u + t * t
                    if q < 1.0:
                        ti.atomic_min(depth[i, j], _key(s[2] - r * ti.sqrt(1.0 - q), base + p))


@ti.func
def _edge(a, b, px, py):
    return (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0])


@ti.kernel
def raster_triangles(screen: _P1, tris: _T1, cam: _F1, depth: _D2, base: _I32):
    """A pixel is covered when its centre is inside the triangle (edges included); depth is interpolated
    perspective-correctly (1 / depth is linear on the screen).  Triangles crossing the near plane were cut
    by clip_near; any left with a vertex behind it are skipped."""
    W = ti.cast(depth.shape[0], ti.f32)
    H = ti.cast(depth.shape[1], ti.f32)
    ortho = cam[CAM_ORTHO] != 0.0
    for t in range(tris.shape[0]):
        a = screen[tris[t][0]]
        b = screen[tris[t][1]]
        c = screen[tris[t][2]]
        near = cam[CAM_NEAR]
        far = cam[CAM_FAR]
        area = _edge(a, b, c[0], c[1])
        if ti.min(a[2], b[2], c[2]) > near and ti.max(a[2], b[2], c[2]) < far and area != 0.0 \
                and ti.abs(area) < 1e30:  # (false for NaN vertices)
            x0, x1 = _box(ti.min(a[0], b[0], c[0]), ti.max(a[0], b[0], c[0]), W)
            y0, y1 = _box(ti.min(a[1], b[1], c[1]), ti.max(a[1], b[1], c[1]), H)
            inv = 1.0 / area
            for i in range(x0, x1 + 1):
                px = i + 0.5
                for j in range(y0, y1 + 1):
                    py = j + 0.5
                    wa = _edge(b, c, px, py) * inv
                    wb = _edge(c, a, px, py) * inv
                    wc = 1.0 - wa - wb
                    if wa >= 0.0 and wb >= 0.0 and wc >= 0.0:
                        d = wa * a[2] + wb * b[2] + wc * c[2]
                        if not ortho:
                            d = 1.0 / (wa * a[3] + wb * b[3] + wc * c[3])
                        ti.atomic_min(depth[i, j], _key(d, base + t))


@ti.kernel
def raster_lines(screen: _P1, segs: _S1, half_width: _F32, cam: _F1, depth: _D2,
                 base: _I32):
    """Screen-space thick segments (``half_width`` pixels) with round ends, depth interpolated along them."""
    W = ti.cast(depth.shape[0], ti.f32)
    H = ti.cast(depth.shape[1], ti.f32)
    ortho = cam[CAM_ORTHO] != 0.0
    for s in range(segs.shape[0]):
        a = screen[segs[s][0]]
        b = screen[segs[s][1]]
        extent = ti.abs(a[0]) + ti.abs(a[1]) + ti.abs(b[0]) + ti.abs(b[1])  # (NaN fails the test below)
        if ti.min(a[2], b[2]) > cam[CAM_NEAR] and ti.max(a[2], b[2]) < cam[CAM_FAR] and extent < 1e30:
            x0, x1 = _box(ti.min(a[0], b[0]) - half_width, ti.max(a[0], b[0]) + half_width, W)
            y0, y1 = _box(ti.min(a[1], b[1]) - half_width, ti.max(a[1], b[1]) + half_width, H)
            dx = b[0] - a[0]
            dy = b[1] - a[1]
            l2 = dx * dx + dy * dy
            for i in range(x0, x1 + 1):
                px = i + 0.5 - a[0]
                for j in range(y0, y1 + 1):
                    py = j + 0.5 - a[1]
                    t = 0.0
                    if l2 > 0.0:
                        t = ti.min(ti.max((px * dx + py * dy) / l2, 0.0), 1.0)
                    ex = px - t * dx
                    ey = py - t * dy
                    if ex * ex + ey * ey <= half_width * half_width:
                        d = (1.0 - t) * a[2] + t * b[2]
                        if not ortho:
                            d = 1.0 / ((1.0 - t) * a[3] + t * b[3])
                        ti.atomic_min(depth[i, j], _key(d, base + s))


@ti.func
def _lambert(color, pos, n, two_sided, lights, ambient):
    """Taichi's GGUI lighting: ambient + diffuse point lights (no attenuation, no specular)."""
    result = ambient * color
    for k in range(lights.shape[0]):
        light_dir = (ti.Vector([lights[k, 0], lights[k, 1], lights[k, 2]]) - pos).normalized(1e-12)
        f = light_dir.dot(n)
        if two_sided != 0:
            f = ti.abs(f)
        else:
            f = ti.max(f, 0.0)
        result += f * color * ti.Vector([lights[k, 3], lights[k, 4], lights[k, 5]])
    return result


@ti.kernel
def shade(depth: _D2, img: _V2, cam: _F1, lights: _F2, ambient: vec3,
          centers: _V1, radii: _F1, pcolors: _V1,
          verts: _V1, normals: _V1, vcolors: _V1, screen: _P1, tris: _T1, two_sided: _I1D,
          lcolors: _V1, segs: _S1):
    """Colour every covered pixel from the primitive that won its depth test."""
    n_particles = centers.shape[0]
    n_tris = tris.shape[0]
    ortho = cam[CAM_ORTHO] != 0.0
    for i, j in ti.ndrange(depth.shape[0], depth.shape[1]):
        key = depth[i, j]
        if key != EMPTY:
            prim = ti.cast(key & _ID_MASK, ti.i32)
            px = i + 0.5
            py = j + 0.5
            color = ti.Vector([0.0, 0.0, 0.0])
            if prim < n_particles:
                c = centers[prim]
                v = _to_view(cam, c)
                s = _to_screen(cam, v)
                R = _disc_radius(cam, v, radii[prim])
                u = (px - s[0]) / R
                t = (py - s[1]) / R
                nz = ti.sqrt(ti.max(1.0 - u * u - t * t, 0.0))
                # the camera-space normal (u, t, nz) back in world space (transpose of the rotation)
                n = ti.Vector([
                    cam[0] * u + cam[4] * t + cam[8] * nz,
                    cam[1] * u + cam[5] * t + cam[9] * nz,
                    cam[2] * u + cam[6] * t + cam[10] * nz,
                ])
                color = _lambert(pcolors[prim], c + radii[prim] * n, n, 0, lights, ambient)
            elif prim < n_particles + n_tris:
                tri = prim - n_particles
                ia = tris[tri][0]
                ib = tris[tri][1]
                ic = tris[tri][2]
                a = screen[ia]
                b = screen[ib]
                c = screen[ic]
                inv = 1.0 / _edge(a, b, c[0], c[1])
                wa = _edge(b, c, px, py) * inv
                wb = _edge(c, a, px, py) * inv
                wc = 1.0 - wa - wb
                if not ortho:  # perspective-correct weights
                    wa *= a[3]
                    wb *= b[3]
                    wc *= c[3]
                    norm = 1.0 / (wa + wb + wc)
                    wa *= norm
                    wb *= norm
                    wc *= norm
                pos = wa * verts[ia] + wb * verts[ib] + wc * verts[ic]
                n = (wa * normals[ia] + wb * normals[ib] + wc * normals[ic]).normalized(1e-12)
                col = wa * vcolors[ia] + wb * vcolors[ib] + wc * vcolors[ic]
                color = _lambert(col, pos, n, two_sided[tri], lights, ambient)
            else:
                seg = prim - n_particles - n_tris
                a = screen[segs[seg][0]]
                b = screen[segs[seg][1]]
                dx = b[0] - a[0]
                dy = b[1] - a[1]
                l2 = dx * dx + dy * dy
                t = 0.0
                if l2 > 0.0:
                    t = ti.min(ti.max(((px - a[0]) * dx + (py - a[1]) * dy) / l2, 0.0), 1.0)
                color = (1.0 - t) * lcolors[segs[seg][0]] + t * lcolors[segs[seg][1]]
            img[i, j] = ti.min(ti.max(color, 0.0), 1.0)


@ti.kernel
def vertex_normals(verts: _V1, tris: _T1, out: _V1):
    """Per-vertex normals as the sum of the unit normals of the triangles around each vertex (normalised
    when shading), as Taichi infers them when a mesh comes without normals."""
    for v in range(out.shape[0]):
        out[v] = ti.Vector([0.0, 0.0, 0.0])
    for t in range(tris.shape[0]):
        a = verts[tris[t][0]]
        b = verts[tris[t][1]]
        c = verts[tris[t][2]]
        n = (b - a).cross(c - a).normalized(1e-20)
        for k in ti.static(range(3)):
            ti.atomic_add(out[tris[t][k]], n)


class Frame:
    """What one ``canvas.scene(scene)`` draws, gathered into flat float32/int32 arrays (see scene.py)."""

    def __init__(self, cam, lights, ambient, centers, radii, pcolors, verts, normals, vcolors, tris, two_sided,
                 line_verts, lcolors, segs, line_widths):
        self.cam, self.lights, self.ambient = cam, lights, ambient
        self.centers, self.radii, self.pcolors = centers, radii, pcolors
        self.verts, self.normals, self.vcolors, self.tris, self.two_sided = verts, normals, vcolors, tris, two_sided
        # line_widths: (first segment, segment count, width in pixels) per scene.lines() call
        self.line_verts, self.lcolors, self.segs, self.line_widths = line_verts, lcolors, segs, line_widths


def nonempty(arr, shape, dtype):
    """Kernels get at least one element (a dummy never read when the count is 0)."""
    return arr if len(arr) else np.zeros(shape, dtype)


_depth_cache: dict = {}


def clip_near(frame: Frame, screen: np.ndarray) -> np.ndarray:
    """Cut the triangles that cross the camera's near plane at (just in front of) it, so a floor that runs
    behind the camera is drawn up to the picture's edge instead of vanishing.  A triangle with one vertex
    behind becomes two, with two behind one; new vertices interpolate position, normal and colour (exact:
    camera depth is linear along an edge).  Changes ``frame``'s mesh arrays; returns the extended screen
    array.  Costs one min() over the vertices when no vertex is behind the plane."""
    near = float(frame.cam[CAM_NEAR])
    d = screen[: len(frame.verts), 2].astype(np.float64)
    if d.min() > near:
        return screen
    behind = d[frame.tris] <= near
    n_behind = behind.sum(axis=1)
    cross = (n_behind == 1) | (n_behind == 2)
    if not cross.any():
        return screen
    tris, flags = frame.tris[cross], frame.two_sided[cross]
    odd = np.where((n_behind[cross] == 1)[:, None], behind[cross], ~behind[cross])  # unlike the other two
    roll = np.argmax(odd, axis=1)
    tris = tris[np.arange(len(tris))[:, None], (roll[:, None] + np.arange(3)) % 3]  # odd one first
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    plane = near * (1 + 1e-4) + 1e-7

    def cut(p, q):
        t = ((plane - d[p]) / (d[q] - d[p]))[:, None]
        return [(1 - t) * arr[p] + t * arr[q] for arr in (frame.verts, frame.normals, frame.vcolors)]

    ab, ca = cut(a, b), cut(c, a)
    base = len(frame.verts)
    m = len(tris)
    new = [np.concatenate([x, y]).astype(np.float32) for x, y in zip(ab, ca)]
    i_ab, i_ca = base + np.arange(m), base + m + np.arange(m)
    one = n_behind[cross] == 1  # odd vertex behind: quad (ab, b, c, ca); else triangle (a, ab, ca)
    added = np.concatenate([np.stack([i_ab, b, c], 1)[one], np.stack([i_ab, c, i_ca], 1)[one],
                            np.stack([a, i_ab, i_ca], 1)[~one]]).astype(np.int32)
    frame.verts = np.concatenate([frame.verts, new[0]])
    frame.normals = np.concatenate([frame.normals, new[1]])
    frame.vcolors = np.concatenate([frame.vcolors, new[2]])
    frame.tris = np.ascontiguousarray(np.concatenate([frame.tris[~cross], added]), np.int32)
    frame.two_sided = np.concatenate([frame.two_sided[~cross], flags[one], flags[one], flags[~one]]).astype(np.int32)
    extra = np.empty((2 * m, 4), np.float32)
    project(new[0], frame.cam, extra)
    return np.concatenate([screen[:base], extra])


def render(img: np.ndarray, frame: Frame, depth: np.ndarray | None = None) -> np.ndarray:
    """Draw ``frame`` over ``img`` (float32 (W, H, 3), changed in place); returns the depth keys, written into
    ``depth`` (int64 (W, H)) when given, else into a buffer shared per resolution."""
    W, H = img.shape[:2]
    if depth is None:
        depth = _depth_cache.get((W, H))
        if depth is None:
            depth = _depth_cache[(W, H)] = np.empty((W, H), np.int64)
    depth.fill(EMPTY)  # a memset: numpy does it 5x faster than a kernel launch
    cam = frame.cam
    n_p, n_t = len(frame.centers), len(frame.tris)
    if n_p:
        splat_particles(frame.centers, frame.radii, cam, depth, 0)
    screen = np.empty((max(1, len(frame.verts)), 4), np.float32)
    if n_t:
        project(frame.verts, cam, screen)
        screen = clip_near(frame, screen)
        n_t = len(frame.tris)
        raster_triangles(screen, frame.tris, cam, depth, n_p)
    line_screen = np.empty((max(1, len(frame.line_verts)), 4), np.float32)
    if len(frame.segs):
        project(frame.line_verts, cam, line_screen)
        for first, count, width in frame.line_widths:
            raster_lines(line_screen, frame.segs[first:first + count], 0.5 * width, cam, depth, n_p + n_t + first)
    v3 = (1, 3)
    shade(depth, img, cam, frame.lights, frame.ambient,
          frame.centers if n_p else np.zeros((0, 3), np.float32), nonempty(frame.radii, (1,), np.float32),
          nonempty(frame.pcolors, v3, np.float32),
          nonempty(frame.verts, v3, np.float32), nonempty(frame.normals, v3, np.float32),
          nonempty(frame.vcolors, v3, np.float32), screen, frame.tris, nonempty(frame.two_sided, (1,), np.int32),
          nonempty(frame.lcolors, v3, np.float32), nonempty(frame.segs, (1, 2), np.int32))
    return depth


def depth_buffer(keys: np.ndarray, cam: np.ndarray) -> np.ndarray:
    """Taichi's depth buffer (``window.get_depth_buffer_as_numpy()``) from the depth keys of a render: float32
    (W, H) of reversed Z in [0, 1], 1 at the near plane, 0 at the far plane and where nothing was drawn (GGUI
    builds glm's zero-to-one projection with near and far swapped, and clears depth to 0)."""
    d = (keys >> 32).astype(np.int32).view(np.float32).astype(np.float64)
    n, f = float(cam[CAM_NEAR]), float(cam[CAM_FAR])
    with np.errstate(divide="ignore", invalid="ignore"):
        if cam[CAM_ORTHO] != 0.0:
            z = (f - d) / (f - n)
        else:
            z = n * (f - d) / (d * (f - n))
    return np.where(keys == EMPTY, 0.0, np.clip(z, 0.0, 1.0)).astype(np.float32)
