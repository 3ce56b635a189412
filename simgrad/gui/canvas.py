"""A numpy raster canvas that draws Taichi-GUI primitives without a display.

The canvas stores float RGB of shape (W, H, 3) in Taichi's convention: the first axis is x (left to
right), the second is y going *up*, and drawing coordinates are normalised so (0, 0) is the
bottom-left corner and (1, 1) the top-right.  Primitives use the coverage rules of Taichi's C++
canvas (circles measure from integer pixel coordinates, lines and triangles from pixel centres)
so pictures match Taichi's; the vectorised sampling and order-exact blending live in
:mod:`.raster`.
"""

from __future__ import annotations

import functools
import math
import numbers
import os

import numpy as np

from . import raster
from .colors import as_rgb

__all__ = ["ImageCanvas", "cook_image", "to_numpy"]

def to_numpy(x):
    """Convert fields (anything with ``to_numpy()``), sequences and arrays to a numpy array."""
    if isinstance(x, np.ndarray):
        return x
    if hasattr(x, "to_numpy"):
        return np.asarray(x.to_numpy())
    return np.asarray(x)


def _image_values(img) -> np.ndarray:
    """The values of an image to read once: a vector field's memory itself when its components sit together
    (lang/field.py `_packed_view`, no to_numpy copy: set_image of a 500x500 RGB field copied it three times),
    else to_numpy."""
    packed = getattr(img, "_packed_view", None)
    view = packed() if callable(packed) and not getattr(img, "sparse", False) else None
    return view if view is not None else to_numpy(img)


def cook_image(img) -> np.ndarray:
    """Convert an image in Taichi's (W, H[, C]) layout to float32 RGB of shape (W, H, 3) (read-only).

    Follows ``ti.GUI.set_image``: unsigned integers are scaled by their maximum, floats are taken as
    [0, 1]; 1 channel is grey, 2 channels are RG (blue = 0), 4 channels drop alpha.
    """
    arr = _image_values(img)
    if arr.dtype.kind == "u":
        arr = arr.astype(np.float32) * np.float32(1.0 / np.iinfo(arr.dtype).max)
    elif arr.dtype.kind in "fb":
        arr = arr.astype(np.float32, copy=False)  # read only: the canvas copies it
    else:
        raise ValueError(f"Data type {arr.dtype} not supported for images (use uint8/16/32 or float)")
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"Image must be grayscale, RG, RGB or RGBA of shape (W, H[, C]); got {arr.shape}")
    channels = arr.shape[2]
    if channels == 1:  # a read-only view: the canvas copies it into its pixels by broadcasting
        return np.broadcast_to(arr, arr.shape[:2] + (3,))
    if channels == 2:
        return np.concatenate([arr, np.zeros(arr.shape[:2] + (1,), np.float32)], axis=2)
    return np.ascontiguousarray(arr[..., :3])


def _points(p) -> np.ndarray:
    """(n, 2) float64 positions from (n, 2), (n, 2, 1) or a single (2,) point."""
    arr = to_numpy(p).astype(np.float64)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"positions must have shape (n, 2), got {arr.shape}")
    return arr


def _per_item(value, n, name) -> np.ndarray:
    """A scalar or an (n,) array as an (n,) float64 array."""
    if isinstance(value, numbers.Real):
        return np.full(n, float(value))
    arr = to_numpy(value).astype(np.float64).reshape(-1)
    if arr.shape == (1,):
        return np.full(n, arr[0])
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a number or an array of shape ({n},), got {arr.shape}")
    return arr


