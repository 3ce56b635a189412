"""ti.GUI's canvas draws with simgrad kernels once a program exists and with numpy before: the same pictures."""

import numpy as np

import simgrad.gui as tg

W, H = 64, 48


def test_kernel_and_numpy_drawing_agree(monkeypatch):
    # the same calls (overlapping, batched line calls, per-vertex colours) drawn by render2d's kernels and by the
    # numpy rasteriser: the kernels keep numpy's coverage, order and float64 geometry, so float32 rounding apart
    # the pictures are one
    import simgrad as ti
    from simgrad.gui import canvas

    rng = np.random.default_rng(3)

    def draw():
        g = tg.GUI("t", res=(W, H), background_color=0x102030, show_gui=False)
        g.circles(rng.random((40, 2)), radius=rng.uniform(0.5, 6, 40), color=rng.integers(0, 1 << 24, 40))
        for _ in range(12):
            g.line(rng.random(2), rng.random(2), radius=rng.uniform(0.5, 3), color=int(rng.integers(0, 1 << 24)))
        g.triangles(rng.random((15, 2)), rng.random((15, 2)), rng.random((15, 2)), color=0xA0C0E0)
        g.canvas.triangles(rng.random((5, 2)), rng.random((5, 2)), rng.random((5, 2)),
                           vertex_colors=rng.random((5, 3, 3)))
        g.canvas.lines(rng.random((6, 2)), rng.random((6, 2)), radius=2.0, vertex_colors=rng.random((6, 2, 3)))
        return np.array(g.canvas.img)

    ti.init(arch=ti.cpu)
    state = rng.bit_generator.state
    by_kernels = draw()
    rng.bit_generator.state = state
    monkeypatch.setattr(canvas, "_kernels", lambda: None)
    by_numpy = draw()
    assert np.abs(by_kernels - by_numpy).max() < 1e-5
    assert np.abs(by_numpy - by_numpy[0, 0]).max() > 0.1  # something was drawn


def test_tiled_and_one_tile_kernel_drawing_agree(monkeypatch):
    # render2d draws many primitives tile by tile in parallel on a GPU and every call as one tile in call order on
    # the CPU: a pixel sees the same primitives in the same order either way, so the pictures are bit-identical
    import simgrad as ti
    from simgrad.gui import render2d

    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    rng = np.random.default_rng(4)
    n = 600
    c = rng.random((n, 2)) * [W, H]
    a, b = rng.random((n, 2)) * [W, H], rng.random((n, 2)) * [W, H]
    P = rng.random((n, 3, 2)) * [W, H]
    colors = rng.random((n, 3))
    pictures = []
    for one_tile in (False, True):  # tiles (the GPU's way for many primitives), then the CPU's one tile
        monkeypatch.setattr(render2d, "_one_tile", lambda n, one_tile=one_tile: one_tile)
        img = np.zeros((W, H, 3), np.float32)
        render2d.circles(img, c, np.full(n, 2.5), colors)
        render2d.lines(img, a, b, np.full(n, 1.5), colors)
        render2d.triangles(img, P, colors)
        pictures.append(img)
    assert np.array_equal(pictures[0], pictures[1])
    assert np.abs(pictures[0]).max() > 0.1


def test_column_bands_draw_what_one_band_draws(monkeypatch):
    # the CPU's one tile cuts the columns into a band a thread; each pixel lies in one band, which draws every
    # primitive in call order, so the picture is bit-identical to one band's (overlaps, band edges inside
    # primitives, more bands than a 64-pixel image has threads)
    import simgrad as ti
    from simgrad.gui import render2d

    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    rng = np.random.default_rng(8)
    n = 500
    c = rng.random((n, 2)) * [W + 8, H + 8] - 4
    a, b = rng.random((n, 2)) * [W, H], rng.random((n, 2)) * [W, H]
    colors = rng.random((n, 3))
    vertex_colors = rng.random((40, 2, 3))
    pictures = []
    for bands in (1, 2, 5):
        monkeypatch.setattr(render2d, "_bands", lambda img, bands=bands: bands)
        img = np.zeros((W, H, 3), np.float32)
        render2d.circles(img, c, np.linspace(0.3, 6, n), colors)
        render2d.lines(img, a, b, np.linspace(0.5, 3, n), colors)
        render2d.lines(img, a[:40], b[:40], np.full(40, 2.0), colors[:40], vertex_colors=vertex_colors)
        pictures.append(img)
    assert np.array_equal(pictures[0], pictures[1]) and np.array_equal(pictures[0], pictures[2])
    assert np.abs(pictures[0]).max() > 0.1


