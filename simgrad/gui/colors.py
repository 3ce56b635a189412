"""Colour conversions between Taichi's 0xRRGGBB integers and float RGB.

Taichi's GUI speaks hex integers while images and ``ti.ui`` speak float RGB in [0, 1]; these helpers
convert both ways (scalars and numpy arrays) with Taichi's exact rounding, so colours drawn here
match the ones Taichi would draw.
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["rgb_to_hex", "hex_to_rgb", "as_rgb"]


def _to255(x):
    # Taichi truncates (np.int32(x * 255)) rather than rounding; keep that so hex values agree.
    return np.clip(np.trunc(np.asarray(x, dtype=np.float64) * 255.0), 0, 255).astype(np.int64)


def rgb_to_hex(c):
    """Convert float RGB in [0, 1] to 0xRRGGBB.

    ``c`` may be a 3-sequence (returns a Python ``int``), an array of shape (..., 3) (returns an int
    array of shape (...)), or, as Taichi's ``c[0], c[1], c[2]`` indexing allows, an array of shape
    (3, ...) whose last axis is not 3.
    """
    arr = np.asarray(c, dtype=np.float64)
    if arr.ndim == 0:
        raise ValueError("rgb_to_hex expects three channels, got a scalar")
    if arr.shape[-1] == 3:
        r, g, b = arr[..., 0], arr[..., 1], arr[..., 2]
    elif arr.shape[0] == 3:
        r, g, b = arr[0], arr[1], arr[2]
    else:
        raise ValueError(f"rgb_to_hex expects 3 channels, got shape {arr.shape}")
    h = (_to255(r) << 16) + (_to255(g) << 8) + _to255(b)
    return int(h) if h.ndim == 0 else h


def hex_to_rgb(h):
    """Convert 0xRRGGBB to float RGB in [0, 1].

    A scalar gives a tuple ``(r, g, b)`` like Taichi; an integer array gives an array of shape
    (..., 3) so that it round-trips through :func:`rgb_to_hex`.
    """
    if isinstance(h, numbers.Integral):
        h = int(h)
        return ((h >> 16) & 0xFF) / 255, ((h >> 8) & 0xFF) / 255, (h & 0xFF) / 255
    arr = np.asarray(h).astype(np.int64)
    if arr.ndim == 0:
        return hex_to_rgb(int(arr))
    return np.stack([(arr >> 16) & 0xFF, (arr >> 8) & 0xFF, arr & 0xFF], axis=-1) / 255.0


def as_rgb(color, n=None):
    """Normalise a drawing colour to float RGB: (3,) when ``n`` is None, else (n, 3).

    Integers (scalars or integer arrays of shape (n,)) are 0xRRGGBB as in ``ti.GUI``; floats
    (a 3-sequence or an array of shape (n, 3)) are RGB in [0, 1] as in ``ti.ui``.
    """
    if hasattr(color, "to_numpy") and not isinstance(color, np.ndarray):
        color = color.to_numpy()
    if isinstance(color, numbers.Integral):
        rgb = np.asarray(hex_to_rgb(int(color)), dtype=np.float64)
    else:
        arr = np.asarray(color)
        if arr.dtype.kind in "iu" and arr.ndim <= 1:
            rgb = np.asarray(hex_to_rgb(arr.astype(np.int64)), dtype=np.float64)
        elif arr.dtype.kind == "f" and arr.shape[-1:] == (3,):
            rgb = arr.astype(np.float64)
        elif arr.dtype.kind == "f" and arr.shape[-1:] == (4,):
            rgb = arr[..., :3].astype(np.float64)
        else:
            raise ValueError(
                f"colour must be an int 0xRRGGBB, an int array of shape (n,), or float RGB; got {color!r}"
            )
    if n is None:
        if rgb.ndim != 1:
            raise ValueError(f"expected a single colour, got shape {rgb.shape}")
        return rgb
    if rgb.ndim == 1:
        return np.broadcast_to(rgb, (n, 3))
    if rgb.shape != (n, 3):
        raise ValueError(f"expected {n} colours, got {rgb.shape[0]}")
    return rgb
