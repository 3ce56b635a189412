"""``ti.ui.Scene`` and ``ti.ui.Camera``: what a GGUI program declares for one 3-D frame.

A scene collects particles, meshes and lines (copied out of fields/ndarrays/numpy as float32 arrays)
and lights; ``canvas.scene(scene)`` turns them into one :class:`~.render3d.Frame`, renders it, and the
scene starts the next frame empty, keeping its camera and ambient light, as in Taichi.  Units follow
GGUI: particle radii are world units, line widths pixels, colours float RGB in [0, 1].
"""

from __future__ import annotations

import enum
import math
import warnings

import numpy as np

from simgrad.errors import SimgradTypeError, caller_loc

from . import render3d
from .canvas import to_numpy

__all__ = ["Camera", "ProjectionMode", "Scene", "make_camera"]


class ProjectionMode(enum.IntEnum):
    """Camera projection mode, 0 for perspective and 1 for orthogonal (``ti.ui.ProjectionMode``)."""

    Perspective = 0
    Orthogonal = 1


def _unit(v):
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


class Camera:
    """A look-at camera with Taichi's defaults: at the origin looking along +z, 45 degree vertical fov."""

    def __init__(self):
        self.curr_position = np.array([0.0, 0.0, 0.0])
        self.curr_lookat = np.array([0.0, 0.0, 1.0])
        self.curr_up = np.array([0.0, 1.0, 0.0])
        self.curr_projection_mode = ProjectionMode.Perspective
        self.curr_fov = 45.0
        self.curr_left, self.curr_right, self.curr_top, self.curr_bottom = -1.0, 1.0, -1.0, 1.0
        self.curr_z_near, self.curr_z_far = 0.1, 1000.0
        self.last_mouse_x = self.last_mouse_y = self.last_time = None

    def position(self, x, y, z):
        self.curr_position = np.array([float(x), float(y), float(z)])

    def lookat(self, x, y, z):
        self.curr_lookat = np.array([float(x), float(y), float(z)])

    def up(self, x, y, z):
        self.curr_up = np.array([float(x), float(y), float(z)])

    def projection_mode(self, mode):
        self.curr_projection_mode = ProjectionMode(int(mode))

    def fov(self, fov):
        """Vertical field of view in degrees."""
        self.curr_fov = float(fov)

    def left(self, left):
        self.curr_left = float(left)

    def right(self, right):
        self.curr_right = float(right)

    def top(self, top):
        self.curr_top = float(top)

    def bottom(self, bottom):
        self.curr_bottom = float(bottom)

    def z_near(self, z_near):
        self.curr_z_near = float(z_near)

    def z_far(self, z_far):
        self.curr_z_far = float(z_far)

    def _basis(self):
        front = _unit(self.curr_lookat - self.curr_position)
        side = _unit(np.cross(front, self.curr_up))
        return front, side, np.cross(side, front)

    def get_view_matrix(self):
        """World -> camera space (row major; the camera looks down -z, as glm::lookAt)."""
        front, side, up = self._basis()
        view = np.eye(4)
        view[0, :3], view[1, :3], view[2, :3] = side, up, -front
        view[:3, 3] = -view[:3, :3] @ self.curr_position
        return view

    def get_projection_matrix(self, aspect):
        """Camera space -> clip space (row major, OpenGL convention: depth -1 near, +1 far)."""
        n, f = self.curr_z_near, self.curr_z_far
        proj = np.zeros((4, 4))
        if self.curr_projection_mode == ProjectionMode.Perspective:
            t = 1.0 / math.tan(math.radians(self.curr_fov) / 2)
            proj[0, 0], proj[1, 1] = t / aspect, t
            proj[2, 2], proj[2, 3], proj[3, 2] = (f + n) / (n - f), 2 * f * n / (n - f), -1.0
        else:
            l_, r, b, t = self.curr_left, self.curr_right, self.curr_top, self.curr_bottom
            proj[0, 0], proj[0, 3] = 2 / (r - l_), -(r + l_) / (r - l_)
            proj[1, 1], proj[1, 3] = 2 / (t - b), -(t + b) / (t - b)
            proj[2, 2], proj[2, 3], proj[3, 3] = -2 / (f - n), -(f + n) / (f - n), 1.0
        return proj

    def _screen(self, res) -> np.ndarray:
        """The renderer's camera array (see render3d.CAM_*) for an image of ``res`` pixels."""
        W, H = res
        cam = np.zeros(render3d.CAM_SIZE, np.float32)
        cam[:12] = self.get_view_matrix()[:3].reshape(-1)
        if self.curr_projection_mode == ProjectionMode.Perspective:
            focal = (H / 2) / math.tan(math.radians(self.curr_fov) / 2)
            cam[render3d.CAM_SX], cam[render3d.CAM_OX] = focal, W / 2
            cam[render3d.CAM_SY], cam[render3d.CAM_OY] = focal, H / 2
        else:  # x from left to right fills the width, y from top to bottom the height (GGUI's y is up)
            sx = W / (self.curr_right - self.curr_left)
            sy = H / (self.curr_bottom - self.curr_top)
            cam[render3d.CAM_SX], cam[render3d.CAM_OX] = sx, -self.curr_left * sx
            cam[render3d.CAM_SY], cam[render3d.CAM_OY] = sy, -self.curr_top * sy
            cam[render3d.CAM_ORTHO] = 1.0
        cam[render3d.CAM_NEAR], cam[render3d.CAM_FAR] = self.curr_z_near, self.curr_z_far
        cam[render3d.CAM_PSCALE] = (W / 2) / math.tan(math.radians(self.curr_fov) / 2)
        return cam

    def _copy(self) -> Camera:
        other = Camera()
        other.__dict__.update({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()})
        return other

    def track_user_inputs(self, window, movement_speed: float = 1.0, yaw_speed: float = 2.0,
                          pitch_speed: float = 2.0, hold_key=None):
        """Fly the camera: w/s forward and back, a/d sideways, e/q up and down, mouse (while ``hold_key`` is
        held, or always if None) turns it.  Speeds are per 1/60 s.  Headless nothing is pressed and the
        cursor stays in the centre, so the camera does not move."""
        import time

        front = _unit(self.curr_lookat - self.curr_position)
        left = np.cross(self.curr_up, front)
        up = self.curr_up
        now = time.perf_counter()
        elapsed = 0.0 if self.last_time is None else now - self.last_time
        self.last_time = now
        step = movement_speed * elapsed * 60.0
        change = np.zeros(3)
        for key, direction in (("w", front), ("s", -front), ("a", left), ("d", -left), ("e", up), ("q", -up)):
            if window.is_pressed(key):
                change += direction * step
        self.curr_position = self.curr_position + change
        x, y = window.get_cursor_pos()
        if hold_key is None or window.is_pressed(hold_key):
            if self.last_mouse_x is None or self.last_mouse_y is None:
                self.last_mouse_x, self.last_mouse_y = x, y
            yaw = math.atan2(front[0], front[2])
            pitch = math.asin(max(-1.0, min(1.0, front[1])))
            yaw -= (x - self.last_mouse_x) * yaw_speed * elapsed * 60.0
            pitch += (y - self.last_mouse_y) * pitch_speed * elapsed * 60.0
            limit = math.pi / 2 * 0.99
            pitch = max(-limit, min(limit, pitch))
            front = np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch), math.cos(yaw) * math.cos(pitch)])
        self.curr_lookat = self.curr_position + front
        self.last_mouse_x, self.last_mouse_y = x, y


