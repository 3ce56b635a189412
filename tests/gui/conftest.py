import numpy as np
import pytest
from PIL import Image


@pytest.fixture(autouse=True)
def _headless(monkeypatch):
    """Never open a window in tests, whatever the environment."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("TI_GUI_SHOW", raising=False)
    import simgrad.gui._tk as tk_backend

    monkeypatch.setattr(tk_backend, "display_available", lambda: False)


@pytest.fixture
def read_rows():
    """Read an image file as a (rows, cols, 3) float array in [0, 1], row 0 at the top."""

    def read(path):
        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0

    return read


@pytest.fixture(params=["numpy", "kernels"])
def raster_path(request, monkeypatch):
    """Both ways ti.GUI's canvas draws: simgrad kernels (render2d.py, once a program exists) and the numpy
    rasteriser (before ti.init). Modules whose every fact holds for both use it for all their tests."""
    from simgrad.gui import canvas

    if request.param == "numpy":
        monkeypatch.setattr(canvas, "_kernels", lambda: None)
    else:
        import simgrad as ti

        ti.init(arch=ti.cpu)
        assert canvas._kernels() is not None
    return request.param
