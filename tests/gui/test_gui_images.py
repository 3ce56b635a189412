"""set_image / imwrite / imread orientation and VideoManager output."""

import importlib.util

import imageio.v3 as iio
import numpy as np
import pytest

import simgrad.gui as tg


class FakeField:
    """Duck-typed stand-in for a Taichi field."""

    def __init__(self, arr):
        self.arr = arr

    def to_numpy(self):
        return self.arr.copy()


def gradient(w, h):
    x, y = np.meshgrid(np.linspace(0, 1, w), np.linspace(0, 1, h), indexing="ij")
    return np.stack([x, y, np.full_like(x, 0.25)], axis=-1)


def test_set_image_gradient_roundtrips_through_png(tmp_path, read_rows):
    w, h = 40, 30
    img = gradient(w, h)
    gui = tg.GUI(res=(w, h), show_gui=False)
    gui.set_image(img)
    path = tmp_path / "grad.png"
    gui.show(str(path))
    rows = read_rows(path)
    assert rows.shape == (h, w, 3)
    expected = np.round(img * 255) / 255  # img[x, y] is PNG row h - 1 - y, column x
    np.testing.assert_allclose(rows, expected.transpose(1, 0, 2)[::-1], atol=1e-9)
    assert rows[0, -1, 0] == 1.0 and rows[0, -1, 1] == 1.0  # top-right is x = 1, y = 1
    assert rows[-1, 0, :2].sum() == 0  # bottom-left is the origin


@pytest.mark.parametrize(
    "make",
    [
        lambda g: g[..., 0],  # greyscale (W, H)
        lambda g: (g * 255).astype(np.uint8),  # uint8 RGB
        lambda g: np.concatenate([g, np.ones(g.shape[:2] + (1,))], axis=-1).astype(np.float32),  # RGBA
        lambda g: FakeField(g.astype(np.float32)),  # anything with to_numpy()
    ],
)
def test_set_image_accepts_taichi_image_kinds(make):
    g = gradient(12, 10)
    gui = tg.GUI(res=(12, 10), show_gui=False)
    gui.set_image(make(g))
    out = gui.get_image()
    assert out.shape == (12, 10, 4)
    assert out[11, 9, 0] == pytest.approx(1.0, abs=1 / 255)
    assert out[0, 0, 0] == pytest.approx(0.0, abs=1e-6)


def test_set_image_rejects_wrong_resolution():
    gui = tg.GUI(res=(12, 10), show_gui=False)
    with pytest.raises(ValueError, match="resolution"):
        gui.set_image(np.zeros((10, 12, 3)))


def test_imwrite_imread_roundtrip_keeps_layout(tmp_path):
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (17, 11, 3), dtype=np.uint8)
    tg.imwrite(img, str(tmp_path / "a.png"))
    back = tg.imread(str(tmp_path / "a.png"))
    assert back.shape == (17, 11, 3) and back.dtype == np.uint8
    np.testing.assert_array_equal(back, img)
    grey = tg.imread(str(tmp_path / "a.png"), channels=1)
    assert grey.shape == (17, 11, 1)
    tg.imwrite(FakeField(img[..., 0] / 255.0), str(tmp_path / "g.png"))
    np.testing.assert_array_equal(tg.imread(str(tmp_path / "g.png"))[..., 0], img[..., 0])


def test_imresize_nearest():
    img = np.arange(12).reshape(4, 3)
    out = tg.imresize(img, 8, 6)
    assert out.shape == (8, 6)
    assert out[0, 0] == img[0, 0] and out[7, 5] == img[3, 2]


def test_video_manager_writes_gif_with_all_frames(tmp_path):
    w, h, n = 24, 16, 5
    vm = tg.VideoManager(str(tmp_path), video_filename="clip", framerate=10, automatic_build=False)
    frames = [np.full((w, h, 3), k / (n - 1)) for k in range(n)]
    vm.write_frames(frames)
    assert vm.frame_counter == n
    vm.make_video(mp4=False, gif=True)
    gif = tmp_path / "clip.gif"
    assert gif.exists()
    data = iio.imread(gif, index=None)
    assert data.shape[0] == n
    assert data.shape[1:3] == (h, w)
    assert data[0].mean() < 5 and data[-1][..., :3].mean() > 250


def test_video_manager_automatic_build_and_mp4_fallback(tmp_path):
    vm = tg.VideoManager(str(tmp_path), framerate=24)
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        with pytest.warns(UserWarning, match="MP4"):
            vm.write_frames([np.random.default_rng(k).random((8, 8, 3)) for k in range(4)])
    else:
        vm.write_frames([np.random.default_rng(k).random((8, 8, 3)) for k in range(4)])
    assert (tmp_path / "video.gif").exists()  # built at the 4-frame checkpoint
    assert vm.next_video_checkpoint == 8