def make_camera() -> Camera:
    return Camera()


def _fail(method: str, message: str):
    raise SimgradTypeError(f"scene.{method}: {message}", caller_loc())


def _array(x, method: str, name: str) -> np.ndarray:
    arr = to_numpy(x)
    if arr.dtype.kind not in "fiu":
        _fail(method, f"{name} must hold numbers, got dtype {arr.dtype}")
    return arr


def _vectors(x, method: str, name: str, widths=(3,)) -> np.ndarray:
    """Float32 (n, 3) rows from a field, ndarray or numpy array of 3-vectors (4-vectors too for colours,
    alpha dropped); any leading shape is flattened."""
    arr = _array(x, method, name)
    if arr.ndim < 2 or arr.shape[-1] not in widths:
        want = " or ".join(f"(n, {w})" for w in widths)
        _fail(method, f"{name} must be a field/array of {widths[0]}-vectors, shape {want}; got shape {arr.shape}")
    out = np.ascontiguousarray(arr.reshape(-1, arr.shape[-1])[:, :3], dtype=np.float32)
    # a snapshot, as Taichi copies into its vertex buffer: later changes to the array must not show
    return out.copy() if isinstance(x, np.ndarray) and np.shares_memory(out, x) else out


def _color(c, method: str, name: str = "color") -> np.ndarray:
    arr = np.asarray(c, dtype=np.float64).reshape(-1)
    if arr.size not in (3, 4):
        _fail(method, f"{name} must be an (r, g, b) tuple of floats, got {c!r}")
    return arr[:3].astype(np.float32)