class ImageCanvas:
    """RGB float image of shape (W, H, 3) with anti-aliased, Taichi-compatible drawing primitives.

    Colours are 0xRRGGBB ints, int arrays of shape (n,), or float RGB (a 3-tuple or (n, 3)).
    Positions are normalised; radii and widths are in pixels, as in ``ti.GUI``.
    """

    def __init__(self, res, background=0x000000):
        if isinstance(res, numbers.Number):
            res = (res, res)
        self.res = (int(res[0]), int(res[1]))
        self._img = np.zeros(self.res + (3,), np.float32)
        # Drawing is deferred: primitives are validated and their data copied at once, but rasterised
        # only when the pixels are looked at.  A headless GUI that shows frames without saving them
        # (show() clears) then costs nothing, as Taichi's C++ canvas nearly does.
        self._fill: tuple | None = None
        self._pending: list = []
        # What the buffer holds: ``_clean`` everywhere outside the boxes ``_dirty`` (x0, x1, y0, y1, half-open), or
        # unknown (``_dirty`` None). A clear then refills only what was drawn since the last one: a frame that
        # draws one small circle on a 400 x 400 canvas would otherwise spend most of its time filling.
        self._clean: tuple | None = None
        self._dirty: list | None = None
        self._column: tuple | None = None  # (fill, one column of it)
        self.clear(background)

    @property
    def img(self) -> np.ndarray:
        """The pixels, float32 RGB of shape (W, H, 3), with every pending primitive drawn (read-only: write
        through :meth:`pixels`)."""
        if self._fill is not None:
            self._refill(self._fill)
        pending, self._pending = self._pending, []
        for draw in pending:
            self._note_drawn(draw)
            draw(self._pixels())
        view = self._img.view()
        view.flags.writeable = False
        return view

    @img.setter
    def img(self, value) -> None:
        self._fill, self._pending, self._dirty = None, [], None
        self._img = value

    #: dirty boxes kept apart; more become their union (bounded bookkeeping)
    MAX_BOXES = 16

    def _refill(self, fill) -> None:
        """Every pixel to ``fill``: only the drawn boxes when the rest already holds it. A box is filled with
        one column copied into each of its columns (broadcasting a 3-vector over pixels is ~20x slower)."""
        pixels = self._pixels()
        if self._column is None or self._column[0] != fill:
            self._column = (fill, np.tile(np.asarray(fill, np.float32), (self.res[1], 1)))
        column = self._column[1]
        boxes = [(0, self.res[0], 0, self.res[1])] if self._dirty is None or self._clean != fill else self._dirty
        for x0, x1, y0, y1 in boxes:
            pixels[x0:x1, y0:y1] = column[y0:y1]
        self._fill, self._clean, self._dirty = None, fill, []

    def _note_drawn(self, draw) -> None:
        """Add the boxes ``draw`` may change to the dirty boxes (everything, when it cannot say)."""
        if self._dirty is None:
            return
        bounds = getattr(draw, "bounds", None)
        boxes = bounds(self.res) if bounds is not None else None
        if boxes is None:
            self._dirty = None
            return
        self._dirty += [b for b in boxes if b[0] < b[1] and b[2] < b[3]]
        if len(self._dirty) > self.MAX_BOXES:
            d = np.array(self._dirty)
            self._dirty = [(int(d[:, 0].min()), int(d[:, 1].max()), int(d[:, 2].min()), int(d[:, 3].max()))]

    @property
    def _scale(self):
        return np.array(self.res, dtype=np.float64)

    # -- whole-image operations -------------------------------------------------------------
    def clear(self, color=0x000000):
        """Fill the whole canvas with one colour, dropping what is pending (filled when looked at: one row
        copied into every column, as numpy broadcasting a 3-vector over the image is ~20x slower)."""
        self._fill = tuple(float(v) for v in np.asarray(as_rgb(color), np.float64).reshape(3))
        self._pending = []

    def set_image(self, img):
        """Replace the canvas with an image in (W, H[, C]) layout (see :func:`cook_image`)."""
        arr = cook_image(img)
        if arr.shape[:2] != self.res:
            raise ValueError(f"Image resolution {arr.shape[:2]} does not match canvas resolution {self.res}")
        self.replace(arr)

    def replace_later(self, make_rgb) -> None:
        """``replace(make_rgb())`` when the pixels are next looked at (fast_gui: the window shows packed words,
        the float canvas is only made for reading)."""
        self._fill = None
        self._pending = [lambda img: self.replace(make_rgb())]

    def replace(self, rgb: np.ndarray) -> None:
        """Overwrite every pixel with float RGB of shape (W, H, 3); what was pending is dropped."""
        self._fill, self._pending, self._dirty = None, [], None
        pixels = self._pixels()
        if rgb.strides[-1] != 0:
            pixels[...] = rgb
            return
        # a grey image broadcast: a kernel when a program exists (float32), else a channel at a time (4x faster
        # in numpy than broadcasting)
        k = _kernels() if rgb.dtype == np.float32 else None
        if k is not None:
            k.grey(pixels, rgb[..., 0])
        else:
            for c in range(3):
                pixels[..., c] = rgb[..., 0]

    def pixels(self) -> np.ndarray:
        """The pixel buffer itself (float32 RGB, C-contiguous) with everything pending drawn, for renderers
        that draw into it in place."""
        self.img  # noqa: B018 (draws what is pending)
        self._dirty = None  # the caller may draw anywhere
        return self._pixels()

    def to_uint8(self) -> np.ndarray:
        """The canvas as uint8 RGB of shape (W, H, 3), rounded like ``ti.tools.imwrite``."""
        return (np.clip(np.nan_to_num(self.img), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)

    def to_pil(self):
        """The canvas as a Pillow image (rows top to bottom, as image files store them)."""
        from PIL import Image

        return Image.fromarray(np.ascontiguousarray(self.to_uint8().transpose(1, 0, 2)[::-1]), "RGB")

    def save(self, filename):
        """Write the canvas to an image file; the format follows the extension (PNG if unknown)."""
        from PIL import Image

        ext = os.path.splitext(str(filename))[1].lower()
        fmt = None if ext in Image.registered_extensions() else "PNG"
        self.to_pil().save(filename, format=fmt)

    # -- primitives -------------------------------------------------------------------------
    def circles(self, pos, radius=1.0, color=0xFFFFFF):
        """Filled circles; ``radius`` in pixels (scalar or (n,)).

        Coverage is Taichi's ``clamp(radius - dist)`` measured from integer pixel coordinates.
        """
        c = _points(pos) * self._scale
        n = len(c)
        self._queue(_circles, c, _per_item(radius, n, "radius"), as_rgb(color, n))

    def lines(self, begin, end, radius=1.0, color=0xFFFFFF, vertex_colors=None):
        """Segments with round caps; ``radius`` is the half-width in pixels (scalar or (n,)).

        ``vertex_colors`` (n, 2, 3) float RGB, if given, is interpolated along each segment.
        Consecutive calls with one colour per segment are drawn as one batch (``gui.line`` in a Python
        loop would otherwise pay numpy's per-call set-up, ~0.1 ms, for every segment).
        """
        A = _points(begin) * self._scale
        B = _points(end) * self._scale
        if A.shape != B.shape:
            raise ValueError(f"begin and end must have the same shape, got {A.shape} and {B.shape}")
        n = len(A)
        r = _per_item(radius, n, "radius")
        if vertex_colors is not None:
            self._queue(_lines, A, B, r, np.array(vertex_colors, dtype=np.float64).reshape(n, 2, 3))
        else:
            self._queue(_lines, A, B, r, as_rgb(color, n))

    def circle1(self, x, y, radius, rgb) -> None:
        """One circle at normalised (x, y) from Python floats, ``rgb`` a float 3-tuple: what ``circles`` does with
        one row, queued as a tuple (``gui.circle`` in a Python loop pays no numpy per call)."""
        self._queue_row(_circles, (x * self.res[0], y * self.res[1], radius) + rgb)

    def line1(self, ax, ay, bx, by, radius, rgb) -> None:
        """One segment from Python floats (see :meth:`circle1`)."""
        W, H = self.res
        self._queue_row(_lines, (ax * W, ay * H, bx * W, by * H, radius) + rgb)

    def triangles(self, a, b, c, color=0xFFFFFF, vertex_colors=None, antialias=False):
        """Filled triangles.

        By default a pixel is covered when its centre is inside (edges included), exactly like
        Taichi, which keeps meshes of adjacent triangles free of seams; zero-area triangles draw
        nothing.  ``antialias=True`` uses edge-distance coverage instead.  ``vertex_colors``
        (n, 3, 3) float RGB is interpolated barycentrically.
        """
        P = np.stack([_points(a), _points(b), _points(c)], axis=1) * self._scale
        n = len(P)
        if vertex_colors is not None:
            vc = np.array(vertex_colors, dtype=np.float64).reshape(n, 3, 3)
        else:
            rgb = as_rgb(color, n)
        if not antialias:
            self._queue(_triangles, P, vc if vertex_colors is not None else rgb)
            return
        # antialiased: edge-distance coverage over each triangle's box, by numpy only
        area2 = raster.triangle_area2(P)
        ok = np.isfinite(P).all(axis=(1, 2)) & (area2 != 0)
        lo, hi = raster.empty_invalid(ok, np.floor(P.min(axis=1) - 1), np.ceil(P.max(axis=1) + 1))

        def shade(o, i, j):
            e = raster.edge_functions(P, o, i + 0.5, j + 0.5)
            s = -np.sign(area2[o])
            dists = [s * e[k] / np.hypot(*(P[o, (k + 1) % 3] - P[o, k]).T) for k in range(3)]
            alpha = np.clip(0.5 + np.minimum(np.minimum(dists[0], dists[1]), dists[2]), 0.0, 1.0)
            if vertex_colors is None:
                return alpha, (rgb, o)
            return alpha, _barycentric_colors(P, area2, o, e, vc)

        self._draw(np.arange(n), lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1], shade)

    def rect(self, topleft, bottomright, radius=1.0, color=0xFFFFFF):
        """Rectangle outline: the four sides drawn as segments, as Taichi does."""
        (x0, y0), (x1, y1) = _points(topleft)[0], _points(bottomright)[0]
        corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        self.lines(corners, np.roll(corners, -1, axis=0), radius, as_rgb(color))

    def arrows(self, orig, direction, radius=1.0, color=0xFFFFFF, tip_scale=0.2, angle=45):
        """Arrows: a shaft plus two tip strokes, ``direction`` rotated by +-(180 - angle) degrees."""
        O, D = _points(orig), _points(direction)
        theta = math.radians(180 - angle)
        c, s = math.cos(theta), math.sin(theta)
        tip = O + D
        left = np.stack([D[:, 0] * c - D[:, 1] * s, D[:, 0] * s + D[:, 1] * c], axis=1)
        right = np.stack([D[:, 0] * c + D[:, 1] * s, -D[:, 0] * s + D[:, 1] * c], axis=1)
        self.lines(O, tip, radius, color)
        self.lines(tip, tip + left * tip_scale, radius, color)
        self.lines(tip, tip + right * tip_scale, radius, color)

    def text(self, content, pos, font_size=15, color=0xFFFFFF):
        """Text whose top-left corner is at ``pos``, rendered with Pillow's default font."""
        content = str(content)
        if not content:
            return
        rows, cols, coverage = _text_mask(content, max(1.0, float(font_size)))
        p = _points(pos)[0] * self._scale
        i = int(round(p[0])) + cols
        j = int(round(p[1])) - 1 - rows
        inside = (i >= 0) & (i < self.res[0]) & (j >= 0) & (j < self.res[1])
        rgb = np.broadcast_to(as_rgb(color), (int(inside.sum()), 3))
        alpha = coverage[inside]
        i, j = i[inside], j[inside]
        if not i.size:
            return
        draw = functools.partial(raster.composite, i=i, j=j, alpha=alpha, rgb=rgb)
        box = (int(i.min()), int(i.max()) + 1, int(j.min()), int(j.max()) + 1)
        self._pending.append(_Bounded(draw, [box]))

    # -- rasterisation ----------------------------------------------------------------------
    def _pixels(self):
        if not self._img.flags.c_contiguous or self._img.dtype != np.float32:
            self._img = np.ascontiguousarray(self._img, dtype=np.float32)
        return self._img

    def defer(self, draw) -> None:
        """Queue ``draw(pixels)`` (pixels: float32 (W, H, 3), C-contiguous, changed in place) to run, after
        what is already queued, when the pixels are next looked at."""
        self._pending.append(draw)

    def _draw(self, owner, x0, y0, x1, y1, shade):
        self.defer(lambda img: raster.rasterize(img, owner, x0, y0, x1, y1, shade))

    def _queue(self, draw, *arrays) -> None:
        """Queue ``draw(pixels, *arrays)``; consecutive calls of one ``draw`` with arrays of one shape each
        become one call on their concatenation (a program calling ``gui.line`` in a Python loop then costs one
        draw, not one per segment; compositing is order-exact, so the picture is the same)."""
        last = self._pending[-1] if self._pending else None
        key = (draw, tuple(a.shape[1:] for a in arrays))
        if type(last) is _Batch and last.key == key:
            last.parts.append(arrays)
        else:
            self.defer(_Batch(key, [arrays]))

    def _queue_row(self, draw, row: tuple) -> None:
        """Queue one primitive as a row of floats (see _Rows); consecutive rows of one ``draw`` are one batch."""
        last = self._pending[-1] if self._pending else None
        if type(last) is _Rows and last.key[0] is draw:
            last.parts.append(row)
        else:
            self._pending.append(_Rows((draw,), [row]))


