"""ti.ui canvas 2-D primitives, drawn by simgrad kernels (gui/render2d.py): pixels checked against coverage
computed here from the geometry (circle area, triangle pixel centres, line profiles, blending order, vertex
colours), and against the numpy rasteriser (ImageCanvas, which ti.GUI uses) on random scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

import simgrad as ti
from simgrad.gui import ImageCanvas

W, H = 150, 110  # not multiples of the 16-pixel tiles


@pytest.fixture(autouse=True)
def _program():
    ti.init(arch=ti.cpu)


def window(res=(W, H), bg=(0.0, 0.0, 0.0)):
    win = ti.ui.Window("t", res, show_window=False)
    win.get_canvas().set_background_color(bg)
    return win, win.get_canvas()


def pixels(win):
    return win.get_image_buffer_as_numpy()[..., :3].astype(np.float64)


def grid(res=(W, H)):
    return np.meshgrid(np.arange(res[0], dtype=np.float64), np.arange(res[1], dtype=np.float64), indexing="ij")


def seg_dist(px, py, a, b):
    d = b - a
    t = np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / (d @ d), 0, 1)
    return np.hypot(px - a[0] - t * d[0], py - a[1] - t * d[1])


def test_circle_coverage_is_the_antialiased_disc():
    win, canvas = window()
    c = np.array([0.41, 0.53])
    r = 0.2  # of the window height: 22 pixels
    canvas.circles(np.array([c], np.float32), radius=r, color=(1.0, 1.0, 1.0))
    img = pixels(win)[..., 0]
    R, cx, cy = r * H, c[0] * W, c[1] * H
    # Taichi's coverage: clamp(R - distance) from integer pixel coordinates
    i, j = grid()
    want = np.clip(R - np.hypot(i - float(np.float32(c[0])) * W, j - float(np.float32(c[1])) * H), 0, 1)
    np.testing.assert_allclose(img, want, atol=1e-5)
    # and as areas: the integral of clamp(R - d, 0, 1) over the plane is pi (R^2 - R + 1/3)
    assert abs(img.sum() - math.pi * (R * R - R + 1 / 3)) < 0.01 * math.pi * R * R
    edge = (img > 0) & (img < 1)
    assert abs(edge.sum() - 2 * math.pi * (R - 0.5)) < 0.1 * 2 * math.pi * R  # a one-pixel AA ring
    assert abs((img * i).sum() / img.sum() - cx) < 0.05 and abs((img * j).sum() / img.sum() - cy) < 0.05


def test_triangle_covers_the_pixel_centres_inside_it():
    win, canvas = window()
    v = np.array([[0.1, 0.15], [0.83, 0.31], [0.35, 0.92]], np.float32)
    canvas.triangles(v, color=(0.0, 1.0, 0.0))
    img = pixels(win)[..., 1]
    P = v.astype(np.float64) * (W, H)
    i, j = grid()
    px, py = i + 0.5, j + 0.5
    inside = np.ones_like(px, bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):  # counter-clockwise: every centre left of every edge
        inside &= (P[b, 0] - P[a, 0]) * (py - P[a, 1]) - (P[b, 1] - P[a, 1]) * (px - P[a, 0]) >= 0
    np.testing.assert_array_equal(img == 1.0, inside)
    assert np.all((img == 0.0) | (img == 1.0))  # no anti-aliasing on triangles, as in Taichi
    (ux, uy), (vx, vy) = P[1] - P[0], P[2] - P[0]
    area = 0.5 * abs(ux * vy - uy * vx)
    perimeter = sum(np.hypot(*(P[(k + 1) % 3] - P[k])) for k in range(3))
    assert abs(inside.sum() - area) < perimeter / 2


@pytest.mark.parametrize("ccw", [True, False])
def test_pixel_centres_on_edges_follow_taichis_tie_rule(ccw):
    # Taichi's test is "all three edge functions <= 0, or all > 0": centres on an edge are covered by a
    # counter-clockwise triangle and not by a clockwise one
    n = 128  # k / 128 and (k + 0.5) / 128 are exact in float32
    win, canvas = window((n, n))
    v = np.array([[20.5, 10.5], [100.5, 10.5], [20.5, 90.5]], np.float32) / n
    canvas.triangles(v if ccw else v[::-1].copy(), color=(1.0, 1.0, 1.0))
    img = pixels(win)[..., 0]
    i, j = grid((n, n))
    d = (i - 20) + (j - 10)  # centres at i + 0.5, j + 0.5: left edge i = 20, bottom j = 10, hypotenuse d = 80
    want = (i >= 20) & (j >= 10) & (d <= 80) if ccw else (i > 20) & (j > 10) & (d < 80)
    np.testing.assert_array_equal(img == 1.0, want)
    ref = ImageCanvas((n, n))  # the numpy rasteriser (ti.GUI) agrees
    P = (v if ccw else v[::-1]).astype(np.float64)
    ref.triangles(P[0:1], P[1:2], P[2:3], (1.0, 1.0, 1.0))
    np.testing.assert_array_equal(ref.img[..., 0] == 1.0, want)


def test_two_triangles_of_a_square_cover_it_once():
    win, canvas = window(bg=(0.0, 0.0, 0.0))
    x0, y0, x1, y1 = 20.25 / W, 10.75 / H, 101.6 / W, 77.3 / H
    v = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y0], [x1, y1], [x0, y1]], np.float32)
    canvas.triangles(v, color=(1.0, 1.0, 1.0))
    img = pixels(win)[..., 0]
    # centres 20.5 .. 101.5 by 11.5 .. 76.5: 82 x 66 pixels, no seam along the diagonal
    assert img.sum() == 82 * 66 and img[20:102, 11:77].min() == 1.0


def test_line_profile_and_thickness():
    win, canvas = window()
    width = 0.08  # of the height: 8.8 pixels, half-width 4.4
    a, b = np.array([0.1, 0.3]), np.array([0.9, 0.62])
    canvas.lines(np.array([a, b], np.float32), width=width, color=(1.0, 0.0, 0.0))
    img = pixels(win)[..., 0]
    r = 0.5 * width * H
    i, j = grid()
    A = np.float32(a).astype(np.float64) * (W, H)
    B = np.float32(b).astype(np.float64) * (W, H)
    want = np.clip(r - seg_dist(i + 0.5, j + 0.5, A, B), 0, 1)  # from pixel centres, round caps
    np.testing.assert_allclose(img, want, atol=1e-5)
    # across a horizontal line each column's coverage sums to the integral 2 r - 1
    win, canvas = window()
    canvas.lines(np.array([[0.2, 0.5], [0.8, 0.5]], np.float32), width=width, color=(1.0, 1.0, 1.0))
    cols = pixels(win)[40:100, :, 0].sum(axis=1)
    np.testing.assert_allclose(cols, 2 * r - 1, atol=0.02)


def test_zero_length_line_is_a_dot_and_bad_input_draws_nothing():
    win, canvas = window()
    canvas.lines(np.array([[0.5, 0.5], [0.5, 0.5]], np.float32), width=0.1, color=(1.0, 1.0, 1.0))
    canvas.lines(np.array([[np.nan, 0.5], [0.2, 0.2]], np.float32), width=0.1, color=(1.0, 1.0, 1.0))
    canvas.circles(np.array([[np.inf, 0.5], [0.1, np.nan]], np.float32), radius=0.1, color=(1.0, 1.0, 1.0))
    canvas.triangles(np.array([[0.1, 0.1], [0.2, 0.2], [0.3, 0.3]], np.float32), color=(1.0, 1.0, 1.0))
    img = pixels(win)[..., 0]
    r = 0.05 * H
    i, j = grid()
    want = np.clip(r - np.hypot(i + 0.5 - 0.5 * W, j + 0.5 - 0.5 * H), 0, 1)
    np.testing.assert_allclose(img, want, atol=1e-5)


def test_later_primitives_are_drawn_over_earlier_ones():
    win, canvas = window()
    centers = np.array([[0.4, 0.5], [0.6, 0.5], [0.5, 0.5]], np.float32)
    colors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], np.float32)
    canvas.circles(centers, radius=0.25, per_vertex_color=colors)
    img = pixels(win)
    # sequential lerp(alpha, dest, colour) in index order, computed here
    i, j = grid()
    want = np.zeros((W, H, 3))
    R = np.float32(0.25) * np.float64(H)
    for c, col in zip(centers.astype(np.float64) * (W, H), colors):
        a = np.clip(R - np.hypot(i - c[0], j - c[1]), 0, 1)[..., None]
        want = want * (1 - a) + col * a
    np.testing.assert_allclose(img, want, atol=1e-5)
    assert img[W // 2, H // 2].tolist() == [0.0, 0.0, 1.0]  # the last one covers the middle
    # across calls too: a circle drawn before a triangle is hidden by it, after it it shows
    for circle_first in (True, False):
        win, canvas = window()
        tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]], np.float32)
        dot = np.array([[0.5, 0.4]], np.float32)
        if circle_first:
            canvas.circles(dot, radius=0.1, color=(1.0, 0.0, 0.0))
        canvas.triangles(tri, color=(0.0, 1.0, 0.0))
        if not circle_first:
            canvas.circles(dot, radius=0.1, color=(1.0, 0.0, 0.0))
        assert pixels(win)[W // 2, int(0.4 * H)].tolist() == ([0.0, 1.0, 0.0] if circle_first else [1.0, 0.0, 0.0])


def test_per_vertex_colors_interpolate():
    win, canvas = window()
    v = np.array([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]], np.float32)
    canvas.triangles(v, per_vertex_color=np.eye(3, dtype=np.float32))
    img = pixels(win)
    P = v.astype(np.float64) * (W, H)
    g = P.mean(axis=0)
    np.testing.assert_allclose(img[int(g[0]), int(g[1])], [1 / 3, 1 / 3, 1 / 3], atol=0.02)
    near_a = P[0] + 0.05 * (g - P[0])
    assert img[int(near_a[0]), int(near_a[1])][0] > 0.9
    np.testing.assert_allclose(img.sum(axis=-1)[img.sum(axis=-1) > 0], 1.0, atol=1e-5)  # weights sum to 1

    win, canvas = window()
    ends = np.array([[0.1, 0.5], [0.9, 0.5]], np.float32)
    canvas.lines(ends, width=0.1, per_vertex_color=np.array([[1, 0, 0], [0, 0, 1]], np.float32))
    img = pixels(win)
    row = int(0.5 * H)
    for x in (0.1, 0.3, 0.5, 0.7, 0.9):
        t = np.clip((int(x * W) + 0.5 - 0.1 * W) / (0.8 * W), 0, 1)
        np.testing.assert_allclose(img[int(x * W), row], [1 - t, 0, t], atol=1e-5)


def test_indices_select_vertices():
    win, canvas = window()
    v = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]], np.float32)
    canvas.triangles(v, indices=np.array([0, 1, 2], np.int32), color=(1.0, 1.0, 1.0))
    img = pixels(win)[..., 0]
    assert img[int(0.8 * W), int(0.2 * H)] == 1.0 and img[int(0.2 * W), int(0.8 * H)] == 0.0
    win, canvas = window()
    canvas.lines(v, width=0.02, indices=np.array([[0, 2]], np.int32), color=(1.0, 1.0, 1.0))
    img = pixels(win)[..., 0]
    assert img[W // 2, H // 2] > 0.9 and img[int(0.5 * W), int(0.1 * H)] == 0.0


def numpy_canvas(res, draws):
    """The same draws on the numpy rasteriser, with ti.ui's units (sizes are fractions of the height)."""
    ref = ImageCanvas(res, background=(0.2, 0.3, 0.4))
    Wr, Hr = res
    for kind, kw in draws:
        if kind == "circles":
            c = kw["centers"].astype(np.float64)
            color = kw.get("per_vertex_color", np.array(kw.get("color", (0.5, 0.5, 0.5))))
            r = kw["per_vertex_radius"].astype(np.float64) * Hr if "per_vertex_radius" in kw else kw["radius"] * Hr
            ref.circles(c, r, np.asarray(color, np.float64))
        elif kind == "lines":
            v = kw["vertices"].astype(np.float64)
            idx = kw["indices"].reshape(-1, 2) if "indices" in kw else np.arange(len(v) - len(v) % 2).reshape(-1, 2)
            vc = kw["per_vertex_color"].astype(np.float64)[idx] if "per_vertex_color" in kw else None
            ref.lines(v[idx[:, 0]], v[idx[:, 1]], 0.5 * kw["width"] * Hr, np.array(kw.get("color", (0.5, 0.5, 0.5))),
                      vertex_colors=vc)
        else:
            v = kw["vertices"].astype(np.float64)
            idx = kw["indices"].reshape(-1, 3) if "indices" in kw else np.arange(len(v) - len(v) % 3).reshape(-1, 3)
            vc = kw["per_vertex_color"].astype(np.float64)[idx] if "per_vertex_color" in kw else None
            ref.triangles(v[idx[:, 0]], v[idx[:, 1]], v[idx[:, 2]], np.array(kw.get("color", (0.5, 0.5, 0.5))),
                          vertex_colors=vc)
    return ref.img.astype(np.float64)