def _count(n_all: int, offset: int, count, method: str, what: str) -> slice:
    offset = int(offset)
    count = n_all - offset if count is None else int(count)
    if offset < 0 or count < 0 or offset + count > n_all:
        _fail(method, f"{what} range [{offset}, {offset + count}) is outside the {n_all} available")
    return slice(offset, offset + count)


def _indices(indices, n_vertices: int, vertex_offset: int, index_offset: int, index_count, arity: int,
             method: str) -> np.ndarray:
    """(m, arity) int32 vertex indices, checked against the vertex count."""
    if indices is None:
        sel = _count(n_vertices, vertex_offset, None, method, "vertex")
        flat = np.arange(sel.start, sel.stop, dtype=np.int64)
    else:
        arr = _array(indices, method, "indices")
        if arr.dtype.kind not in "iu":
            _fail(method, f"indices must be integers, got dtype {arr.dtype}")
        flat = arr.reshape(-1).astype(np.int64)
        flat = flat[_count(len(flat), index_offset, index_count, method, "index")] + int(vertex_offset)
        if len(flat) and (flat.min() < 0 or flat.max() >= n_vertices):
            _fail(method, f"indices must lie in [0, {n_vertices}) (the vertex count), got values in "
                          f"[{flat.min()}, {flat.max()}]")
    flat = flat[: len(flat) - len(flat) % arity]
    return flat.reshape(-1, arity).astype(np.int32)


class _Mesh:
    def __init__(self, verts, normals, colors, tris, two_sided):
        self.verts, self.normals, self.colors, self.tris, self.two_sided = verts, normals, colors, tris, two_sided