@functools.lru_cache(maxsize=1024)
def _text_mask(content: str, size: float):
    """(rows, columns, coverage in [0, 1]) of the pixels `content` covers at `size`: rendered once, as programs
    draw the same labels every frame (Pillow's font set-up and rendering cost ~0.4 ms a call)."""
    from PIL import Image, ImageDraw, ImageFont

    try:
        font = ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 has a single bitmap font
        font = ImageFont.load_default()
    left, top, right, bottom = ImageDraw.Draw(Image.new("L", (1, 1))).textbbox((0, 0), content, font=font)
    mask = Image.new("L", (max(1, int(right)), max(1, int(bottom))))
    ImageDraw.Draw(mask).text((0, 0), content, fill=255, font=font)
    m = np.asarray(mask, dtype=np.float64) / 255.0
    rows, cols = np.nonzero(m)
    for a in (rows, cols):
        a.flags.writeable = False
    coverage = m[rows, cols]
    coverage.flags.writeable = False
    return rows, cols, coverage


class _Bounded:
    """A pending drawing that changes only pixels in ``boxes`` (x0, x1, y0, y1, half-open)."""

    def __init__(self, draw, boxes):
        self.draw, self.boxes = draw, boxes

    def __call__(self, img) -> None:
        self.draw(img)

    def bounds(self, res):
        return self.boxes


