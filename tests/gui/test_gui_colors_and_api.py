"""Colour helpers, headless GUI state/events, and the ti.ui-style Window."""

import numpy as np
import pytest

import simgrad.gui as tg


def test_rgb_to_hex_hand_computed():
    assert tg.rgb_to_hex((1, 0, 0)) == 0xFF0000
    assert tg.rgb_to_hex([0, 1, 0]) == 0x00FF00
    assert tg.rgb_to_hex(np.array([0.0, 0.0, 1.0])) == 0x0000FF
    assert tg.rgb_to_hex((0.5, 0.5, 0.5)) == 0x7F7F7F  # Taichi truncates 127.5 -> 127
    assert tg.rgb_to_hex((2.0, -1.0, 1.0)) == 0xFF00FF  # clamped
    assert isinstance(tg.rgb_to_hex((1, 1, 1)), int)


def test_rgb_to_hex_arrays():
    cols = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    np.testing.assert_array_equal(tg.rgb_to_hex(cols), [0xFF0000, 0x00FF00, 0x0000FF, 0xFFFFFF])
    # Taichi indexes c[0], c[1], c[2]: channel-first arrays work too.
    np.testing.assert_array_equal(tg.rgb_to_hex(cols.T), [0xFF0000, 0x00FF00, 0x0000FF, 0xFFFFFF])


def test_hex_to_rgb_and_round_trip():
    assert tg.hex_to_rgb(0xFF8000) == (1.0, 128 / 255, 0.0)
    assert tg.hex_to_rgb(0x000000) == (0.0, 0.0, 0.0)
    hexes = np.random.default_rng(0).integers(0, 0x1000000, 500)
    rgb = tg.hex_to_rgb(hexes)
    assert rgb.shape == (500, 3)
    np.testing.assert_array_equal(tg.rgb_to_hex(rgb), hexes)
    for h in hexes[:20]:
        assert tg.rgb_to_hex(tg.hex_to_rgb(int(h))) == h


def test_headless_gui_state_and_events():
    gui = tg.GUI("x", res=32, show_gui=False)
    assert gui.res == (32, 32)
    assert gui.running
    assert list(gui.get_events()) == []
    assert list(gui.get_events(tg.GUI.PRESS)) == []
    assert gui.get_event(tg.GUI.ESCAPE, tg.GUI.EXIT) is False
    assert gui.get_key_event() is None
    assert not gui.has_key_event()
    assert not gui.is_pressed(tg.GUI.SPACE, "a", tg.GUI.SHIFT)
    assert gui.get_cursor_pos() == (0.0, 0.0)  # Taichi's headless ti.GUI: the C++ cursor starts at (0, 0)
    gui.fps_limit = 30
    assert gui.fps_limit == pytest.approx(30)
    gui.running = False
    assert not gui.running
    gui.running = True
    assert gui.running
    gui.close()
    assert not gui.running


def test_gui_constants_match_taichi():
    G = tg.GUI
    assert (G.ESCAPE, G.SPACE, G.LMB, G.RMB, G.EXIT, G.SHIFT) == (
        "Escape",
        " ",
        "LMB",
        "RMB",
        "WMClose",
        "Shift",
    )
    assert G.PRESS != G.RELEASE and G.MOTION not in (G.PRESS, G.RELEASE)


def test_headless_without_display_even_when_show_gui():
    gui = tg.GUI(res=(8, 8))  # show_gui defaults to True; the test environment has no display
    assert gui.show_gui is False
    for _ in range(3):
        gui.circle((0.5, 0.5))
        gui.show()
    assert gui.frame == 3


def test_widgets_headless():
    gui = tg.GUI(res=8, show_gui=False)
    s = gui.slider("dt", 0.1, 2.0)
    assert s.value == 0.1
    s.value = 1.5
    assert s.value == 1.5
    assert gui.button("Reset") == "WidgetButton_Reset"


def test_ui_window_canvas_uses_height_relative_sizes(tmp_path, read_rows):
    window = tg.ui.Window("w", (100, 50), show_window=True)
    assert window.running and window.get_window_shape() == (100, 50)
    canvas = window.get_canvas()
    canvas.set_background_color((0.0, 0.0, 0.2))
    canvas.circles(np.array([[0.5, 0.5]]), radius=0.1, color=(1.0, 0.0, 0.0))  # 5 pixels
    img = window.get_image_buffer_as_numpy()
    assert img.shape == (100, 50, 4)
    np.testing.assert_allclose(img[50, 25, :3], [1, 0, 0])
    assert img[50 + 3, 25, 0] == 1.0
    np.testing.assert_allclose(img[50 + 6, 25, :3], [0, 0, 0.2], atol=1e-6)
    path = tmp_path / "ui.png"
    window.save_image(str(path))
    rows = read_rows(path)
    assert rows.shape == (50, 100, 3) and rows[25 - 1, 50, 0] == 1.0
    window.show()
    np.testing.assert_allclose(window.get_image_buffer_as_numpy()[50, 25, :3], [0, 0, 0.2], atol=1e-6)
    assert window.get_events() == [] and window.get_event(tg.ui.PRESS) is False
    window.running = False
    assert not window.running


def test_ui_lines_and_triangles_with_indices_and_vertex_colors():
    window = tg.ui.Window("w", (64, 64), show_window=False)
    canvas = window.get_canvas()
    verts = np.array([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9], [0.1, 0.5]], dtype=np.float32)
    canvas.triangles(verts, indices=np.array([0, 1, 2]), per_vertex_color=np.eye(4, 3))
    img = window.get_image_buffer_as_numpy()[..., :3]
    np.testing.assert_allclose(img[int(0.5 * 64), int(0.37 * 64)].sum(), 1.0, atol=1e-6)  # barycentric mix
    assert img[7, 7, 0] > img[7, 7, 1]  # near vertex 0 (red)
    canvas.set_background_color((0, 0, 0))
    canvas.lines(verts, width=0.05, indices=np.array([[0, 3]]), color=(0.0, 1.0, 0.0))
    img = window.get_image_buffer_as_numpy()[..., :3]
    np.testing.assert_allclose(img[6, 20], [0, 1, 0])
    assert img[40, 20].sum() == 0
