"""Frame-to-frame facts of ti.GUI's canvas: a clear refills only what was drawn, one-primitive calls queue rows,
and every picture is the one a fresh canvas draws (checked against fresh canvases, both drawing paths)."""

import numpy as np
import pytest

import simgrad.gui as tg

W, H = 64, 48


pytestmark = pytest.mark.usefixtures("raster_path")  # every fact for both drawing paths (conftest.py)


def new_gui(background=0x000000):
    return tg.GUI("t", res=(W, H), background_color=background, show_gui=False)


def draw_frame(gui, rng, kind):
    """One frame's calls; the same rng state gives the same calls."""
    if kind == 0:
        for _ in range(3):
            gui.circle(tuple(rng.random(2)), int(rng.integers(0, 1 << 24)), float(rng.uniform(0.5, 9)))
        gui.line(rng.random(2), rng.random(2), radius=float(rng.uniform(0.5, 3)), color=0xFF8800)
    elif kind == 1:
        gui.circles(rng.random((30, 2)), radius=rng.uniform(0.5, 4, 30), color=rng.integers(0, 1 << 24, 30))
        gui.text("hi", tuple(rng.random(2)), font_size=12, color=0x00FF00)
    elif kind == 2:
        gui.triangle(tuple(rng.random(2)), tuple(rng.random(2)), tuple(rng.random(2)), color=0x3366FF)
        gui.lines(rng.random((5, 2)), rng.random((5, 2)), radius=1.5, color=0xFFFFFF)
    elif kind == 3:
        gui.set_image(rng.random((W, H, 3)).astype(np.float32))
        gui.circle((0.5, 0.5), 0xFF0000, 3)
    elif kind == 5:  # 5 to 16 one-primitive calls of a kind: their boxes found row by row in Python
        for _ in range(10):
            gui.line(rng.random(2), rng.random(2), radius=float(rng.uniform(0.5, 3)), color=0x33CC99)
        for _ in range(6):
            gui.circle(tuple(rng.random(2) * 1.4 - 0.2), 0xFFFFFF, float(rng.uniform(0.5, 9)))
    else:  # a primitive with no place: the canvas cannot say where it drew, so the next clear fills everything
        gui.circle((float("nan"), 0.5), 0xFFFFFF, 4)
        gui.line((0.1, 0.1), (0.9, 0.8), radius=2, color=0x00FFFF)


def test_frames_after_clears_are_the_pictures_of_fresh_canvases():
    rng = np.random.default_rng(11)
    gui = new_gui(0x102030)
    kinds = [0, 0, 1, 2, 0, 3, 0, 4, 1, 2, 2, 0, 5, 5, 0, 5]
    backgrounds = [0x102030] * 6 + [0x000000, 0x000000, 0x102030, 0x102030, 0xFFFFFF, 0xFFFFFF] + [0x102030] * 4
    for kind, background in zip(kinds, backgrounds):
        state = rng.bit_generator.state
        gui.clear(background)
        draw_frame(gui, rng, kind)
        shown = gui.get_image()
        rng.bit_generator.state = state
        fresh = new_gui(background)
        draw_frame(fresh, rng, kind)
        np.testing.assert_array_equal(shown, fresh.get_image())
        gui.show()


def test_a_clear_refills_only_the_boxes_drawn_since_the_last():
    # white-box: a pixel far from what was drawn is not written by the next clear of the same colour (a sentinel
    # put there behind the canvas's back survives), and a clear of another colour writes everything
    gui = new_gui()
    gui.circle((0.2, 0.2), 0xFFFFFF, 3)
    gui.line((0.1, 0.9), (0.3, 0.9), radius=1, color=0xFFFFFF)
    assert gui.get_image()[..., :3].max() == 1.0
    gui.show()  # clears
    gui.canvas._img[W - 1, 0] = 0.5  # far from the circle and the segment
    assert gui.get_image()[..., :3].max() == 0.5
    gui.clear(0x000000)
    assert gui.get_image()[W - 1, 0, 0] == 0.5 and gui.get_image()[..., :3].sum() == 1.5
    gui.clear(0x010101)
    assert (gui.get_image()[..., :3] == np.float32(1 / 255)).all()


def test_the_canvas_pixels_are_read_only_where_the_canvas_cannot_see_writes():
    gui = new_gui()
    with pytest.raises(ValueError):
        gui.canvas.img[0, 0] = 1.0
    gui.canvas.pixels()[0, 0] = 1.0  # written in place by a renderer: the canvas no longer knows what is clean
    gui.clear(0)
    assert gui.get_image()[0, 0, 0] == 0.0


