"""ti.ui.Window headless: stable defaults for input and widgets, frame limits and recording, saved images;
ti.tools (PLYWriter, imshow) and the ti._lib.core backend probes."""

from __future__ import annotations

import os

import numpy as np
import pytest

import simgrad as ti


@pytest.fixture(autouse=True)
def _program():
    ti.init(arch=ti.cpu)


def test_headless_input_has_stable_defaults():
    window = ti.ui.Window("w", (64, 48), vsync=True)  # show_window=True, but there is no display
    assert window.running
    assert window.get_events() == [] and window.get_events(ti.ui.PRESS) == []
    assert window.get_event() is False and window.get_event(ti.ui.PRESS) is False
    assert not window.is_pressed("w", ti.ui.LMB, ti.ui.SHIFT)
    assert window.get_cursor_pos() == (0.5, 0.5)
    assert window.get_window_shape() == (64, 48)
    window.running = False
    assert not window.running


def test_gui_widgets_return_their_defaults():
    window = ti.ui.Window("w", (64, 48), show_window=False)
    for gui in (window.get_gui(), window.GUI):
        assert gui.begin("options", 0.05, 0.1, 0.2, 0.3) is True
        gui.text("hello")
        assert gui.slider_float("x", 0.25, 0.0, 1.0) == 0.25
        assert gui.slider_int("n", 3, 0, 10) == 3
        assert gui.checkbox("on", True) is True
        assert gui.button("go") is False
        assert gui.color_edit_3("c", (0.1, 0.2, 0.3)) == (0.1, 0.2, 0.3)
        gui.end()
        with gui.sub_window("sub", 0.1, 0.1, 0.5, 0.5) as w:
            assert w.slider_float("y", 1.5, 0.0, 2.0) == 1.5


def test_camera_tracking_does_not_move_without_input():
    window = ti.ui.Window("w", (64, 48), show_window=False)
    cam = ti.ui.make_camera()
    cam.position(1.0, 2.0, 3.0)
    cam.lookat(1.0, 2.0, 2.0)
    for _ in range(3):
        cam.track_user_inputs(window, movement_speed=0.03, hold_key=ti.ui.RMB)
        cam.track_user_inputs(window)
    np.testing.assert_allclose(cam.curr_position, (1.0, 2.0, 3.0))
    np.testing.assert_allclose(cam.curr_lookat, (1.0, 2.0, 2.0), atol=1e-12)


def test_camera_tracking_moves_forward_when_w_is_held(monkeypatch):
    window = ti.ui.Window("w", (64, 48), show_window=False)
    monkeypatch.setattr(window, "is_pressed", lambda *keys: "w" in keys)
    cam = ti.ui.Camera()
    cam.position(0.0, 0.0, 3.0)
    cam.lookat(0.0, 0.0, 0.0)
    cam.track_user_inputs(window)  # the first call only starts the clock
    import time

    time.sleep(0.02)
    cam.track_user_inputs(window, movement_speed=0.1)
    assert cam.curr_position[2] < 3.0 and abs(cam.curr_position[0]) < 1e-12  # along -z, the view direction
    np.testing.assert_allclose(cam.curr_lookat - cam.curr_position, (0.0, 0.0, -1.0), atol=1e-12)


def test_max_frames_ends_the_loop(monkeypatch):
    monkeypatch.setenv("SIMGRAD_UI_MAX_FRAMES", "3")
    window = ti.ui.Window("w", (16, 16), show_window=False)
    frames = 0
    while window.running:
        window.show()
        frames += 1
    assert frames == 3
    monkeypatch.delenv("SIMGRAD_UI_MAX_FRAMES")
    window = ti.ui.Window("w", (16, 16), show_window=False, max_frames=2)
    window.show()
    assert window.running
    window.show()
    assert not window.running


def test_recording_writes_every_shown_frame_and_a_gif(tmp_path, monkeypatch):
    monkeypatch.setenv("SIMGRAD_UI_FRAMES", str(tmp_path))
    window = ti.ui.Window("my run", (32, 24), show_window=False)
    canvas = window.get_canvas()
    for k in range(4):
        canvas.set_background_color((k / 3, 0.0, 0.0))
        window.show()
    window.destroy()
    frames = sorted(os.listdir(tmp_path / "frames"))
    assert frames == [f"{k:06d}.png" for k in range(4)]
    last = ti.tools.imread(str(tmp_path / "frames" / frames[-1]))
    assert last.shape == (32, 24, 3) and (last[..., 0] == 255).all()
    assert (tmp_path / "my_run.gif").exists()


def test_save_image_matches_the_image_buffer(tmp_path):
    window = ti.ui.Window("w", (40, 30), show_window=False)
    canvas, scene = window.get_canvas(), window.get_scene()
    canvas.set_background_color((0.2, 0.4, 0.6))
    cam = ti.ui.Camera()
    cam.position(0.0, 0.0, 2.0)
    cam.lookat(0.0, 0.0, 0.0)
    scene.set_camera(cam)
    scene.point_light((0.0, 0.0, 5.0), (1.0, 1.0, 1.0))
    scene.particles(np.zeros((1, 3), np.float32), radius=0.3, color=(1.0, 1.0, 0.0))
    canvas.scene(scene)
    window.save_image(str(tmp_path / "f.png"))
    saved = ti.tools.imread(str(tmp_path / "f.png"))
    buf = window.get_image_buffer_as_numpy()
    np.testing.assert_array_equal(saved, (np.clip(buf[..., :3], 0, 1) * 255 + 0.5).astype(np.uint8))
    assert (saved[20, 15] != saved[0, 0]).any()


