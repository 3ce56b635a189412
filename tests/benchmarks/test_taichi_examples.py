"""benchmarks/taichi_examples.py under simgrad only (CI has no taichi): the child stops GUI loops after N
frames, gives the program a frame clock, dumps fields and the last image; the parent records crashes by
signal and compares two dumps."""

import argparse
import importlib.util
import os
import shutil
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("taichi_examples",
                                              os.path.join(HERE, "..", "..", "benchmarks", "taichi_examples.py"))
tex = importlib.util.module_from_spec(spec)
sys.modules["taichi_examples"] = tex
spec.loader.exec_module(tex)

GUI_LOOP = """\
import time
import taichi as ti
import taichi.math as tm
from taichi.examples.helper import scale
ti.init(arch=ti.cuda)
n = 16
pixels = ti.field(ti.f32, shape=(n, n))
speed = ti.Vector.field(2, ti.f32, shape=4)
t0 = time.time()

@ti.kernel
def paint(t: ti.f32):
    for i, j in pixels:
        pixels[i, j] = tm.fract(t * scale + i * 0.01 + j * 0.001)
    for k in speed:
        speed[k] = [k * t, -t]

gui = ti.GUI("loop", res=(n, n))
frames = 0
while gui.running:
    paint(time.time() - t0)
    gui.set_image(pixels)
    gui.show()
    frames += 1
print("frames", frames, "t", round(time.time() - t0, 3))
"""

HELPER = "scale = 3.0\n"

UNBOUNDED = """\
import taichi as ti
ti.init()
x = ti.field(ti.i32, shape=())
gui = ti.GUI("for", res=(8, 8))
for i in range(10**9):
    x[None] = i
    gui.show()
"""

SEGFAULT = """\
import ctypes
import taichi as ti
ti.init()  # a field before ti.init() is Taichi's TaichiRuntimeError
y = ti.field(ti.f32, shape=3)
ctypes.string_at(0)
"""

RAISES = """\
import taichi as ti
ti.init()
z = ti.field(ti.f32, shape=2)
z[1] = 5.0
raise ValueError("planted")
"""


@pytest.fixture
def examples(tmp_path):
    root = tmp_path / "examples"
    (root / "sub").mkdir(parents=True)
    for name, text in [("sub/gui_loop.py", GUI_LOOP), ("helper.py", HELPER), ("unbounded.py", UNBOUNDED),
                       ("segfault.py", SEGFAULT), ("raises.py", RAISES)]:
        (root / name).write_text(text)
    return str(root)


def _args(examples, frames=3, timeout=120):
    return argparse.Namespace(examples=examples, frames=frames, timeout=timeout, nice=0, keep=False,
                              taichi_init=[], frameworks="simgrad", simgrad_path=tex.ROOT, threads=0)


def _run(examples, name, tmp_path, frames=3):
    out = tmp_path / ("out-" + os.path.basename(name))
    out.mkdir()
    rec = tex.run_child(sys.executable, "simgrad", os.path.join(examples, name), _args(examples, frames), str(out))
    return rec, str(out)


def test_lists_examples_below_the_folder(examples):
    assert tex.list_examples(examples) == ["helper.py", "raises.py", "segfault.py", "sub/gui_loop.py",
                                           "unbounded.py"]