def random_draws(rng, n):
    f32 = np.float32
    pts = (rng.random((3 * n, 2)) * 1.6 - 0.3).astype(f32)  # some off the canvas
    pts[rng.random(3 * n) < 0.02] = np.nan
    cols = rng.random((3 * n, 3)).astype(f32)
    draws = [
        ("circles", {"centers": pts[:n], "radius": 0.03, "per_vertex_color": cols[:n]}),
        ("lines", {"vertices": pts[: 2 * n], "width": 0.02, "per_vertex_color": cols[: 2 * n]}),
        ("triangles", {"vertices": pts, "per_vertex_color": cols}),
        ("lines", {"vertices": pts, "width": 0.05, "color": (0.9, 0.1, 0.5),
                   "indices": rng.integers(0, 3 * n, (n, 2)).astype(np.int32)}),
        ("triangles", {"vertices": (pts * 0.1 + 0.4).astype(f32), "color": (0.1, 0.8, 0.2),
                       "indices": rng.integers(0, 3 * n, (n, 3)).astype(np.int32)}),
        ("circles", {"centers": pts[n: 2 * n], "radius": 0.0,
                     "per_vertex_radius": (rng.random(n) * 0.2).astype(f32), "color": (1.0, 1.0, 0.0)}),
        ("lines", {"vertices": np.array([[0.3, 0.3], [0.3, 0.3], [-5.0, 0.5], [7.0, 0.52]], f32), "width": 0.03,
                   "color": (0.0, 1.0, 1.0)}),
    ]
    return draws