def test_backend_probes_answer_false_and_tools_names_exist():
    core = ti._lib.core
    assert not any(f() for f in (core.with_vulkan, core.with_cuda, core.with_metal, core.with_opengl,
                                 core.with_dx11, core.with_dx12, core.with_amdgpu))
    assert core.GGUI_AVAILABLE
    for name in ("PLYWriter", "imshow", "imwrite", "imread", "imresize", "VideoManager"):
        assert callable(getattr(ti.tools, name))
    for name in ("Window", "Scene", "Camera", "make_camera", "ProjectionMode", "Canvas", "Gui", "GUI"):
        assert hasattr(ti.ui, name)
    assert ti.ui.ProjectionMode.Perspective == 0 and ti.ui.ProjectionMode.Orthogonal == 1


def test_imshow_returns_headless():
    ti.tools.imshow(np.zeros((8, 6, 3), np.float32), "nothing to see")


def _read_ply(path):
    with open(path, "rb") as f:
        data = f.read()
    head, body = data.split(b"end_header\n", 1)
    return head.decode().splitlines(), body


def test_ply_writer_binary_round_trip(tmp_path):
    n, nf = 5, 2
    pos = np.arange(15, dtype=np.float32).reshape(5, 3)
    w = ti.tools.PLYWriter(num_vertices=n, num_faces=nf, face_type="tri")
    w.add_vertex_pos(pos[:, 0], pos[:, 1], pos[:, 2])
    w.add_vertex_color(np.ones(n), np.zeros(n), np.full(n, 0.5))
    w.add_vertex_id()
    w.add_faces(np.array([0, 1, 2, 2, 3, 4]))
    w.add_face_id()
    w.export_frame(7, str(tmp_path / "out.ply"))
    head, body = _read_ply(tmp_path / "out_000007.ply")
    assert head[1].startswith("format binary_") and "element vertex 5" in head and "element face 2" in head
    props = [h.split()[-1] for h in head if h.startswith("property") and "list" not in h]
    assert props == ["x", "y", "z", "red", "green", "blue", "id", "id"]
    vert = np.dtype([("x", "f4"), ("y", "f4"), ("z", "f4"), ("r", "f4"), ("g", "f4"), ("b", "f4"), ("id", "i4")])
    verts = np.frombuffer(body[: n * vert.itemsize], vert)
    np.testing.assert_array_equal(np.stack([verts["x"], verts["y"], verts["z"]], 1), pos)
    np.testing.assert_array_equal(verts["id"], np.arange(n))
    face = np.dtype([("n", "u1"), ("v", "i4", (3,)), ("id", "i4")])
    faces = np.frombuffer(body[n * vert.itemsize:], face)
    assert (faces["n"] == 3).all() and faces["v"].tolist() == [[0, 1, 2], [2, 3, 4]]


def test_ply_writer_ascii_and_errors(tmp_path, capsys):
    w = ti.tools.PLYWriter(num_vertices=2)
    w.add_vertex_pos(np.array([0.0, 1.0]), np.array([2.0, 3.0]), np.array([4.0, 5.0]))
    w.add_vertex_channel("temperature", "double", np.array([1.5, 2.5]))
    w.export_ascii(str(tmp_path / "a.ply"))
    lines = (tmp_path / "a.ply").read_text().splitlines()
    assert lines[lines.index("end_header") + 1:] == ["0.0 2.0 4.0 1.5", "1.0 3.0 5.0 2.5"]
    # Taichi's writer prints and skips a channel of an unknown type (its export_mesh.py example relies on it)
    w.add_vertex_channel("q", "float128", np.zeros(2))
    w.add_face_channel("foo_key", "foo_data_type", np.zeros(2))
    assert capsys.readouterr().out.splitlines() == ["Unknown type float128 detected, skipping this channel",
                                                    "Unknown type foo_data_type detected, skipping this channel"]
    assert w.vertex_channels == ["x", "y", "z", "temperature"] and w.face_channels == []
    with pytest.raises(ValueError, match="not a multiple of 2"):
        w.add_vertex_channel("q", "float", np.zeros(3))
    bad = ti.tools.PLYWriter(num_vertices=2, num_faces=1)
    bad.add_vertex_pos(np.zeros(2), np.zeros(2), np.zeros(2))
    bad.add_faces(np.array([0, 1, 5]))
    with pytest.raises(ValueError, match="face indices"):
        bad.export(str(tmp_path / "b.ply"))


def test_canvas_circles_per_vertex_radius():
    window = ti.ui.Window("w", (100, 100), show_window=False)
    canvas = window.get_canvas()
    canvas.set_background_color((0.0, 0.0, 0.0))
    centers = np.array([[0.25, 0.5], [0.75, 0.5]], np.float32)
    canvas.circles(centers, radius=0.0, per_vertex_radius=np.array([0.05, 0.15], np.float32), color=(1.0, 1.0, 1.0))
    img = window.get_image_buffer_as_numpy()[..., 0]
    left, right = img[:50].sum(), img[50:].sum()
    assert abs(left - np.pi * 5 ** 2) < 2 * np.pi * 5 and abs(right - np.pi * 15 ** 2) < 2 * np.pi * 15


def test_max_frames_ends_a_ti_gui_loop_too(monkeypatch):
    """Issue 21: oit_renderer.py's `while gui.running: gui.show()` ran headless until a harness killed it."""
    monkeypatch.setenv("SIMGRAD_UI_MAX_FRAMES", "4")
    gui = ti.GUI("g", (16, 16), show_gui=False)
    frames = 0
    while gui.running and frames < 100:
        gui.show()
        frames += 1
    assert frames == 4
    monkeypatch.delenv("SIMGRAD_UI_MAX_FRAMES")
    assert gui.running