def test_gui_loop_ends_after_n_frames_on_a_frame_clock_and_dumps_state(examples, tmp_path):
    rec, out = _run(examples, "sub/gui_loop.py", tmp_path, frames=4)
    assert rec["status"] == "ok", rec.get("stderr_tail")
    assert rec["how"] == "end" and rec["frames"] == 4
    # the program's clock advanced 1/60 s per shown frame (plus 1 us per read), never with the wall clock
    assert rec["stdout"] == "frames 4 t 0.067"
    assert rec["peak_rss_mib"] > 10 and rec["wall_s"] > 0
    dump = np.load(os.path.join(out, "simgrad.npz"))
    assert {"pixels", "speed", "n", "frames", "@image"} <= set(dump.files)
    t = 3 / 60 + 1e-6 * 2  # the last paint: 3 frames shown, second clock read of that frame
    i, j = np.meshgrid(np.arange(16), np.arange(16), indexing="ij")
    np.testing.assert_allclose(dump["pixels"], np.modf(t * 3.0 + i * 0.01 + j * 0.001)[0], atol=1e-4)
    np.testing.assert_allclose(dump["speed"], [[k * t, -t] for k in range(4)], atol=1e-5)
    np.testing.assert_allclose(dump["@image"][..., 0], dump["pixels"], atol=1 / 255)
    # frame times on the real clock: one per shown frame after the first; the steady time is their median from
    # the 3rd frame on, leaving out the frames right after the harness copied the picture (frame 3 of 4 here: every
    # 3rd frame and the last one are copied)
    assert len(rec["frame_s"]) == 3 and all(0 < t < 10 for t in rec["frame_s"])
    assert rec["after_copy"] == [False, False, True]
    assert tex.steady_ms(rec) == pytest.approx(1e3 * rec["frame_s"][1])
    table = tex.speed_table([{"example": "a.py", "simgrad": rec, "taichi": dict(rec, frame_s=[1.0, 0.2, 0.2])}])
    assert f"| a.py | 200.00 | {tex.steady_ms(rec):.2f} |" in table and "1 examples timed by both" in table


def test_steady_time_leaves_out_frames_after_a_picture_copy():
    rec = {"status": "ok", "frame_s": [9.0, 1.0, 5.0, 2.0, 3.0, 7.0], "after_copy": [False, False, True, False, False,
                                                                                    True]}
    assert tex.steady_ms(rec) == pytest.approx(2000.0)  # the median of 1, 2, 3 (5 and 7 came after copies)
    assert tex.steady_ms(dict(rec, after_copy=None)) == pytest.approx(3000.0)  # an older record: all from the 3rd


def test_a_loop_that_never_asks_running_is_stopped(examples, tmp_path):
    rec, out = _run(examples, "unbounded.py", tmp_path, frames=2)
    assert rec["status"] == "ok" and rec["how"] == "frame limit" and rec["frames"] == 3
    assert int(np.load(os.path.join(out, "simgrad.npz"))["x"]) == 2


def test_a_planted_crash_is_recorded_by_its_signal(examples, tmp_path):
    rec, _ = _run(examples, "segfault.py", tmp_path)
    assert rec["status"] == "SIGSEGV" and rec["rc"] < 0


def test_an_exception_is_recorded_and_the_state_still_dumped(examples, tmp_path):
    rec, out = _run(examples, "raises.py", tmp_path)
    assert rec["status"] == "exit 1" and rec["how"] == "exception"
    assert rec["error"].startswith("ValueError: planted")
    assert np.load(os.path.join(out, "simgrad.npz"))["z"].tolist() == [0.0, 5.0]