@pytest.mark.parametrize("point", [tuple, list, np.array, lambda p: np.array(p, np.float32)])
def test_one_primitive_calls_draw_what_the_array_calls_draw(point):
    # gui.circle / gui.line with plain points queue Python rows; the same calls through the canvas's array methods
    # (one-row arrays) give the bit-identical picture, interleaved calls keep their order
    rng = np.random.default_rng(2)
    pts = rng.random((12, 2))
    pts[3] = (0.25, 0.75)  # exactly representable ones as well
    fast, slow = new_gui(0x202020), new_gui(0x202020)
    for k in range(6):
        p, q, r = pts[2 * k], pts[2 * k + 1], float(rng.uniform(0.5, 6))
        color = int(rng.integers(0, 1 << 24))
        fast.circle(point(list(p)), color, r)
        fast.line(point(list(p)), point(list(q)), radius=r / 2, color=color ^ 0xFFFFFF)
        p, q = (np.asarray(point(list(v)), np.float64)[None] for v in (p, q))  # (a float32 point rounds)
        slow.canvas.circles(p, r, tg.hex_to_rgb(np.array([color])))
        slow.canvas.lines(p, q, r / 2, tg.hex_to_rgb(np.array([color ^ 0xFFFFFF])))
    np.testing.assert_array_equal(fast.get_image(), slow.get_image())
    assert np.abs(fast.get_image()[..., :3] - 0x20 / 255).max() > 0.5


def test_a_few_circles_blend_as_the_kernel_blends(monkeypatch):
    # up to canvas._FEW circles are blended on their box slices by numpy (before ti.init: no kernels), with the
    # kernel's float64 lerp: the same pixels as render2d's kernel, and within float32 rounding of the order-exact
    # rasteriser; a circle drawn again (its coverage kept from the first time) blends the same
    import simgrad as ti
    from simgrad.gui import canvas, render2d

    ti.init(arch=ti.cpu)
    monkeypatch.setattr(canvas, "_kernels", lambda: None)
    rng = np.random.default_rng(8)
    base = rng.random((W, H, 3)).astype(np.float32)
    base[5, 5] = np.nan
    c = np.array([[5.2, 5.7], [30.5, 20.25], [62.9, 47.1], [-3.0, 10.0]])
    r = np.array([4.0, 7.5, 2.2, 5.0])
    rgb = rng.random((4, 3))
    few, kernel, general = base.copy(), base.copy(), base.copy()
    canvas._circles(few, c, r, rgb)
    render2d.circles(kernel, c, r, rgb)
    canvas.raster.rasterize(general, np.arange(4), *np.ceil(c - r[:, None]).T, *np.floor(c + r[:, None]).T,
                            lambda o, i, j: (np.clip(r[o] - np.hypot(c[o, 0] - i, c[o, 1] - j), 0, 1), (rgb, o)))
    np.testing.assert_array_equal(few, kernel)
    assert np.nanmax(np.abs(few - general)) < 1e-6
    assert np.abs(few - base)[~np.isnan(base)].max() > 0.5
    again = base.copy()
    canvas._circles(again, c, r, rgb)
    np.testing.assert_array_equal(again, kernel)


@pytest.mark.parametrize("threads", [1, 2])
def test_small_circles_at_every_edge_match_the_numpy_blend(monkeypatch, threads):
    # a circle of fewer than render2d.RUN rows is drawn over RUN rows of each of its columns (moved up at the
    # bottom edge), the rows past its box written back as they were: the same pixels as the numpy blend of its box
    import simgrad as ti
    from simgrad.gui import canvas, render2d

    ti.init(arch=ti.cpu, cpu_max_num_threads=threads)
    rng = np.random.default_rng(9)
    base = rng.random((W, H, 3)).astype(np.float32)
    c = np.array([[10.3, H - 1.2], [W - 0.5, H - 3.3], [30.0, 0.4], [20.6, H / 2]])
    r = np.array([3.0, 6.5, 2.5, 7.4])
    rgb = rng.random((4, 3))
    kernel = base.copy()
    render2d.circles(kernel, c, r, rgb)
    monkeypatch.setattr(canvas, "_kernels", lambda: None)
    few = base.copy()
    canvas._circles(few, c, r, rgb)
    np.testing.assert_array_equal(kernel, few)
    assert (np.abs(kernel - base).max(axis=2) > 0).sum() > 100


def test_get_image_writes_one_buffer_again_as_taichi_does():
    # taichi 1.7.4's GUI.get_image copies the canvas into its one `img` buffer and returns it: a later call
    # overwrites what an earlier one returned (no allocation per frame)
    gui = new_gui()
    first = gui.get_image()
    assert (first[..., :3] == 0).all() and (first[..., 3] == 1).all()
    gui.circle((0.5, 0.5), 0xFFFFFF, 5)
    second = gui.get_image()
    assert second is first and first[W // 2, H // 2, 0] == 1.0
    first[..., 3] = 0.0  # the caller's writes to the buffer do not stick
    assert (gui.get_image()[..., 3] == 1).all()


def test_grey_set_image_fills_every_channel_with_the_value(raster_path):
    # a grey float32 image (a field's or numpy's) fills each pixel's three channels with its value, exactly:
    # NaN, infinities, negatives and values past 1 included (the kernel once a program exists, numpy before)
    import simgrad as ti

    rng = np.random.default_rng(4)
    g = (rng.random((W, H)) * 3 - 1).astype(np.float32)
    g[1, 2], g[3, 4], g[5, 6] = np.nan, np.inf, -np.inf
    sources = [g, g.astype(np.float64)]
    if raster_path == "kernels":
        f = ti.field(ti.f32, shape=(W, H))
        f.from_numpy(g)
        sources.append(f)
    for source in sources:
        gui = new_gui(0x808080)
        gui.circle((0.5, 0.5), 0xFF0000, 4)
        gui.set_image(source)
        out = gui.get_image()[..., :3]
        for c in range(3):
            np.testing.assert_array_equal(out[..., c], g)
