"""The ``ti.ui`` canvas's 2-D primitives (circles, lines, triangles) drawn by simgrad kernels.

Coverage follows the numpy rasteriser (raster.py, canvas.py), which follows Taichi's C++ canvas: circles
are anti-aliased by ``clamp(r - distance)`` from integer pixel coordinates, lines by the same from pixel
centres to the segment, triangles cover the pixel centres inside them (edges included, per-vertex
colours barycentric).  Each covered pixel is blended ``dest * (1 - a) + colour * a``, so the primitives of
one call must land on a pixel in index order.  Parallelising over primitives would race and reorder, so
the image is cut into TILE x TILE tiles: numpy bins every primitive's pixel box into the tiles it touches
(a stable sort keeps index order within a tile), and a kernel loops over tiles in parallel, each thread
drawing its tile's primitives one after another.  Long segments are cut into short pieces first
(:class:`.raster.SegmentPieces`) so their boxes stay tight.

Geometry and blending are float64, as in numpy, so pictures agree with the numpy rasteriser to float32
rounding.  Kernels take ndarrays only: nothing lands in the user's SNode tree and they re-instantiate on
whatever program ``ti.init`` made last (as render3d.py's).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

import simgrad as ti

from . import raster

__all__ = ["TILE", "bin_boxes", "circles", "grey", "lines", "triangles"]

TILE = 16

#: one segment's pixels in a column are visited in runs of a multiple of this many (the vector width the
#: loop vectoriser picks for it with AVX-512)
RUN = 16
#: how far past the half-width a segment's pixels are still visited: rounding slack only (the visited range
#: only bounds the work; a visited pixel the segment does not cover is written back unchanged)
NEAR_MARGIN = 1.0e-3

if TYPE_CHECKING:  # kernel parameter annotations are simgrad types, opaque to mypy
    _IMG: TypeAlias = Any
    _I1: TypeAlias = Any
    _B1: TypeAlias = Any
    _G2: TypeAlias = Any
    _F1: TypeAlias = Any
    _F2: TypeAlias = Any
    _C1: TypeAlias = Any
    _I32: TypeAlias = Any
    _ROWS: TypeAlias = Any
else:
    _IMG = ti.types.ndarray(dtype=ti.types.vector(3, ti.f32), ndim=2)
    _I1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
    _B1 = ti.types.ndarray(dtype=ti.types.vector(4, ti.i32), ndim=1)
    _G2 = ti.types.ndarray(dtype=ti.f64, ndim=2)
    _F1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
    _F2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
    _C1 = ti.types.ndarray(dtype=ti.types.vector(3, ti.f64), ndim=1)
    _I32 = ti.i32
    _ROWS = ti.template()  # a compile-time row count (_circle_runs, _segment_runs)


#: on a GPU, at most this many primitives are drawn as one tile covering the image (``tiles_y`` 0): one thread
#: draws them in call order, with no binning. On the CPU every call is one tile: binning (numpy boxes and a
#: counting sort) costs more than drawing small primitives, so tiles lost even on two threads (200k circles of
#: radius 1.5: 42 ms tiled on two threads, 16 ms as one tile)
SERIAL_MAX = 256
#: the narrowest band of columns a thread draws (_bands)
BAND_MIN = 32


def _one_tile(n: int) -> bool:
    """Whether n primitives are drawn as one tile (see SERIAL_MAX)."""
    from simgrad.lang.program import get_program

    return n <= SERIAL_MAX or not get_program().on_gpu


def _bands(img) -> int:
    """Column bands a CPU draws in parallel: one a thread, none narrower than BAND_MIN columns."""
    from simgrad.lang.program import get_program

    return max(1, min(get_program().config.num_threads, img.shape[0] // BAND_MIN))


def bin_boxes(x0, y0, x1, y1, res):
    """Tile lists of pixel boxes (inclusive, in drawing order; clipped here): returns ``start`` (one more
    than the tile count) and ``items`` (box indices), tile ``t`` holding ``items[start[t]:start[t + 1]]`` in
    ascending order, the clipped boxes as int32 (n, 4), and ``tiles_y`` (0: one tile, the whole image).
    Tiles are numbered x-major.  The lists are filled by a serial kernel (a counting sort: cheaper than numpy's
    repeat/sort chain)."""
    W, H = res
    x0 = np.clip(x0, 0, W).astype(np.int32)
    y0 = np.clip(y0, 0, H).astype(np.int32)
    x1 = np.clip(x1, -1, W - 1).astype(np.int32)
    y1 = np.clip(y1, -1, H - 1).astype(np.int32)
    boxes = np.stack([x0, y0, x1, y1], axis=1)
    if _one_tile(len(boxes)):
        return np.array([0, len(boxes)], np.int32), np.arange(len(boxes), dtype=np.int32), boxes, 0
    tiles_y = -(-H // TILE)
    n_tiles = -(-W // TILE) * tiles_y
    count = (x1 // TILE - x0 // TILE + 1) * (y1 // TILE - y0 // TILE + 1)
    total = int(count[(x1 >= x0) & (y1 >= y0)].sum(dtype=np.int64))
    start = np.zeros(n_tiles + 1, np.int32)
    items = np.empty(max(total, 1), np.int32)
    if total:
        _bin(boxes, start, np.empty(n_tiles, np.int32), items, tiles_y)
    return start, items[:total], boxes, tiles_y


@ti.kernel
def _bin(boxes: _B1, start: _I1, cursor: _I1, items: _I1, tiles_y: _I32):
    """Counting sort of the boxes' (tile, box) pairs by tile; serial loops keep box order within a tile."""
    for p in range(boxes.shape[0]):  # start[t + 1] = pairs in tile t (parallel, atomic)
        b = boxes[p]
        if b[2] >= b[0] and b[3] >= b[1]:
            for tx in range(b[0] // TILE, b[2] // TILE + 1):
                for ty in range(b[1] // TILE, b[3] // TILE + 1):
                    ti.atomic_add(start[tx * tiles_y + ty + 1], 1)
    ti.loop_config(serialize=True)
    for t in range(cursor.shape[0]):
        start[t + 1] += start[t]
        cursor[t] = start[t]
    ti.loop_config(serialize=True)
    for p in range(boxes.shape[0]):
        b = boxes[p]
        if b[2] >= b[0] and b[3] >= b[1]:
            for tx in range(b[0] // TILE, b[2] // TILE + 1):
                for ty in range(b[1] // TILE, b[3] // TILE + 1):
                    t = tx * tiles_y + ty
                    items[cursor[t]] = p
                    cursor[t] += 1


@ti.func
def _tile(t, tiles_y, W, H):
    """Pixel range [x0, x1] x [y0, y1] of tile ``t`` (the whole image when ``tiles_y`` is 0)."""
    x0, x1, y0, y1 = 0, W - 1, 0, H - 1
    if tiles_y > 0:
        tx = t // tiles_y
        ty = t - tx * tiles_y
        x0, x1, y0, y1 = tx * TILE, ti.min(tx * TILE + TILE, W) - 1, ty * TILE, ti.min(ty * TILE + TILE, H) - 1
    return x0, x1, y0, y1


@ti.func
def _blend(img, i, j, a, c):
    """``lerp(a, dest, c)`` in float64; an opaque sample replaces the pixel (even a NaN one), one with no
    coverage keeps it (written back as it was: selects, no branch per pixel)."""
    old = img[i, j]
    mixed = ti.cast(ti.cast(old, ti.f64) * (1.0 - a) + c * a, ti.f32)
    img[i, j] = ti.select(a >= 1.0, ti.cast(c, ti.f32), ti.select(a > 0.0, mixed, old))


@ti.func
def _circle(img, i0, i1, j0, j1, cx, cy, r, c):
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            _circle_pixel(img, i, j, cx, cy, r, c)


@ti.func
def _circle_runs(img, i0, i1, j0, rows: _ROWS, cx, cy, r, c):
    """Columns i0..i1 of a small circle, each the same `rows` rows from j0 (moved up to fit the image): a loop of
    constant trip count that vectorises, where a 7-row column is all scalar remainder code. Fewer than RUN (16)
    trips carry the vectorize hint: LLVM leaves loops of fewer than 16 scalar otherwise."""
    jb = ti.min(j0, img.shape[1] - rows)
    for i in range(i0, i1 + 1):
        if ti.static(rows < RUN):
            ti.loop_config(vectorize=True)
        for dj in range(rows):
            _circle_pixel(img, i, jb + dj, cx, cy, r, c)


@ti.func
def _circle_pixel(img, i, j, cx, cy, r, c):
    """Coverage clamp(r - distance) from integer pixel coordinates, blended."""
    dx = cx - i
    dy = cy - j
    _blend(img, i, j, ti.min(ti.max(r - ti.sqrt(dx * dx + dy * dy), 0.0), 1.0), c)


@ti.func
def _band_columns(img, band, bands):
    """The first and last column of band `band` of `bands` (see _bands)."""
    width = (img.shape[0] + bands - 1) // bands
    first = band * width
    return first, ti.min(first + width, img.shape[0]) - 1


@ti.func
def _finite(x):
    return ti.abs(x) <= 1.7976931348623157e308  # false for NaN and +-inf


@ti.kernel
def _circles_in_order(img: _IMG, centers: _G2, radii: _F1, colors: _C1, each: _I32, bands: _I32):
    """Every circle in call order, in ``bands`` bands of columns as _lines_in_order, its pixel box computed here
    as numpy computes it for the tiles (the one-tile case needs no numpy boxes: at 200k circles a frame they cost
    as much as drawing).
    Circle p takes colour ``colors[p * each]`` (``each`` 0: one colour for all)."""
    w = ti.cast(img.shape[0], ti.f64)
    h = ti.cast(img.shape[1], ti.f64)
    ti.loop_config(block_dim=1)  # a band a task
    for band in range(bands):
        first, last = _band_columns(img, band, bands)
        for p in range(centers.shape[0]):
            cx = centers[p, 0]
            cy = centers[p, 1]
            r = radii[p]
            if _finite(cx) and _finite(cy) and _finite(r) and r > 0.0:
                i0 = ti.max(ti.cast(ti.min(ti.max(ti.ceil(cx - r), 0.0), w), ti.i32), first)
                i1 = ti.min(ti.cast(ti.min(ti.max(ti.floor(cx + r), -1.0), w - 1.0), ti.i32), last)
                j0 = ti.cast(ti.min(ti.max(ti.ceil(cy - r), 0.0), h), ti.i32)
                j1 = ti.cast(ti.min(ti.max(ti.floor(cy + r), -1.0), h - 1.0), ti.i32)
                c = colors[p * each]
                if i1 - i0 <= 1 and j1 - j0 <= 1:  # at most 2 x 2 pixels (a particle): no loops to set up
                    for di in ti.static(range(2)):
                        for dj in ti.static(range(2)):
                            i = i0 + di
                            j = j0 + dj
                            if i <= i1 and j <= j1:
                                _circle_pixel(img, i, j, cx, cy, r, c)
                elif j1 - j0 < RUN // 2 and img.shape[1] >= RUN:  # (radius < 3.5: half the rows)
                    _circle_runs(img, i0, i1, j0, RUN // 2, cx, cy, r, c)
                elif j1 - j0 < RUN and img.shape[1] >= RUN:
                    # a small circle: every column visits the same rows from the box's top (see _circle_runs); the
                    # rows past the box are further than r from the centre, coverage 0, written back as they were
                    _circle_runs(img, i0, i1, j0, RUN, cx, cy, r, c)
                else:
                    _circle(img, i0, i1, j0, j1, cx, cy, r, c)


@ti.kernel
def _circles(img: _IMG, start: _I1, items: _I1, boxes: _B1, geo: _G2, colors: _C1, tiles_y: _I32):
    """``geo`` rows: centre x, y and radius in pixels."""
    for t in range(start.shape[0] - 1):
        tx0, tx1, ty0, ty1 = _tile(t, tiles_y, img.shape[0], img.shape[1])
        for k in range(start[t], start[t + 1]):
            p = items[k]
            b = boxes[p]
            cx = geo[p, 0]
            cy = geo[p, 1]
            r = geo[p, 2]
            _circle(img, ti.max(b[0], tx0), ti.min(b[2], tx1), ti.max(b[1], ty0), ti.min(b[3], ty1), cx, cy, r,
                    colors[p])


@ti.func
def _segment_cover(px, py, dx, dy, l2, r):
    """(s, coverage) of the pixel centre at (px, py) from the segment's start, direction (dx, dy) and squared
    length l2: s the parameter of its nearest point, coverage clamp(r - distance) (raster.py's, in float64;
    selects, no branch)."""
    s = ti.select(l2 > 0.0, ti.min(ti.max((px * dx + py * dy) / ti.select(l2 > 0.0, l2, 1.0), 0.0), 1.0), 0.0)
    ex = px - s * dx
    ey = py - s * dy
    return s, ti.min(ti.max(r - ti.sqrt(ex * ex + ey * ey), 0.0), 1.0)


@ti.kernel
def _lines(img: _IMG, start: _I1, items: _I1, boxes: _B1, owner: _I1, piece: _I1, geo: _G2, c0: _C1, c1: _C1,
           per_vertex: _I32, tiles_y: _I32):
    """Items are segment pieces; ``geo`` rows per segment: clipped start x, y, direction x, y, squared length,
    half-width, pieces, ``ta`` and ``span`` (where the clipped segment lies on the original one)."""
    for t in range(start.shape[0] - 1):
        tx0, tx1, ty0, ty1 = _tile(t, tiles_y, img.shape[0], img.shape[1])
        for k in range(start[t], start[t + 1]):
            q = items[k]
            b = boxes[q]
            o = owner[q]
            ax = geo[o, 0]
            ay = geo[o, 1]
            dx = geo[o, 2]
            dy = geo[o, 3]
            l2 = geo[o, 4]
            r = geo[o, 5]
            n = ti.cast(geo[o, 6], ti.i32)
            # pixels at least r from the segment's line are skipped before the division and square root
            band = (r + 1e-6) * (r + 1e-6) * l2
            for i in range(ti.max(b[0], tx0), ti.min(b[2], tx1) + 1):
                px = i + 0.5 - ax
                for j in range(ti.max(b[1], ty0), ti.min(b[3], ty1) + 1):
                    py = j + 0.5 - ay
                    cross = px * dy - py * dx
                    if l2 > 0.0 and cross * cross >= band:
                        continue
                    s, a = _segment_cover(px, py, dx, dy, l2, r)
                    # piece boxes overlap: a pixel belongs to the piece holding its nearest point
                    if a > 0.0 and ti.min(ti.cast(s * n, ti.i32), n - 1) == piece[q]:
                        c = c0[o]
                        if per_vertex != 0:
                            u = geo[o, 7] + s * geo[o, 8]
                            c = c0[o] * (1.0 - u) + c1[o] * u
                        _blend(img, i, j, a, c)


@ti.func
def _segment_pixel(img, i, j, ax, ay, dx, dy, l2, r, ta, span, c0, c1, per_vertex):
    """One pixel of a segment as ``_lines`` shades it, without branches (the loops over a row or column of
    pixels vectorise): a pixel the segment does not cover is written back as it was."""
    s, alpha = _segment_cover(i + 0.5 - ax, j + 0.5 - ay, dx, dy, l2, r)
    u = ta + s * span
    c = ti.select(per_vertex != 0, c0 * (1.0 - u) + c1 * u, c0)
    _blend(img, i, j, alpha, c)


@ti.func
def _segment_runs(img, i0, i1, j0, rows: _ROWS, ax, ay, dx, dy, l2, r, ta, span, c0, c1, per_vertex):
    """Columns i0..i1 of a short segment, each the same `rows` rows from j0 (moved up to fit the image; see
    _circle_runs)."""
    jb = ti.min(j0, img.shape[1] - rows)
    for i in range(i0, i1 + 1):
        if ti.static(rows < RUN):
            ti.loop_config(vectorize=True)
        for dj in range(rows):
            _segment_pixel(img, i, jb + dj, ax, ay, dx, dy, l2, r, ta, span, c0, c1, per_vertex)


@ti.func
def _near(p, a, d, pad):
    """The parameter range [s0, s1] within [0, 1] where a + s d is within ``pad`` of ``p`` (empty: s0 > s1)."""
    s0 = ti.cast(0.0, ti.f64)
    s1 = ti.cast(1.0, ti.f64)
    if d != 0.0:
        inv = 1.0 / d  # (a reciprocal: the range only bounds the pixels visited; pad has a margin for it)
        u = (p - pad - a) * inv
        v = (p + pad - a) * inv
        s0 = ti.max(s0, ti.min(u, v))
        s1 = ti.min(s1, ti.max(u, v))
    elif ti.abs(p - a) > pad:
        s1 = -1.0
    return s0, s1


@ti.kernel
def _lines_in_order(img: _IMG, ends: _G2, c0: _C1, c1: _C1, colouring: _I32, bands: _I32):
    """Every segment in call order, the image's columns cut into ``bands`` bands drawn in parallel (each pixel in
    one band, so its segments land on it in call order; no binning: every band looks at every segment). ``ends``
    rows: start x, y, end x, y and half-width in pixels; ``colouring`` 2: per-vertex colours ``c0`` to ``c1``,
    1: ``c0`` per segment, 0: ``c0``'s one row for all. Each segment is clipped as raster.clip_segments clips it
    and shaded as ``_lines`` shades (the same float64 operations, so the same pixels), but without pieces: each
    column of pixels visits only the run of rows near the part of the segment within ``r`` of it, each pixel once.
    Runs go along the image's contiguous axis, whatever the segment's direction: a loop across columns did not
    vectorise, and rows first for mostly horizontal segments (scalar) was slower (7 full-width lines 81 -> 97 us)."""
    w = ti.cast(img.shape[0], ti.f64)
    h = ti.cast(img.shape[1], ti.f64)
    ti.loop_config(block_dim=1)  # a band a task
    for band in range(bands):
        first, last = _band_columns(img, band, bands)
        for o in range(ends.shape[0]):
            ax0 = ends[o, 0]
            ay0 = ends[o, 1]
            r = ends[o, 4]
            dx0 = ends[o, 2] - ax0
            dy0 = ends[o, 3] - ay0
            if _finite(ax0) and _finite(ay0) and _finite(ends[o, 2]) and _finite(ends[o, 3]) and _finite(r) and r > 0.0:
                pad = r + 1.0
                ta = ti.cast(0.0, ti.f64)
                tb = ti.cast(1.0, ti.f64)
                for axis in ti.static(range(2)):
                    a = ax0 if axis == 0 else ay0
                    d = dx0 if axis == 0 else dy0
                    hi = (w if axis == 0 else h) + pad
                    if d != 0.0:
                        t_lo = (-pad - a) / d
                        t_hi = (hi - a) / d
                        ta = ti.max(ta, ti.min(t_lo, t_hi))
                        tb = ti.min(tb, ti.max(t_lo, t_hi))
                    elif a < -pad or a > hi:
                        tb = -1.0
                if tb >= ta:
                    span = tb - ta
                    ax = ax0 + dx0 * ta
                    ay = ay0 + dy0 * ta
                    dx = dx0 * span
                    dy = dy0 * span
                    l2 = dx * dx + dy * dy
                    ca = c0[o * ti.min(colouring, 1)]  # colouring 0: one colour for all (c0 has one row)
                    cb = c1[o * ti.min(colouring, 1)]
                    per_vertex = ti.cast(colouring == 2, ti.i32)
                    # a pixel is covered only when its centre lies within r of the segment, so columns and rows
                    # are visited within r (and a rounding margin) of it: pixel centres sit at +0.5
                    near = r + NEAR_MARGIN
                    i0 = ti.max(ti.cast(ti.max(ti.floor(ti.min(ax, ax + dx) - near - 0.5), 0.0), ti.i32), first)
                    i1 = ti.min(ti.cast(ti.min(ti.ceil(ti.max(ax, ax + dx) + near - 0.5), w - 1.0), ti.i32), last)
                    jb = ti.cast(ti.max(ti.floor(ti.min(ay, ay + dy) - near - 0.5), 0.0), ti.i32)
                    je = ti.cast(ti.min(ti.ceil(ti.max(ay, ay + dy) + near - 0.5), h - 1.0), ti.i32)
                    if je - jb < RUN and img.shape[1] >= RUN:
                        # a short segment: every column visits the same RUN rows from the box's top (half as many
                        # for a mostly horizontal stroke), a loop of constant trip count (no per-column range, no
                        # run-time checks before the vector code)
                        if je - jb < RUN // 2:
                            _segment_runs(img, i0, i1, jb, RUN // 2, ax, ay, dx, dy, l2, r, ta, span, ca, cb,
                                          per_vertex)
                        else:
                            _segment_runs(img, i0, i1, jb, RUN, ax, ay, dx, dy, l2, r, ta, span, ca, cb, per_vertex)
                    else:
                        for i in range(i0, i1 + 1):
                            s0, s1 = _near(i + 0.5, ax, dx, near)
                            if s0 <= s1:
                                y0 = ay + s0 * dy
                                y1 = ay + s1 * dy
                                j0 = ti.cast(ti.max(ti.floor(ti.min(y0, y1) - near - 0.5), 0.0), ti.i32)
                                j1 = ti.cast(ti.min(ti.ceil(ti.max(y0, y1) + near - 0.5), h - 1.0), ti.i32)
                                # a run rounded up to whole vectors of RUN pixels (more pixels, each as before,
                                # written back unchanged), so short runs take the vector loop too
                                n = (j1 - j0 + RUN) // RUN * RUN
                                j1 = ti.min(j0 + n - 1, img.shape[1] - 1)
                                j0 = ti.max(j1 - n + 1, 0)
                                for j in range(j0, j1 + 1):
                                    _segment_pixel(img, i, j, ax, ay, dx, dy, l2, r, ta, span, ca, cb, per_vertex)


@ti.func
def _edge(ux, uy, vx, vy, px, py):
    """Taichi's edge function cross(p - u, v - u), in raster.edge_functions' operation order."""
    return (px - ux) * (vy - uy) - (py - uy) * (vx - ux)


@ti.kernel
def _triangles(img: _IMG, start: _I1, items: _I1, boxes: _B1, geo: _G2, colors: _G2, per_vertex: _I32,
               tiles_y: _I32):
    """``geo`` rows: the vertices (x, y) * 3 in pixels and twice the signed area; ``colors`` rows: one RGB,
    or three (one per vertex) when ``per_vertex``."""
    for t in range(start.shape[0] - 1):
        tx0, tx1, ty0, ty1 = _tile(t, tiles_y, img.shape[0], img.shape[1])
        for k in range(start[t], start[t + 1]):
            p = items[k]
            b = boxes[p]
            x0 = geo[p, 0]
            y0 = geo[p, 1]
            x1 = geo[p, 2]
            y1 = geo[p, 3]
            x2 = geo[p, 4]
            y2 = geo[p, 5]
            area2 = geo[p, 6]
            c = ti.Vector([colors[p, 0], colors[p, 1], colors[p, 2]])
            for i in range(ti.max(b[0], tx0), ti.min(b[2], tx1) + 1):
                px = i + 0.5
                for j in range(ti.max(b[1], ty0), ti.min(b[3], ty1) + 1):
                    py = j + 0.5
                    e0 = _edge(x0, y0, x1, y1, px, py)
                    e1 = _edge(x1, y1, x2, y2, px, py)
                    e2 = _edge(x2, y2, x0, y0, px, py)
                    # Taichi's test: the centre on the inner side of all three edges, ties included
                    inside = (e0 <= 0.0) == (e1 <= 0.0) and (e0 <= 0.0) == (e2 <= 0.0)
                    if inside:
                        if per_vertex != 0:
                            # a vertex's weight is the opposite edge's function over -area2
                            w0 = ti.min(ti.max(e1 / -area2, 0.0), 1.0)
                            w1 = ti.min(ti.max(e2 / -area2, 0.0), 1.0)
                            w2 = ti.min(ti.max(e0 / -area2, 0.0), 1.0)
                            norm = ti.max(w0 + w1 + w2, 1e-12)
                            w0 /= norm
                            w1 /= norm
                            w2 /= norm
                            c = ti.Vector([w0 * colors[p, 0] + w1 * colors[p, 3] + w2 * colors[p, 6],
                                           w0 * colors[p, 1] + w1 * colors[p, 4] + w2 * colors[p, 7],
                                           w0 * colors[p, 2] + w1 * colors[p, 5] + w2 * colors[p, 8]])
                        _blend(img, i, j, 1.0, c)


@ti.kernel
def _grey(img: _IMG, values: _F2):
    """Every pixel's three channels set to its grey value (numpy's three strided channel copies took 3x as
    long: grey set_image of a 512 x 512 field, taichi_logo's whole frame)."""
    for i, j in ti.ndrange(img.shape[0], img.shape[1]):
        v = values[i, j]
        img[i, j] = ti.Vector([v, v, v])


def grey(img, values) -> None:
    """Fill float32 RGB ``img`` (W, H, 3) with the float32 grey ``values`` (W, H) in every channel."""
    _grey(img, np.ascontiguousarray(values))


def _colour_table(colors):
    """(table, each): one row when every primitive has the colour of a broadcast (n, 3) view (``as_rgb`` of one
    colour: its 0-stride rows are not copied out), else the colours themselves, and whether to index per item."""
    colors = np.asarray(colors, np.float64)
    if len(colors) and colors.strides[0] == 0:
        return np.ascontiguousarray(colors[:1]), 0
    return np.ascontiguousarray(colors), 1


def circles(img, centers, radii, colors):
    """Draw circles into ``img`` (float32 (W, H, 3), C-contiguous): ``centers`` (n, 2) and ``radii`` (n,) in
    pixels, ``colors`` (n, 3) float RGB."""
    c = np.asarray(centers, np.float64)
    r = np.asarray(radii, np.float64)
    if _one_tile(len(c)):
        if len(c):
            table, each = _colour_table(colors)
            _circles_in_order(img, np.ascontiguousarray(c), np.ascontiguousarray(r), table, each, _bands(img))
        return
    ok = np.isfinite(c).all(axis=1) & np.isfinite(r) & (r > 0)
    lo, hi = raster.empty_invalid(ok, np.ceil(c - r[:, None]), np.floor(c + r[:, None]))
    start, items, boxes, tiles_y = bin_boxes(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1], img.shape[:2])
    if items.size:
        geo = np.ascontiguousarray(np.column_stack([c, r]))
        _circles(img, start, items, boxes, geo, np.ascontiguousarray(colors, np.float64), tiles_y)


def lines(img, A, B, radius, colors, vertex_colors=None):
    """Draw round-capped segments A -> B (n, 2 pixels) of half-width ``radius`` (n,) into ``img``, coloured
    ``colors`` (n, 3), or ``vertex_colors`` (n, 2, 3) interpolated along each segment."""
    A = np.asarray(A, np.float64)
    B = np.asarray(B, np.float64)
    r = np.asarray(radius, np.float64)
    if vertex_colors is not None:
        vc = np.asarray(vertex_colors, np.float64)
        c0, c1, colouring = np.ascontiguousarray(vc[:, 0]), np.ascontiguousarray(vc[:, 1]), 2
    else:
        c0, colouring = _colour_table(colors)  # 1: one colour each, 0: one for all
        c1 = c0
    if _one_tile(len(A)):
        if len(A):
            _lines_in_order(img, np.ascontiguousarray(np.column_stack([A, B, r])), c0, c1, colouring, _bands(img))
        return
    if colouring == 0:  # the tiles index a colour per segment
        c0 = c1 = np.ascontiguousarray(np.broadcast_to(c0, (len(A), 3)))
    ok = np.isfinite(A).all(axis=1) & np.isfinite(B).all(axis=1) & np.isfinite(r) & (r > 0)
    seg = raster.SegmentPieces(A, B, r, ok, img.shape[:2])
    start, items, boxes, tiles_y = bin_boxes(seg.x0, seg.y0, seg.x1, seg.y1, img.shape[:2])
    if not items.size:
        return
    geo = np.ascontiguousarray(np.column_stack([seg.A, seg.D, seg.L2, r, seg.pieces, seg.ta, seg.span]))
    _lines(img, start, items, boxes, seg.owner.astype(np.int32), seg.k.astype(np.int32), geo, c0, c1,
           int(vertex_colors is not None), tiles_y)


def triangles(img, P, colors, vertex_colors=None):
    """Draw triangles ``P`` (n, 3, 2 pixels) into ``img``: a pixel is covered when its centre is inside
    (edges included, Taichi's rule); colour ``colors`` (n, 3) or ``vertex_colors`` (n, 3, 3) barycentric."""
    P = np.asarray(P, np.float64)
    W, H = img.shape[:2]
    area2 = raster.triangle_area2(P)
    ok = np.isfinite(P).all(axis=(1, 2)) & (area2 != 0)
    lo = np.where(ok[:, None], np.floor(np.where(ok[:, None, None], P, 0.0).min(axis=1)), 0.0)
    hi = np.where(ok[:, None], np.ceil(np.where(ok[:, None, None], P, 0.0).max(axis=1)) - 1, -1.0)
    start, items, boxes, tiles_y = bin_boxes(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1], (W, H))
    if not items.size:
        return
    geo = np.ascontiguousarray(np.column_stack([P.reshape(-1, 6), area2]))
    if vertex_colors is not None:
        col = np.asarray(vertex_colors, np.float64).reshape(-1, 9)
    else:
        col = np.asarray(colors, np.float64).reshape(-1, 3)
    _triangles(img, start, items, boxes, geo, np.ascontiguousarray(col), int(vertex_colors is not None),
               tiles_y)