class Scene:
    """Particles, meshes, lines and lights of one frame, plus the camera and ambient light that persist."""

    def __init__(self):
        # Taichi 1.7.4's words: a scene belongs to a window now
        warnings.warn("Instantiating ti.ui.Scene directly is deprecated, use the get_scene() function from a "
                      "taichi.ui.Window object instead.", DeprecationWarning, stacklevel=2)
        self._setup()

    @classmethod
    def _for_window(cls) -> Scene:
        """The scene ``window.get_scene()`` returns (no deprecation warning)."""
        scene = cls.__new__(cls)
        scene._setup()
        return scene

    def _setup(self):
        self._camera = Camera()
        self._ambient = np.array([0.1, 0.1, 0.1], np.float32)
        self._clear()

    def _clear(self):
        self._lights: list[np.ndarray] = []
        self._particles: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._meshes: list[_Mesh] = []
        self._lines: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]] = []

    def set_camera(self, camera: Camera):
        """Use (a copy of) ``camera``'s current settings for the next renders."""
        self._camera = camera._copy()

    def point_light(self, pos, color):
        self._lights.append(np.concatenate([np.asarray(pos, np.float32).reshape(3), _color(color, "point_light")]))

    def ambient_light(self, color):
        self._ambient = _color(color, "ambient_light")

    def particles(self, centers, radius, color=(0.5, 0.5, 0.5), per_vertex_color=None, per_vertex_radius=None,
                  index_offset: int = 0, index_count=None):
        """Spheres of ``radius`` (world units) at ``centers``, shaded as Taichi's particle impostors.

        On screen a sphere is a disc of ``radius / (tan(fov / 2) * distance)`` times half the window's width
        (distance from the camera position), as Taichi's GGUI draws it: on a 4:3 window that is 4/3 of the
        sphere's geometric silhouette, and orthographic cameras size particles the same way."""
        c = _vectors(centers, "particles", "centers")
        sel = _count(len(c), index_offset, index_count, "particles", "index")
        if per_vertex_radius is not None:
            r = _array(per_vertex_radius, "particles", "per_vertex_radius").reshape(-1).astype(np.float32)
            if len(r) != len(c):
                _fail("particles", f"per_vertex_radius has {len(r)} values for {len(c)} centers")
        else:
            r = np.full(len(c), float(radius), np.float32)
        if per_vertex_color is not None:
            col = _vectors(per_vertex_color, "particles", "per_vertex_color", (3, 4))
            if len(col) != len(c):
                _fail("particles", f"per_vertex_color has {len(col)} colours for {len(c)} centers")
        else:
            col = np.broadcast_to(_color(color, "particles"), c.shape)
        self._particles.append((c[sel], r[sel], col[sel]))

    def mesh(self, vertices, indices=None, normals=None, color=(0.5, 0.5, 0.5), per_vertex_color=None,
             two_sided=False, vertex_offset: int = 0, vertex_count=None, index_offset: int = 0, index_count=None,
             show_wireframe: bool = False):
        """Triangles (index triples, or consecutive vertex triples without ``indices``).  Without ``normals``
        each vertex gets the average of its triangles' normals; ``show_wireframe`` draws the edges only."""
        self._add_mesh("mesh", vertices, indices, normals, color, per_vertex_color, two_sided, vertex_offset,
                       vertex_count, index_offset, index_count, show_wireframe, None)

    def mesh_instance(self, vertices, indices=None, normals=None, color=(0.5, 0.5, 0.5), per_vertex_color=None,
                      two_sided=False, transforms=None, instance_offset: int = 0, instance_count=None,
                      vertex_offset: int = 0, vertex_count=None, index_offset: int = 0, index_count=None,
                      show_wireframe: bool = False):
        """The mesh drawn once per 4x4 matrix of ``transforms`` (once untransformed without it)."""
        mats = None
        if transforms is not None:
            t = _array(transforms, "mesh_instance", "transforms")
            if t.ndim < 2 or t.shape[-2:] != (4, 4):
                _fail("mesh_instance", f"transforms must be a field/array of 4x4 matrices, got shape {t.shape}")
            t = t.reshape(-1, 4, 4).astype(np.float64)
            mats = t[_count(len(t), instance_offset, instance_count, "mesh_instance", "instance")]
        self._add_mesh("mesh_instance", vertices, indices, normals, color, per_vertex_color, two_sided,
                       vertex_offset, vertex_count, index_offset, index_count, show_wireframe, mats)

    def _add_mesh(self, method, vertices, indices, normals, color, per_vertex_color, two_sided, vertex_offset,
                  vertex_count, index_offset, index_count, show_wireframe, mats):
        v = _vectors(vertices, method, "vertices")
        if indices is None and vertex_count is not None:
            v = v[: int(vertex_offset) + int(vertex_count)]
        tris = _indices(indices, len(v), vertex_offset, index_offset, index_count, 3, method)
        if per_vertex_color is not None:
            col = _vectors(per_vertex_color, method, "per_vertex_color", (3, 4))[: len(v)]
            if len(col) != len(v):
                _fail(method, f"per_vertex_color has {len(col)} colours for {len(v)} vertices")
        else:
            col = np.broadcast_to(_color(color, method), v.shape)
        if normals is not None:
            n = _vectors(normals, method, "normals")[: len(v)]
            if len(n) != len(v):
                _fail(method, f"normals has {len(n)} vectors for {len(v)} vertices")
        else:
            n = np.empty_like(v)
            if len(v):
                render3d.vertex_normals(v, render3d.nonempty(tris, (1, 3), np.int32)[: len(tris)], n)
        if mats is not None:  # every instance as its own copy of the mesh
            nv = len(v)
            rot, shift = mats[:, :3, :3], mats[:, :3, 3]
            inv_t = np.linalg.inv(rot).transpose(0, 2, 1)
            v = (np.einsum("kij,nj->kni", rot, v) + shift[:, None]).reshape(-1, 3).astype(np.float32)
            n = np.einsum("kij,nj->kni", inv_t, n).reshape(-1, 3).astype(np.float32)
            col = np.tile(col, (len(mats), 1))
            tris = (tris[None] + (np.arange(len(mats)) * nv)[:, None, None])
            tris = tris.reshape(-1, 3).astype(np.int32)
        if show_wireframe:
            edges = tris[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
            self._lines.append((v, np.ascontiguousarray(col, np.float32), edges, 1.0))
            return
        self._meshes.append(_Mesh(v, n, col, tris, bool(two_sided)))

    def lines(self, vertices, width, indices=None, color=(0.5, 0.5, 0.5), per_vertex_color=None,
              vertex_offset: int = 0, vertex_count=None, index_offset: int = 0, index_count=None):
        """Segments between vertex pairs (or index pairs), ``width`` pixels wide, unlit."""
        v = _vectors(vertices, "lines", "vertices")
        if indices is None and vertex_count is not None:
            v = v[: int(vertex_offset) + int(vertex_count)]
        segs = _indices(indices, len(v), vertex_offset, index_offset, index_count, 2, "lines")
        if per_vertex_color is not None:
            col = _vectors(per_vertex_color, "lines", "per_vertex_color", (3, 4))[: len(v)]
            if len(col) != len(v):
                _fail("lines", f"per_vertex_color has {len(col)} colours for {len(v)} vertices")
        else:
            col = np.broadcast_to(_color(color, "lines"), v.shape)
        self._lines.append((v, np.ascontiguousarray(col, np.float32), segs, float(width)))

    def _take_frame(self, res) -> render3d.Frame:
        """Everything declared since the last render as one frame; the scene starts the next one empty."""
        f32, i32 = np.float32, np.int32

        def cat(parts, cols, dtype):
            if len(parts) == 1:  # the common case: no copy when the one part is already contiguous
                return np.ascontiguousarray(parts[0], dtype)
            return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros((0, cols), dtype), dtype)

        centers = cat([p[0] for p in self._particles], 3, f32)
        radii = cat([p[1] for p in self._particles], 1, f32).reshape(-1)
        pcolors = cat([p[2] for p in self._particles], 3, f32)
        starts = np.cumsum([0] + [len(m.verts) for m in self._meshes])
        verts = cat([m.verts for m in self._meshes], 3, f32)
        normals = cat([m.normals for m in self._meshes], 3, f32)
        vcolors = cat([m.colors for m in self._meshes], 3, f32)
        tris = cat([m.tris + s if s else m.tris for m, s in zip(self._meshes, starts)], 3, i32)
        two_sided = cat([np.full(len(m.tris), m.two_sided, i32) for m in self._meshes], 1, i32).reshape(-1)
        lstarts = np.cumsum([0] + [len(v) for v, _, _, _ in self._lines])
        sstarts = np.cumsum([0] + [len(s) for _, _, s, _ in self._lines])
        line_verts = cat([v for v, _, _, _ in self._lines], 3, f32)
        lcolors = cat([c for _, c, _, _ in self._lines], 3, f32)
        segs = cat([s + o if o else s for (_, _, s, _), o in zip(self._lines, lstarts)], 2, i32)
        widths = [(int(s0), len(s), w) for (_, _, s, w), s0 in zip(self._lines, sstarts)]
        lights = cat(self._lights, 6, f32).reshape(-1, 6)
        frame = render3d.Frame(self._camera._screen(res), lights, self._ambient, centers, radii, pcolors, verts,
                               normals, vcolors, tris, two_sided, line_verts, lcolors, segs, widths)
        self._clear()
        return frame
