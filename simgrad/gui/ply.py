"""``ti.tools.PLYWriter``: particles and meshes to PLY files (for Houdini, Blender, ParaView...).

Channels are named as Taichi's writer names them (x y z, nx ny nz, vx vy vz, red green blue, Alpha,
id, piece), so files from either load the same way.  Binary export writes every record at once
through a numpy structured array.
"""

from __future__ import annotations

import sys

import numpy as np

__all__ = ["PLYWriter"]

_TYPES = {"char": np.int8, "uchar": np.uint8, "short": np.int16, "ushort": np.uint16, "int": np.int32,
          "uint": np.uint32, "float": np.float32, "double": np.float64}


class PLYWriter:
    """Collect per-vertex and per-face channels, then ``export`` (binary) or ``export_ascii``."""

    def __init__(self, num_vertices: int, num_faces: int = 0, face_type: str = "tri",
                 comment: str = "created by PLYWriter"):
        if num_vertices <= 0:
            raise ValueError(f"num_vertices must be positive, got {num_vertices}")
        if num_faces < 0:
            raise ValueError(f"num_faces must not be negative, got {num_faces}")
        if face_type not in ("tri", "quad"):
            raise ValueError(f"face_type must be 'tri' or 'quad', got {face_type!r}")
        self.num_vertices, self.num_faces, self.face_type, self.comment = num_vertices, num_faces, face_type, comment
        self.vertex_channels: list[str] = []
        self.vertex_data_type: list[str] = []
        self.vertex_data: list[np.ndarray] = []
        self.face_channels: list[str] = []
        self.face_data_type: list[str] = []
        self.face_data: list[np.ndarray] = []
        self.face_indices = -np.ones((num_faces, 3 if face_type == "tri" else 4), dtype=np.int32)

    @property
    def num_vertex_channels(self):
        return len(self.vertex_channels)

    @property
    def num_face_channels(self):
        return len(self.face_channels)

    @staticmethod
    def _add(names, types, data_list, count, what, key, data_type, data):
        if data_type not in _TYPES:  # Taichi's writer says so and goes on without the channel
            print("Unknown type " + str(data_type) + " detected, skipping this channel")
            return
        arr = np.asarray(data)
        if arr.size % count or arr.size == 0:
            raise ValueError(f"{what} channel {key!r} has {arr.size} values, not a multiple of {count}")
        cols = arr.reshape(count, -1)
        single = arr.ndim == 1 or cols.shape[1] == 1
        for i in range(cols.shape[1]):
            names.append(key if single else f"{key}_{i + 1}")
            types.append(data_type)
            data_list.append(cols[:, i].astype(_TYPES[data_type]))

    def add_vertex_channel(self, key: str, data_type: str, data):
        self._add(self.vertex_channels, self.vertex_data_type, self.vertex_data, self.num_vertices, "vertex", key,
                  data_type, data)

    def add_vertex_pos(self, x, y, z):
        for key, d in (("x", x), ("y", y), ("z", z)):
            self.add_vertex_channel(key, "float", d)

    def add_vertex_normal(self, nx, ny, nz):
        for key, d in (("nx", nx), ("ny", ny), ("nz", nz)):
            self.add_vertex_channel(key, "float", d)

    def add_vertex_vel(self, vx, vy, vz):
        for key, d in (("vx", vx), ("vy", vy), ("vz", vz)):
            self.add_vertex_channel(key, "float", d)

    def add_vertex_color(self, r, g, b):
        for key, d in (("red", r), ("green", g), ("blue", b)):
            self.add_vertex_channel(key, "float", d)

    def add_vertex_alpha(self, alpha):
        self.add_vertex_channel("Alpha", "float", alpha)

    def add_vertex_rgba(self, r, g, b, a):
        self.add_vertex_color(r, g, b)
        self.add_vertex_alpha(a)

    def add_vertex_id(self):
        self.add_vertex_channel("id", "int", np.arange(self.num_vertices))

    def add_vertex_piece(self, piece):
        self.add_vertex_channel("piece", "int", piece)

    def add_faces(self, indices):
        per_face = self.face_indices.shape[1]
        arr = np.asarray(indices)
        if arr.size != per_face * self.num_faces:
            raise ValueError(f"add_faces: expected {per_face * self.num_faces} indices, got {arr.size}")
        self.face_indices = arr.reshape(self.num_faces, per_face).astype(np.int32)

    def add_face_channel(self, key: str, data_type: str, data):
        self._add(self.face_channels, self.face_data_type, self.face_data, self.num_faces, "face", key, data_type,
                  data)

    def add_face_id(self):
        self.add_face_channel("id", "int", np.arange(self.num_faces))

    def add_face_piece(self, piece):
        self.add_face_channel("piece", "int", piece)

    def sanity_check(self):
        if not {"x", "y", "z"} <= set(self.vertex_channels):
            raise ValueError("PLYWriter: the vertex positions (add_vertex_pos) are missing")
        if self.num_faces and (self.face_indices.min() < 0 or self.face_indices.max() >= self.num_vertices):
            raise ValueError(f"PLYWriter: face indices must lie in [0, {self.num_vertices})")

    def _header(self, fmt: str) -> str:
        lines = ["ply", f"format {fmt} 1.0", f"comment {self.comment}", f"element vertex {self.num_vertices}"]
        lines += [f"property {t} {k}" for t, k in zip(self.vertex_data_type, self.vertex_channels)]
        if self.num_faces:
            lines += [f"element face {self.num_faces}", "property list uchar int vertex_indices"]
            lines += [f"property {t} {k}" for t, k in zip(self.face_data_type, self.face_channels)]
        return "\n".join(lines + ["end_header"]) + "\n"

    def export(self, path):
        """Binary PLY in this machine's byte order."""
        self.sanity_check()
        with open(path, "wb") as f:
            f.write(self._header(f"binary_{sys.byteorder}_endian").encode())
            rec = np.empty(self.num_vertices, [(f"c{i}", d.dtype) for i, d in enumerate(self.vertex_data)])
            for i, d in enumerate(self.vertex_data):
                rec[f"c{i}"] = d
            f.write(rec.tobytes())
            if self.num_faces:
                per_face = self.face_indices.shape[1]
                fields = [("n", np.uint8), ("v", np.int32, (per_face,))]
                fields += [(f"c{i}", d.dtype) for i, d in enumerate(self.face_data)]
                frec = np.empty(self.num_faces, fields)
                frec["n"] = per_face
                frec["v"] = self.face_indices
                for i, d in enumerate(self.face_data):
                    frec[f"c{i}"] = d
                f.write(frec.tobytes())

    def export_ascii(self, path):
        self.sanity_check()
        with open(path, "w") as f:
            f.write(self._header("ascii"))
            for i in range(self.num_vertices):
                f.write(" ".join(str(d[i]) for d in self.vertex_data) + "\n")
            for i in range(self.num_faces):
                items = [str(self.face_indices.shape[1])] + [str(v) for v in self.face_indices[i]]
                f.write(" ".join(items + [str(d[i]) for d in self.face_data]) + "\n")

    @staticmethod
    def _series(path: str, series_num: int) -> str:
        return f"{path[:-4] if path.endswith('.ply') else path}_{series_num:06d}.ply"

    def export_frame(self, series_num: int, path: str):
        """``export`` to ``<path without .ply>_<series_num:06d>.ply``."""
        self.export(self._series(path, series_num))

    def export_frame_ascii(self, series_num: int, path: str):
        self.export_ascii(self._series(path, series_num))