def test_one_tile_segments_without_pieces_match_tiled_pieces(monkeypatch):
    # on the CPU a segment is drawn column by column (the rows near it, each pixel once) instead of as padded
    # pieces: the awkward segments (clipped far off the canvas, axis-aligned, zero-length, not finite, wide, per-vertex
    # colours through the clipping) give bit-identical pictures either way
    import simgrad as ti
    from simgrad.gui import render2d

    ti.init(arch=ti.cpu)
    a = np.array([[-1e6, 10.0], [5.0, -40.0], [10.0, 10.0], [3.0, 3.0], [np.nan, 1.0], [-5.0, -5.0], [20.5, 0.0],
                  [0.0, 47.5], [63.9, 1.0], [30.0, 20.0], [1e300, 1.0], [-3.0, 25.0]])
    b = np.array([[1e6, 30.0], [5.0, 90.0], [10.0, 10.0], [60.0, 45.0], [4.0, 4.0], [70.0, 53.0], [20.5, 48.0],
                  [64.0, 47.5], [-1.0, 46.0], [31.0, 20.5], [2.0, 3.0], [2.0, 25.0]])
    r = np.array([1.5, 2.0, 3.0, 0.7, 2.0, 9.0, 0.5, 1.0, 4.0, 2.5, 1.0, 1.2])
    rng = np.random.default_rng(5)
    vc = rng.random((len(a), 2, 3))
    pictures = []
    for one_tile in (False, True):
        monkeypatch.setattr(render2d, "_one_tile", lambda n, one_tile=one_tile: one_tile)
        img = np.full((W, H, 3), 0.25, np.float32)
        render2d.lines(img, a, b, r, vc[:, 0])
        render2d.lines(img, a[::-1], b[::-1], r[::-1], None, vertex_colors=vc)
        render2d.lines(img, a, b, r * 0.5, np.broadcast_to([0.9, 0.1, 0.5], (len(a), 3)))  # one colour for all
        render2d.circles(img, a, r, np.broadcast_to([0.2, 0.8, 0.4], (len(a), 3)))
        pictures.append(img)
    assert np.array_equal(pictures[0], pictures[1])
    assert (pictures[0] != 0.25).sum() > 1000


def test_one_tile_segments_visit_every_covered_pixel(monkeypatch):
    # the column-by-column path visits only pixels whose centre may lie within the half-width of the segment: many
    # short random segments, ends on the pixel grid, on pixel centres and between them, any radius, must still give
    # the tiled path's picture bit for bit
    import simgrad as ti
    from simgrad.gui import render2d

    ti.init(arch=ti.cpu)
    rng = np.random.default_rng(11)
    n = 3000
    a = rng.integers(-4, W + 4, (n, 2)) + rng.choice([0.0, 0.5, 0.25, 1e-9, -1e-9], (n, 2))
    b = a + rng.integers(-9, 10, (n, 2)) + rng.choice([0.0, 0.5, 0.75], (n, 2))
    r = rng.choice([0.25, 0.5, 0.5 + 1e-12, 0.7071067811865476, 1.0, 1.5, 3.0], n)
    colors = rng.random((n, 3))
    pictures = []
    for one_tile in (False, True):
        monkeypatch.setattr(render2d, "_one_tile", lambda n, one_tile=one_tile: one_tile)
        img = np.full((W, H, 3), 0.25, np.float32)
        render2d.lines(img, a, b, r, colors)
        pictures.append(img)
    assert np.array_equal(pictures[0], pictures[1])
    assert (pictures[0] != 0.25).any(axis=-1).mean() > 0.3


def test_composite_matches_sequential_blending_on_both_paths():
    # raster.composite drops samples hidden by a later opaque one through an image-sized array when the samples
    # are many, and within each pixel's sorted run when they are few (texts): both equal drawing the samples one
    # after another with lerp(alpha, dest, rgb)
    from simgrad.gui import raster

    rng = np.random.default_rng(11)
    for w, h in ((6, 5), (64, 48)):  # 30 pixels: many samples each; 3072: the few-samples path
        n = 120
        i, j = rng.integers(0, 6, n), rng.integers(0, 5, n)
        alpha = np.where(rng.random(n) < 0.4, rng.choice([1.0, 1.5], n), rng.uniform(-0.2, 0.99, n))
        rgb = rng.random((n, 3))
        img = rng.random((w, h, 3)).astype(np.float32)
        want = img.astype(np.float64)
        for k in range(n):
            a = min(alpha[k], 1.0)
            if a > 0:
                want[i[k], j[k]] = want[i[k], j[k]] * (1 - a) + rgb[k] * a
        raster.composite(img, i, j, alpha, rgb)
        assert np.abs(img - want).max() < 1e-5, (w, h)


def test_few_row_boxes_clip_as_floor_and_ceil():
    # _Rows.bounds clips a few rows' boxes without isfinite/floor per side: the same integers as clipping
    # floor(v) - 1 and ceil(v) + 2 to [0, n], infinities at the ends
    import math

    from simgrad.gui.canvas import _box_hi, _box_lo

    def lo(v, n):
        return min(max(math.floor(v) - 1, 0), n) if math.isfinite(v) else (0 if v < 0 else n)

    def hi(v, n):
        return min(max(math.ceil(v) + 2, 0), n) if math.isfinite(v) else (0 if v < 0 else n)

    rng = np.random.default_rng(5)
    edges = [math.inf, -math.inf, 0.0, -0.0, 1.0, 0.999, 1.0001, 2.0, -2.0, -1.99, -2.01, 1e300, -1e300]
    values = edges + [n + d for n in (1, 64) for d in (-3, -2.5, -2, -1.5, -1, 0, 0.5, 1, 1.5, 2)]
    values += list(rng.uniform(-10, 80, 5000)) + list(rng.integers(-5, 70, 500).astype(float))
    for n in (1, 64):
        for v in values:
            assert (_box_lo(v, n), _box_hi(v, n)) == (lo(v, n), hi(v, n)), (v, n)