def test_timeout_kills_the_child(examples, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    args = _args(examples, frames=10**6, timeout=3)
    rec = tex.run_child(sys.executable, "simgrad", os.path.join(examples, "unbounded.py"), args, str(out))
    assert rec["status"] == "timeout"


def test_compare_states_finds_a_changed_array_and_image(examples, tmp_path):
    _, out = _run(examples, "sub/gui_loop.py", tmp_path)
    shutil.copy(os.path.join(out, "simgrad.npz"), os.path.join(out, "taichi.npz"))
    same = tex.compare_states(out)
    assert same["worst_err"] == 0 and same["image"] == 0 and not same["only_simgrad"]
    entry = {"simgrad": {"status": "ok"}, "taichi": {"status": "ok"}, "compare": same, "stdout_agrees": True}
    assert tex.verdict(entry) == "yes"

    d = dict(np.load(os.path.join(out, "simgrad.npz")))
    d["speed"] = d["speed"].copy()
    d["speed"][1, 0] += 0.5 * np.abs(d["speed"]).max()
    d["@image"] = d["@image"] * 0.5
    del d["frames"]
    np.savez(os.path.join(out, "taichi.npz"), **d)
    diff = tex.compare_states(out)
    assert diff["worst"] == "speed" and diff["worst_err"] == pytest.approx(0.5, rel=1e-3)  # 1.5 t of the largest, 3 t
    assert diff["fraction"]["speed"] == pytest.approx(1 / 8)
    assert diff["image"] > 0.1 and diff["only_simgrad"] == ["frames"]
    assert tex.verdict(dict(entry, compare=diff)) == "no"


@pytest.mark.parametrize("a, b, agrees", [
    ("x = 1.0000001\nok", "x = 1.0\nok", True),
    ("x = 1.1", "x = 1.0", False),
    ("a 1", "b 1", False),
    ("1\n2", "1", False),
])
def test_stdout_comparison_tolerates_rounding_only(a, b, agrees):
    assert tex.compare_stdout(a, b)[0] is agrees


TAICHI_EXAMPLES = "/work/tivenv/lib/python3.11/site-packages/taichi/examples"


@pytest.mark.skipif(not os.path.isdir(TAICHI_EXAMPLES), reason="no taichi wheel's examples here")
@pytest.mark.parametrize("name", ["minimal.py", "algorithm/laplace.py"])
def test_shipped_examples_run_under_simgrad(name, tmp_path):
    rec, out = _run(TAICHI_EXAMPLES, name, tmp_path)
    assert rec["status"] == "ok" and rec["how"] == "end", rec.get("stderr_tail")
    if name == "minimal.py":
        assert rec["stdout"] == "42\n42.0"  # the kernel returns ti.f32
    else:
        assert "x" in np.load(os.path.join(out, "simgrad.npz")).files


def test_taichi_fast_gui_words_decode_to_an_x_y_image():
    # taichi's fast_gui buffer: 0x00RRGGBB words, top row first (read from taichi 1.7.4: a red pixel at
    # x=1, y=0 of a 4x3 window is word 9, a blue one at x=3, y=2 is word 3)
    class FakeGUI:
        res = (4, 3)
        img = np.zeros(12, np.uint32)

    FakeGUI.img[9], FakeGUI.img[3], FakeGUI.img[0] = 0xFF0000, 0x0000FF, 0x007F00
    assert tex._is_fast(FakeGUI)
    img = tex._fast_gui_image(FakeGUI)
    want = np.zeros((4, 3, 3), np.float32)
    want[1, 0] = [1, 0, 0]
    want[3, 2] = [0, 0, 1]
    want[0, 2, 1] = 127 / 255
    np.testing.assert_array_equal(img, want)


def test_fields_too_large_to_dump_are_refused_before_to_numpy(monkeypatch):
    import simgrad as ti

    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32, shape=(4, 4))
    monkeypatch.setattr(tex, "MAX_ELEMENTS", 8)
    with pytest.raises(ValueError, match=r"not dumped: 16 cells"):
        tex._arrays(x, np)
    monkeypatch.setattr(tex, "MAX_ELEMENTS", 16)
    assert tex._arrays(x, np)[""].shape == (4, 4)


@pytest.mark.parametrize("frame_ms,min_seconds,want,kept", [
    (0.05, 0.25, 300, False),  # 50 us frames: the most frames allowed, taichi runs again with them
    (10.0, 0.25, 25, False),  # 10 ms: 25 frames make 0.25 s
    (100.0, 0.25, 12, True),  # long frames: --frames, taichi's probe is its record
    (0.05, 0.0, 12, True),  # --min-seconds 0: --frames, no probe
])
def test_short_frames_get_more_frames_for_both_frameworks(monkeypatch, frame_ms, min_seconds, want, kept):
    calls = []

    def fake_child(python, framework, script, args, out, frames=None):
        calls.append((framework, frames))
        return {"status": "ok", "frame_s": [1.0] + [frame_ms / 1e3] * (frames - 1)}

    monkeypatch.setattr(tex, "run_child", fake_child)
    args = argparse.Namespace(frames=12, min_seconds=min_seconds, max_frames=300)
    frames, probe = tex.steady_frames("x.py", args, {"taichi": "py"}, "x.py", "out")
    assert frames == want
    assert (probe is not None) == (kept and min_seconds > 0)
    assert calls == ([("taichi", 12)] if min_seconds else [])
