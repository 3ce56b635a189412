"""``fast_gui``'s packed window words written by a simgrad kernel, as Taichi's fast GUI does.

Taichi's ``set_image`` with ``fast_gui=True`` runs a kernel that turns a 3- or 4-vector float field into
the 0x00RRGGBB words its window shows. In numpy that took six passes over the pixels (scale, truncate,
clamp, cast, flip and pack; 40 ms a frame at 1920x1080); one parallel kernel takes a pass. Quantisation is
the one of gui.py ``_fast_pixels``: ``min(255, max(0, int(c * 255)))`` in the field's own precision, NaN and
-inf giving 0, +inf 255.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

import simgrad as ti

__all__ = ["packable", "pack_words", "unpack_words"]

if TYPE_CHECKING:  # kernel parameter annotations are simgrad types, opaque to mypy
    _WORDS: TypeAlias = Any
    _I32: TypeAlias = Any
    _FIELD: TypeAlias = Any
else:
    _WORDS = ti.types.ndarray(dtype=ti.u32, ndim=1)
    _I32 = ti.i32
    _FIELD = ti.template()


def packable(img) -> bool:
    """A dense 2-D field of 3- or 4-vectors of floats (what Taichi's fast path takes); others go by numpy."""
    if not (isinstance(img, ti.MatrixField) and img.is_vector and img.n in (3, 4) and img.dtype.is_float):
        return False
    c = img.comps[0]
    return len(img.shape) == 2 and not c.offset and not c.sparse  # a struct-for then visits every pixel


@ti.func
def _level(c):
    s = c * 255
    q = 0
    if s >= 255:
        q = 255
    elif s > 0:  # false for NaN
        q = ti.cast(s, ti.i32)  # truncation, as int()
    return q


@ti.kernel
def _pack(img: _FIELD, out: _WORDS, height: _I32):
    for i, j in img:
        c = img[i, j]
        word = (_level(c[0]) << 16) | (_level(c[1]) << 8) | _level(c[2])
        out[(height - 1 - j) * img.shape[0] + i] = ti.cast(word, ti.u32)


def pack_words(img, out: np.ndarray) -> None:
    """Write ``img``'s pixels into ``out`` (W * H uint32 words, word ``j * W + i`` the pixel (i, H - 1 - j))."""
    _pack(img, out, img.shape[1])


def unpack_words(words: np.ndarray, res: tuple[int, int]) -> np.ndarray:
    """The float32 RGB (W, H, 3) canvas of packed words: each level / 255, as set_image gives 8-bit pixels."""
    w, h = res
    grid = words.reshape(h, w)[::-1].T  # (W, H): pixel (i, j) is word (H - 1 - j) * W + i
    rgb = np.stack([(grid >> s) & 0xFF for s in (16, 8, 0)], axis=-1).astype(np.uint8)
    return rgb.astype(np.float32) * np.float32(1.0 / 255)