@pytest.mark.parametrize("seed", range(6))
def test_random_scenes_match_the_numpy_rasteriser(seed):
    rng = np.random.default_rng(seed)
    res = [(W, H), (64, 64), (211, 37)][seed % 3]
    draws = random_draws(rng, 40)
    win = ti.ui.Window("t", res, show_window=False)
    canvas = win.get_canvas()
    canvas.set_background_color((0.2, 0.3, 0.4))
    for kind, kw in draws:
        getattr(canvas, kind)(**kw)
    got = pixels(win)
    want = numpy_canvas(res, draws)
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_many_overlapping_circles_match_the_numpy_rasteriser():
    rng = np.random.default_rng(7)
    n = 3000  # about 40 circles over every pixel: tile lists long, order matters
    draws = [("circles", {"centers": rng.random((n, 2)).astype(np.float32), "radius": 0.06,
                          "per_vertex_color": rng.random((n, 3)).astype(np.float32)})]
    win = ti.ui.Window("t", (W, H), show_window=False)
    canvas = win.get_canvas()
    canvas.set_background_color((0.2, 0.3, 0.4))
    canvas.circles(**draws[0][1])
    np.testing.assert_allclose(pixels(win), numpy_canvas((W, H), draws), atol=1e-6)


def test_drawing_is_deferred_but_snapshots_its_input():
    win, canvas = window()
    centers = np.array([[0.5, 0.5]], np.float32)
    canvas.circles(centers, radius=0.1, color=(1.0, 1.0, 1.0))
    centers[:] = 0.1  # changed before the pixels are looked at: the drawing must not see it
    img = pixels(win)[..., 0]
    assert img[W // 2, H // 2] == 1.0 and img[int(0.1 * W), int(0.1 * H)] == 0.0


def test_canvas_kernels_survive_a_new_program_and_leave_the_snode_tree_alone():
    win, canvas = window()
    canvas.circles(np.array([[0.5, 0.5]], np.float32), radius=0.1, color=(1.0, 1.0, 1.0))
    first = pixels(win)
    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32, 4)  # the user's tree, built after the canvas drew
    win, canvas = window()
    canvas.circles(np.array([[0.5, 0.5]], np.float32), radius=0.1, color=(1.0, 1.0, 1.0))
    np.testing.assert_array_equal(pixels(win), first)

    @ti.kernel
    def fill():
        for k in x:
            x[k] = k

    fill()
    assert x.to_numpy().tolist() == [0, 1, 2, 3]