class _Batch:
    """Primitives of one kind queued by consecutive calls, drawn together when the pixels are looked at."""

    def __init__(self, key, parts: list):
        self.key, self.parts = key, parts
        self._made: tuple | None = None  # (parts made, their arrays): bounds() and the draw share them

    def _arrays(self):
        if self._made is None or self._made[0] != len(self.parts):
            self._made = (len(self.parts), self._make())
        return self._made[1]

    def _make(self):
        return self.parts[0] if len(self.parts) == 1 else [np.concatenate(a) for a in zip(*self.parts)]

    def __call__(self, img) -> None:
        self.key[0](img, *self._arrays())

    def bounds(self, res):
        """The boxes the batch may draw in (its primitives' boxes padded by a pixel: each, when there are few,
        else their union), None when unknown."""
        arrays = self._arrays()
        if len(arrays[0]) > ImageCanvas.MAX_BOXES:  # one box around them all, from per-axis extremes (an (n, 2)
            lo, hi = _union_extent(self.key[0], *arrays)  # reduction along axis 0 is ~20x slower than two 1-D ones)
        else:
            lo, hi = _EXTENT[self.key[0]](*arrays)
        if np.isnan(lo).any() or np.isnan(hi).any():
            return None
        lo, hi = np.clip(np.floor(lo) - 1, 0, res), np.clip(np.ceil(hi) + 2, 0, res)
        return [(int(a), int(b), int(c), int(d)) for a, c, b, d in np.concatenate([lo, hi], axis=1).tolist()]