def test_fast_gui_img_is_taichis_packed_words():
    # taichi 1.7.4 (ti.GUI(res=(4, 3), fast_gui=True).set_image of an f32 3-vector field with offset (-1, 5)):
    # word j * W + i is pixel (i, H - 1 - j) as 0x00RRGGBB, floats truncated (0.5 -> 0x7f, 0.999 -> 0xfe)
    import simgrad as ti

    ti.init(arch=ti.cpu)
    img = ti.Vector.field(3, ti.f32, shape=(4, 3), offset=(-1, 5))
    a = np.zeros((4, 3, 3), np.float32)
    a[1, 0] = [0.5, 1.2, -0.3]
    a[3, 2] = [0.999, 0.0, 1.0]
    img.from_numpy(a)
    gui = tg.GUI("t", res=(4, 3), show_gui=False, fast_gui=True)
    gui.set_image(img)
    want = np.zeros(12, np.uint32)
    want[3], want[9] = 0xFE00FF, 0x7FFF00
    assert gui.img.dtype == np.uint32
    np.testing.assert_array_equal(gui.img, want)
    np.testing.assert_array_equal(gui.canvas.to_uint8()[1, 0], [0x7F, 0xFF, 0])  # what show(file) saves


@pytest.mark.parametrize("dtype,n", [("f32", 3), ("f64", 3), ("f32", 4)])
def test_fast_gui_field_words_by_kernel(dtype, n, monkeypatch):
    # a dense float vector field goes through simgrad.gui.fastpack's kernel; the words are Taichi's quantisation
    # min(255, max(0, int(c * 255))) in the field's precision (NaN, -inf -> 0; +inf -> 255), computed here in numpy
    import simgrad as ti
    from simgrad.gui import gui as gui_module

    ti.init(arch=ti.cpu)
    np_t = np.float32 if dtype == "f32" else np.float64
    w, h = 37, 23
    a = np.random.default_rng(1).uniform(-0.2, 1.2, (w, h, n)).astype(np_t)
    a[0, 0, :3] = [np.nan, np.inf, -np.inf]
    a[1, 1, :3] = [1.0, 0.0, 254.99 / 255]
    a[2, 2, :3] = [0.999, 1e-9, -0.0]
    img = ti.Vector.field(n, getattr(ti, dtype), shape=(w, h))
    img.from_numpy(a)
    with np.errstate(invalid="ignore"):
        s = a[..., :3] * np_t(255)
        q = np.where(s >= 255, 255, np.where(s > 0, np.trunc(np.nan_to_num(s)), 0)).astype(np.uint32)
    words = (q[..., 0] << 16) | (q[..., 1] << 8) | q[..., 2]
    want = words[:, ::-1].T.reshape(-1)  # word j * W + i is pixel (i, H - 1 - j)
    monkeypatch.setattr(gui_module, "_fast_pixels", lambda arr: pytest.fail("the numpy path ran"))
    gui = tg.GUI("t", res=(w, h), show_gui=False, fast_gui=True)
    gui.set_image(img)
    np.testing.assert_array_equal(gui.img, want)
    np.testing.assert_array_equal(gui.canvas.to_uint8(), q.astype(np.uint8))  # the canvas follows the words


def test_gui_img_without_fast_gui_is_float_rgba():
    gui = tg.GUI(res=(4, 3), show_gui=False)
    gui.set_image(np.full((4, 3), 0.5, np.float32))
    assert gui.img.shape == (4, 3, 4) and gui.img.dtype == np.float32
    np.testing.assert_array_equal(gui.img[..., 3], 1.0)


def test_lib_utils_os_name():
    import simgrad as ti

    assert ti._lib.utils.get_os_name() in ("linux", "osx", "win", "unix")


def test_imwrite_scales_wider_unsigned_ints_by_their_bound(tmp_path):
    # taichi 1.7.4 (ti.tools.imwrite): a u16/u32/u64 pixel v is written as v // (max // 256)
    for t in (np.uint16, np.uint32, np.uint64):
        step = np.iinfo(t).max // 256
        px = (np.arange(24, dtype=t).reshape(4, 2, 3) * 10) * t(step)
        path = str(tmp_path / f"u{np.dtype(t).itemsize}.png")
        tg.imwrite(px, path)
        np.testing.assert_array_equal(tg.imread(path).astype(np.int64), (px // step).astype(np.int64))


def test_set_image_of_a_vector_field_reads_its_memory_once(monkeypatch):
    """A packed vector field (pixels = ti.Vector.field(3, ...)) is read through its memory view, without the
    to_numpy copy (rasterizer's frame copied 3 MB three times), and the picture is the field's current values."""
    import simgrad as ti

    ti.init(arch=ti.cpu)
    pixels = ti.Vector.field(3, ti.f32, (40, 30))
    vals = np.random.default_rng(0).random((40, 30, 3), dtype=np.float32)
    pixels.from_numpy(vals)
    gui = tg.GUI("set_image", res=(40, 30), show_gui=False)
    monkeypatch.setattr(type(pixels), "to_numpy", lambda *a, **k: pytest.fail("copied through to_numpy"))
    gui.set_image(pixels)
    np.testing.assert_array_equal(gui.get_image()[..., :3], vals)
    pixels[3, 4] = (0.25, 0.5, 0.75)
    gui.set_image(pixels)
    np.testing.assert_array_equal(gui.get_image()[3, 4, :3], np.float32([0.25, 0.5, 0.75]))
