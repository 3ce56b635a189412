"""Pixel facts about ti.GUI primitives, checked against independent numpy geometry."""

import numpy as np
import pytest

import simgrad.gui as tg
from simgrad.gui import raster

W, H = 64, 48


def rgb(h):
    return np.array([(h >> 16) & 255, (h >> 8) & 255, h & 255]) / 255.0


def pixel_grid(res=(W, H)):
    return np.meshgrid(np.arange(res[0]), np.arange(res[1]), indexing="ij")


def seg_dist(px, py, a, b):
    """Distance from points to segment ab, all in pixel units."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    t = np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / (d @ d), 0, 1)
    return np.hypot(px - a[0] - t * d[0], py - a[1] - t * d[1])


pytestmark = pytest.mark.usefixtures("raster_path")  # every fact for both drawing paths (conftest.py)


@pytest.fixture
def gui():
    return tg.GUI("test", res=(W, H), background_color=0x000000, show_gui=False)


def test_circle_matches_coverage_formula(gui):
    r = 5.0
    gui.circle((0.5, 0.5), color=0xFF8000, radius=r)
    img = gui.get_image()[..., :3]
    assert img.shape == (W, H, 3)
    cx, cy = 0.5 * W, 0.5 * H
    np.testing.assert_allclose(img[int(cx), int(cy)], rgb(0xFF8000), atol=1e-6)
    assert np.all(img[int(cx + 2 * r), int(cy)] == 0)
    assert np.all(img[int(cx), int(cy - 2 * r)] == 0)
    i, j = pixel_grid()
    alpha = np.clip(r - np.hypot(i - cx, j - cy), 0, 1)
    np.testing.assert_allclose(img, alpha[..., None] * rgb(0xFF8000), atol=1e-6)


def test_circle_edge_is_antialiased(gui):
    gui.circle((0.37, 0.41), color=0xFFFFFF, radius=7.3)
    red = gui.get_image()[..., 0]
    partial = (red > 0.01) & (red < 0.99)
    assert partial.sum() >= 10
    i, j = pixel_grid()
    dist = np.hypot(i - 0.37 * W, j - 0.41 * H)
    assert np.all((dist[partial] > 7.3 - 1) & (dist[partial] < 7.3))


def test_circle_top_left_lands_top_left_in_png(tmp_path, read_rows):
    gui = tg.GUI(res=(100, 80), show_gui=False)
    gui.circle((0.1, 0.9), color=0xFF0000, radius=4)
    path = tmp_path / "frame.png"
    gui.show(str(path))
    rows = read_rows(path)
    assert rows.shape == (80, 100, 3)
    red_r, red_c = np.nonzero(rows[..., 0] > 0.5)
    assert red_r.size > 0
    assert red_r.max() < 16 and red_c.max() < 20  # top-left fifth of the image
    # GUI pixel (10, 72) is PNG row 80 - 1 - 72 = 7, column 10.
    np.testing.assert_allclose(rows[7, 10], [1, 0, 0])
    assert rows[80 - 8, 10].sum() == 0  # the mirrored (bottom-left) spot stays empty


def test_show_clears_to_background(tmp_path):
    gui = tg.GUI(res=(16, 16), background_color=0x204060, show_gui=False)
    gui.circle((0.5, 0.5), radius=4)
    assert gui.frame == 0
    gui.show()
    assert gui.frame == 1
    np.testing.assert_allclose(
        gui.get_image()[..., :3], np.broadcast_to(rgb(0x204060), (16, 16, 3)), atol=1e-6
    )


def test_line_colours_midpoint_and_follows_distance(gui):
    a, b, r = (0.2, 0.3), (0.8, 0.7), 2.0
    gui.line(a, b, radius=r, color=0x00FF00)
    g = gui.get_image()[..., 1]
    mid = ((a[0] + b[0]) / 2 * W, (a[1] + b[1]) / 2 * H)
    assert g[int(mid[0]), int(mid[1])] == pytest.approx(1.0)
    i, j = pixel_grid()
    dist = seg_dist(i + 0.5, j + 0.5, np.multiply(a, (W, H)), np.multiply(b, (W, H)))
    assert np.all(g[dist < r - 1] == pytest.approx(1.0))
    assert np.all(g[dist >= r] == 0)
    assert g[0, H - 1] == 0


def test_lines_batch_with_colour_and_radius_arrays(gui):
    y0, y1 = 10, 38  # lines through pixel centres (y + 0.5) / H
    begin = np.array([[0.1, (y0 + 0.5) / H], [0.1, (y1 + 0.5) / H]])
    end = np.array([[0.9, (y0 + 0.5) / H], [0.9, (y1 + 0.5) / H]])
    gui.lines(begin, end, radius=np.array([1.0, 3.0]), color=np.array([0xFF0000, 0x0000FF]))
    img = gui.get_image()[..., :3]
    np.testing.assert_allclose(img[W // 2, y0], [1, 0, 0])
    np.testing.assert_allclose(img[W // 2, y1], [0, 0, 1])
    # Thicker blue line: covers 2 pixels away from its axis, the red one does not.
    assert img[W // 2, y1 + 2, 2] == pytest.approx(1.0)
    assert img[W // 2, y0 + 2, 0] == 0


def test_triangles_fill_centroid_and_match_inside_test(gui):
    a = np.array([[0.1, 0.1], [0.6, 0.9]])
    b = np.array([[0.5, 0.2], [0.9, 0.5]])
    c = np.array([[0.2, 0.6], [0.95, 0.95]])
    colors = np.array([0xFFFF00, 0x00FFFF])
    gui.triangles(a, b, c, color=colors)
    img = gui.get_image()[..., :3]
    i, j = pixel_grid()
    px, py = i + 0.5, j + 0.5
    for k in range(2):
        centroid = (a[k] + b[k] + c[k]) / 3 * (W, H)
        np.testing.assert_allclose(img[int(centroid[0]), int(centroid[1])], rgb(colors[k]))
        # Independent barycentric inside test, away from edges.
        A, B, C = a[k] * (W, H), b[k] * (W, H), c[k] * (W, H)
        den = (B[1] - C[1]) * (A[0] - C[0]) + (C[0] - B[0]) * (A[1] - C[1])
        l1 = ((B[1] - C[1]) * (px - C[0]) + (C[0] - B[0]) * (py - C[1])) / den
        l2 = ((C[1] - A[1]) * (px - C[0]) + (A[0] - C[0]) * (py - C[1])) / den
        l3 = 1 - l1 - l2
        inside = (l1 > 0.02) & (l2 > 0.02) & (l3 > 0.02)
        assert inside.sum() > 20
        np.testing.assert_allclose(img[inside], np.broadcast_to(rgb(colors[k]), img[inside].shape))
    assert img[W - 1, 0].sum() == 0


@pytest.mark.parametrize("snap", [False, True])
def test_triangle_spans_match_taichi_edge_rule(snap):
    rng = np.random.default_rng(7 + snap)
    P = rng.uniform(-0.2, 1.2, (40, 3, 2))
    if snap:  # vertices on pixel centres/corners make pixel centres fall exactly on edges
        P = np.round(P * (2 * W, 2 * H)) / (2 * W, 2 * H)
    cv = tg.ImageCanvas((W, H))
    colors = rng.integers(1, 0xFFFFFF, len(P))
    cv.triangles(P[:, 0], P[:, 1], P[:, 2], color=colors)
    # Brute force, per triangle over every pixel, with Taichi's cross(p - u, v - u) <= 0 rule.
    ref = np.zeros((W, H, 3))
    i, j = pixel_grid()
    px, py = i + 0.5, j + 0.5
    for k, tri in enumerate(P * (W, H)):
        (abx, aby), (acx, acy) = tri[1] - tri[0], tri[2] - tri[0]
        area2 = abx * acy - aby * acx
        if area2 == 0:
            continue
        e = [
            (px - u[0]) * (v[1] - u[1]) - (py - u[1]) * (v[0] - u[0]) <= 0
            for u, v in zip(tri, np.roll(tri, -1, 0))
        ]
        ref[(e[0] == e[1]) & (e[0] == e[2])] = rgb(colors[k])
    np.testing.assert_allclose(cv.img, ref, atol=1e-6)


def test_triangle_antialias_option_gives_partial_edges():
    cv = tg.ImageCanvas((W, H))
    cv.triangles([[0.1, 0.1]], [[0.83, 0.27]], [[0.4, 0.9]], color=0xFFFFFF, antialias=True)
    red = cv.img[..., 0]
    assert ((red > 0.05) & (red < 0.95)).sum() > 10
    assert red[int(0.44 * W), int(0.42 * H)] == pytest.approx(1.0)


def test_per_circle_colours_and_radii(gui):
    pos = np.array([[0.2, 0.5], [0.5, 0.5], [0.8, 0.5]])
    colors = np.array([0xFF0000, 0x00FF00, 0x0000FF])
    gui.circles(pos, radius=np.array([2.0, 4.0, 6.0]), color=colors)
    img = gui.get_image()[..., :3]
    for k in range(3):
        x, y = pos[k] * (W, H)
        np.testing.assert_allclose(img[int(round(x)), int(round(y))], rgb(colors[k]))
    # radius 6 reaches 5 pixels right of the blue centre, radius 2 does not for red.
    assert img[int(0.8 * W) + 5, H // 2, 2] > 0
    assert img[int(0.2 * W) + 5, H // 2].sum() == 0


def test_palette_and_palette_indices(gui):
    palette = [0x123456, 0xABCDEF]
    pos = np.array([[0.25, 0.5], [0.5, 0.5], [0.75, 0.5]])
    gui.circles(pos, radius=3, palette=palette, palette_indices=[1, 0, 1])
    img = gui.get_image()[..., :3]
    expected = [palette[1], palette[0], palette[1]]
    for k in range(3):
        x, y = pos[k] * (W, H)
        np.testing.assert_allclose(img[int(x), int(y)], rgb(expected[k]), atol=1e-6)
    with pytest.raises(ValueError):
        gui.circles(pos, palette=palette)
    with pytest.raises(ValueError):
        gui.circles(pos, palette=palette, palette_indices=[0, 1, 2])


def test_batched_overlaps_blend_like_sequential_draws():
    rng = np.random.default_rng(0)
    n = 60
    pos = rng.random((n, 2))
    radius = rng.uniform(1, 9, n)
    colors = rng.integers(0, 0xFFFFFF, n)
    begin, end = rng.random((n, 2)), rng.random((n, 2))
    batched, sequential = tg.ImageCanvas((W, H), 0x101010), tg.ImageCanvas((W, H), 0x101010)
    batched.circles(pos, radius, colors)
    batched.lines(begin, end, radius / 3, colors)
    for k in range(n):
        sequential.circles(pos[k : k + 1], radius[k], int(colors[k]))
    for k in range(n):
        sequential.lines(begin[k : k + 1], end[k : k + 1], radius[k] / 3, int(colors[k]))
    np.testing.assert_allclose(batched.img, sequential.img, atol=1e-5)


def test_chunked_rasterisation_is_identical(monkeypatch):
    rng = np.random.default_rng(1)
    pos, begin, end = rng.random((40, 2)), rng.random((30, 2)) * 1.4 - 0.2, rng.random((30, 2))
    ref = tg.ImageCanvas((W, H))
    ref.circles(pos, 4.0, 0xFF00FF)
    ref.lines(begin, end, 1.5, 0x00FFFF)
    monkeypatch.setattr(raster, "CHUNK", 50)
    monkeypatch.setattr(raster, "PIECE", 3.0)
    small = tg.ImageCanvas((W, H))
    small.circles(pos, 4.0, 0xFF00FF)
    small.lines(begin, end, 1.5, 0x00FFFF)
    np.testing.assert_allclose(small.img, ref.img, atol=1e-6)


def test_degenerate_and_offscreen_input_is_safe(gui):
    y = (H // 2 + 0.5) / H
    gui.lines(np.array([[-1e12, y]]), np.array([[1e12, y]]), radius=1, color=0xFFFFFF)
    row = gui.get_image()[:, :, 0]
    assert np.all(row[:, H // 2] == 1.0)
    assert np.all(row[:, H // 2 + 1] == 0.0)
    gui.clear()
    gui.circles(np.array([[np.nan, 0.5], [0.5, 0.5]]), radius=2)
    gui.line((0.5, 0.5), (0.5, 0.5), radius=2)
    gui.triangle((0.1, 0.1), (0.1, 0.1), (0.1, 0.1))
    gui.circles(np.zeros((0, 2)))
    assert gui.get_image()[W // 2, H // 2, 0] == 1.0


def test_rect_draws_outline_only(gui):
    gui.rect((0.2, 0.8), (0.8, 0.2), radius=1, color=0xFFFFFF)
    img = gui.get_image()[..., 0]
    assert img[W // 2, int(0.8 * H)] > 0.5  # top side
    assert img[int(0.2 * W), H // 2] > 0.5  # left side
    assert img[W // 2, H // 2] == 0  # inside stays empty


def test_arrow_has_shaft_and_tip(gui):
    y = (H // 2 + 0.5) / H
    gui.arrow((0.2, y), (0.6, 0.0), radius=1, color=0xFFFFFF)
    img = gui.get_image()[..., 0]
    assert img[W // 2, H // 2] == 1.0
    tip = np.array([0.8 * W, y * H])
    # Tip strokes go back and up/down by 0.2 * |direction| at 45 degrees.
    up = tip + np.array([-np.sqrt(0.5), np.sqrt(0.5)]) * 0.12 * np.array([W, H]) * 0.5
    assert img[int(up[0]), int(up[1])] > 0
    gui.clear()
    gui.arrows(np.array([[0.1, 0.1], [0.1, 0.9]]), np.array([[0.3, 0.0], [0.3, 0.0]]), color=0x00FF00)
    assert gui.get_image()[int(0.25 * W), int(0.1 * H), 1] > 0.5


def test_text_renders_below_and_right_of_pos(gui):
    gui.text("Hi!", (0.25, 0.75), font_size=12, color=0xFF0000)
    red = gui.get_image()[..., 0]
    xs, ys = np.nonzero(red > 0.2)
    assert xs.size > 5
    assert xs.min() >= int(0.25 * W) - 1 and ys.max() < int(0.75 * H)
    assert ys.min() > int(0.75 * H) - 20


def test_deferred_drawing_snapshots_its_inputs_and_show_clears(gui, tmp_path):
    """Primitives are rasterised when the pixels are looked at: what the user changes in their arrays
    afterwards must not show, a bad argument must still fail at the call, and show() must clear."""
    pos = np.array([[0.25, 0.5]])
    colors = np.array([0x00FF00])
    gui.circles(pos, radius=4, color=colors)
    pos[0, 0] = 0.75
    colors[0] = 0xFF0000
    img = gui.get_image()[..., :3]
    np.testing.assert_allclose(img[int(0.25 * W), H // 2], rgb(0x00FF00), atol=1e-6)
    np.testing.assert_allclose(img[int(0.75 * W), H // 2], 0.0, atol=1e-6)
    with pytest.raises(ValueError):
        gui.circles(np.zeros((3, 3)))
    gui.triangle((0.1, 0.1), (0.9, 0.1), (0.5, 0.9), color=0xFFFFFF)
    gui.show(str(tmp_path / "frame.png"))  # saved with the triangle, then cleared
    assert (tmp_path / "frame.png").exists()
    np.testing.assert_allclose(gui.get_image()[..., :3], 0.0, atol=1e-6)
    gui.circle((0.5, 0.5), radius=3, color=0xFFFFFF)
    gui.clear(0x0000FF)  # a clear drops what was drawn before it
    np.testing.assert_allclose(gui.get_image()[..., :3], np.broadcast_to(rgb(0x0000FF), (W, H, 3)), atol=1e-6)


def test_triangles_and_lines_are_prepared_only_when_the_pixels_are_looked_at(gui, monkeypatch):
    """A headless frame that nobody looks at costs only the argument checks: the spans of triangles and the
    pieces of segments are computed when the pixels are read (mciso_advanced draws 2500 triangles and 7500
    lines a frame; preparing them took longer than its kernels). The picture is the one drawn eagerly."""
    calls = []
    spans, pieces = raster.triangle_spans, raster.SegmentPieces
    monkeypatch.setattr(raster, "triangle_spans", lambda *a: calls.append("spans") or spans(*a))
    monkeypatch.setattr(raster, "SegmentPieces", lambda *a: calls.append("pieces") or pieces(*a))
    a = np.array([[0.1, 0.1], [0.5, 0.5]])
    b = np.array([[0.9, 0.2], [0.7, 0.9]])
    c = np.array([[0.4, 0.8], [0.2, 0.6]])
    gui.triangles(a, b, c, color=0x336699)
    gui.lines(a, b, radius=2, color=0xFF0000)
    a[:] = 0.0  # the call's inputs were copied
    assert calls == []
    img = gui.get_image()[..., :3].copy()
    # the numpy rasteriser needs both; the CPU kernels need neither (triangles are tested per pixel, a one-tile
    # segment visits its columns' rows without pieces)
    assert calls in (["spans", "pieces"], [])
    gui.clear(0)
    gui.triangles(np.array([[0.1, 0.1], [0.5, 0.5]]), b, c, color=0x336699)
    gui.lines(np.array([[0.1, 0.1], [0.5, 0.5]]), b, radius=2, color=0xFF0000)
    np.testing.assert_array_equal(gui.get_image()[..., :3], img)
    assert img.max() > 0