# The primitives are drawn by simgrad kernels (render2d.py: tiles in parallel, the numpy rasteriser's coverage and
# order) once a program exists; before ti.init() by the numpy rasteriser itself, so a GUI needs no program.
def _kernels():
    from simgrad.lang import program

    if program._program is None:
        return None
    from . import render2d

    return render2d


def _circles(img, c, r, rgb) -> None:
    k = _kernels()
    if k is not None:
        return k.circles(img, c, r, rgb)
    if len(c) <= _FEW:
        for k in range(len(c)):
            _circle_in_box(img, c[k, 0], c[k, 1], r[k], rgb[k])
        return
    ok = np.isfinite(c).all(axis=1) & np.isfinite(r) & (r > 0)
    lo, hi = raster.empty_invalid(ok, np.ceil(c - r[:, None]), np.floor(c + r[:, None]))

    def shade(o, i, j):
        dist = np.hypot(c[o, 0] - i, c[o, 1] - j)
        return np.clip(r[o] - dist, 0.0, 1.0), (rgb, o)

    raster.rasterize(img, np.arange(len(c)), lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1], shade)


# At most this many circles are drawn one after another on their boxes' slices (the sample lists and sort of
# raster.rasterize cost ~0.1 ms however few pixels are drawn; ``gui.circle`` once a frame is common).
_FEW = 4


def _circle_in_box(img, cx, cy, r, rgb) -> None:
    """One circle blended in place as render2d's kernel blends it: coverage clamp(r - distance) from integer
    pixel coordinates, ``dest * (1 - a) + rgb * a`` in float64, opaque samples replace the pixel."""
    if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r) and r > 0):
        return
    W, H = img.shape[:2]
    i0, i1 = max(math.ceil(cx - r), 0), min(math.floor(cx + r), W - 1)
    j0, j1 = max(math.ceil(cy - r), 0), min(math.floor(cy + r), H - 1)
    if i0 > i1 or j0 > j1:
        return
    part, ap, keep, full = _circle_cover(cx, cy, r, i0, i1, j0, j1, H)
    flat = img.reshape(-1)  # C-contiguous (ImageCanvas._pixels): the pixels' channels by flat index
    col = np.asarray(rgb, np.float64)
    flat[part] = flat[part] * keep + col * ap
    flat[full] = col


@functools.lru_cache(maxsize=16)
def _circle_cover(cx, cy, r, i0, i1, j0, j1, H):
    """(partly covered pixels, their coverage a and 1 - a as columns, fully covered pixels) of a circle's box in
    an image of height H, the pixels as (n, 3) flat indices of their channels (boolean masks of the box's view
    cost a radius-8 circle 9 us, these 5): kept for the circles drawn again in the next frame (a cursor, a
    marker), the geometry being most of the work."""
    dx = cx - np.arange(i0, i1 + 1, dtype=np.float64)
    dy = cy - np.arange(j0, j1 + 1, dtype=np.float64)
    d2 = np.add.outer(dx * dx, dy * dy)
    a = r - np.sqrt(d2, out=d2)
    part = (a > 0.0) & (a < 1.0)
    ap = a[part][:, None]

    def channels(mask):
        i, j = np.nonzero(mask)
        return ((i + i0) * H + (j + j0))[:, None] * 3 + np.arange(3)

    cover = (channels(part), ap, 1.0 - ap, channels(a >= 1.0))
    for x in cover:
        x.flags.writeable = False  # shared by later calls
    return cover


def _lines(img, A, B, r, colors) -> None:
    """Segments A -> B of half-width r: ``colors`` (n, 3) one each, or (n, 2, 3) interpolated along each."""
    vc = colors if colors.ndim == 3 else None
    k = _kernels()
    if k is not None:
        return k.lines(img, A, B, r, colors if vc is None else None, vertex_colors=vc)
    ok = np.isfinite(A).all(axis=1) & np.isfinite(B).all(axis=1) & np.isfinite(r) & (r > 0)
    seg = raster.SegmentPieces(A, B, r, ok, img.shape[:2])
    owner, k_, pieces, ta, span_all = seg.owner, seg.k, seg.pieces, seg.ta, seg.span
    A, D, L2 = seg.A, seg.D, seg.L2

    def shade(b, i, j):
        o = owner[b]
        px, py = i + 0.5 - A[o, 0], j + 0.5 - A[o, 1]
        dx, dy, l2 = D[o, 0], D[o, 1], L2[o]
        t = np.where(l2 > 0, np.clip((px * dx + py * dy) / np.where(l2 > 0, l2, 1.0), 0.0, 1.0), 0.0)
        alpha = np.clip(r[o] - np.hypot(px - t * dx, py - t * dy), 0.0, 1.0)
        # Piece boxes overlap; a pixel belongs to the piece holding its nearest point.
        p = pieces[o]
        alpha[np.minimum((t * p).astype(np.int64), p - 1) != k_[b]] = 0.0
        if vc is None:
            return alpha, (colors, o)
        t = (ta[o] + t * span_all[o])[:, None]
        return alpha, vc[o, 0] * (1 - t) + vc[o, 1] * t

    raster.rasterize(img, owner, seg.x0, seg.y0, seg.x1, seg.y1, shade)


def _triangles(img, P, colors) -> None:
    """Triangles covering the pixel centres inside them: ``colors`` (n, 3) one each or (n, 3, 3) per vertex."""
    vc = colors if colors.ndim == 3 else None
    k = _kernels()
    if k is not None:
        return k.triangles(img, P, colors if vc is None else None, vertex_colors=vc)
    owner, x0, y0, x1 = raster.triangle_spans(P, np.isfinite(P).all(axis=(1, 2)), img.shape[:2])
    area2 = raster.triangle_area2(P)

    def shade(b, i, j):  # spans hold exactly the covered pixels
        o = owner[b]
        if vc is None:
            return np.ones(o.size), (colors, o)
        return np.ones(o.size), _barycentric_colors(P, area2, o, raster.edge_functions(P, o, i + 0.5, j + 0.5), vc)

    raster.rasterize(img, owner, x0, y0, x1, y0, shade)


def _barycentric_colors(P, area2, o, e, vc):
    """Per-vertex colours ``vc`` of triangles ``o`` at samples with edge functions ``e``: the weight of a vertex is
    the edge function of the opposite edge over -area2."""
    w = np.stack([e[1], e[2], e[0]], axis=1) / -area2[o][:, None]
    w = np.clip(w, 0.0, 1.0)
    w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    return np.einsum("sk,skc->sc", w, vc[o])


class _Rows(_Batch):
    """One-primitive calls queued as float rows (the arrays of the kind's array call side by side: centre, radius
    and colour of a circle; start, end, half-width and colour of a segment), made arrays when drawn."""

    def _make(self):
        rows = np.array(self.parts, np.float64)
        if self.key[0] is _circles:
            return rows[:, 0:2], rows[:, 2], rows[:, 3:6]
        return rows[:, 0:2], rows[:, 2:4], rows[:, 4], rows[:, 5:8]

    def bounds(self, res):
        if len(self.parts) > ImageCanvas.MAX_BOXES:
            return super().bounds(res)
        # a few rows: their boxes in Python, padded as _Batch pads (numpy's set-up cost 10 segments 22 us, this 6)
        boxes = []
        W, H = res
        for row in self.parts:
            if self.key[0] is _circles:
                x, y, r = row[0], row[1], row[2]
                lx, ly, hx, hy = x - r, y - r, x + r, y + r
            else:
                ax, ay, bx, by, r = row[0], row[1], row[2], row[3], row[4]
                lx, ly, hx, hy = min(ax, bx) - r, min(ay, by) - r, max(ax, bx) + r, max(ay, by) + r
            if lx != lx or ly != ly or hx != hx or hy != hy:  # NaN
                return None
            boxes.append((_box_lo(lx, W), _box_hi(hx, W), _box_lo(ly, H), _box_hi(hy, H)))
        return boxes


def _box_lo(v: float, n: int) -> int:
    """floor(v) - 1 clipped to [0, n] (v not NaN, maybe infinite)."""
    return 0 if v < 1.0 else n if v >= n + 1 else math.floor(v) - 1


def _box_hi(v: float, n: int) -> int:
    """ceil(v) + 2 clipped to [0, n] (v not NaN, maybe infinite)."""
    return 0 if v <= -2.0 else n if v > n - 2 else math.ceil(v) + 2


def _union_extent(draw, *arrays):
    """(1, 2) corners around every primitive of a batch (a superset of _EXTENT's union: the largest radius at the
    extreme centres), NaN when any coordinate is NaN (np.min and np.max propagate it)."""
    if draw is _triangles:
        points, pad = arrays[0].reshape(-1, 2), 0.0
    elif draw is _circles:
        points, pad = arrays[0], arrays[1].max(initial=0.0)
    else:
        points, pad = np.concatenate([arrays[0], arrays[1]]), arrays[2].max(initial=0.0)
    x, y = points[:, 0], points[:, 1]
    return np.array([[x.min() - pad, y.min() - pad]]), np.array([[x.max() + pad, y.max() + pad]])


# Per primitive kind: the (n, 2) lower and upper corners of what its arguments may cover, in pixels.
_EXTENT = {
    _circles: lambda c, r, rgb: (c - r[:, None], c + r[:, None]),
    _lines: lambda A, B, r, colors: (np.minimum(A, B) - r[:, None], np.maximum(A, B) + r[:, None]),
    _triangles: lambda P, colors: (P.min(axis=1), P.max(axis=1)),
}
