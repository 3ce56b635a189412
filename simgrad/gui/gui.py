"""``ti.GUI``: Taichi's immediate-mode 2D GUI, drawing into a numpy canvas.

Programs written for ``ti.GUI`` run unchanged: they draw circles, lines and images each frame and
call ``show()`` (optionally with a filename to save a screenshot).  Without a display, or with
``show_gui=False``, nothing is ever opened: frames are only kept in memory and written on request,
which is what simulations on servers and in tests need.
"""

from __future__ import annotations

import functools
import numbers
import os
import sys
import time

import numpy as np

from . import _tk
from .canvas import ImageCanvas, _points, cook_image, to_numpy
from .colors import as_rgb, hex_to_rgb, rgb_to_hex

__all__ = ["GUI", "rgb_to_hex", "hex_to_rgb"]


def _colors_arg(color, n):
    """Validate a ``ti.GUI`` colour argument (int or (n,) array); float RGB is accepted too."""
    if isinstance(color, np.ndarray) and color.dtype.kind in "iu" and color.shape != (n,):
        raise ValueError(f"color array must have shape ({n},), got {color.shape}")
    return as_rgb(color, n)


def _xy(p) -> tuple | None:
    """A point given as two Python or numpy reals, or a float numpy array of shape (2,), as two floats (the values
    ``_points`` would give); None for anything else (which takes the array path)."""
    if type(p) is np.ndarray:
        if p.shape == (2,) and p.dtype.kind == "f":
            return float(p[0]), float(p[1])
    elif type(p) in (tuple, list) and len(p) == 2:
        x, y = p
        if _real(x) and _real(y):
            return float(x), float(y)
    return None


def _real(v) -> bool:
    """isinstance(v, numbers.Real), Python's floats and ints first (the ABC check costs ~0.3 us, and gui.line in
    a Python loop makes five a call)."""
    return type(v) is float or type(v) is int or isinstance(v, numbers.Real)


@functools.lru_cache(maxsize=256)
def _hex_rgb(color: int) -> tuple:
    """0xRRGGBB as the float RGB ``as_rgb`` gives, as a tuple (cached: programs draw with a few colours)."""
    return tuple(float(v) for v in as_rgb(color))


def _fast_pixels(arr: np.ndarray) -> np.ndarray:
    """Float pixels as Taichi's fast GUI quantises them (``min(255, max(0, int(c * 255)))``); others unchanged."""
    if arr.dtype.kind != "f":
        return arr
    scaled = arr * arr.dtype.type(255)
    np.trunc(scaled, out=scaled)
    np.fmax(scaled, 0, out=scaled)  # fmax/fmin pass over NaN: NaN and -inf -> 0, +inf -> 255 (as nan_to_num + clip)
    np.fmin(scaled, 255, out=scaled)
    return scaled.astype(np.uint8)


def _pack_fast(rgb: np.ndarray) -> np.ndarray:
    """uint8 RGB (W, H, 3) -> Taichi's fast-GUI words, word ``j * W + i`` the pixel (i, H - 1 - j)."""
    from simgrad._lib.utils import get_os_name

    osx = get_os_name() == "osx"  # the window is ABGR there, opaque
    if sys.byteorder == "little":  # the words' bytes written in place: one pass, no uint32 arithmetic
        w, h = rgb.shape[:2]
        out = np.zeros((h, w, 4), np.uint8)
        rows = rgb[:, ::-1].transpose(1, 0, 2)  # row j is the pixels (i, H - 1 - j)
        out[..., :3] = rows if osx else rows[..., ::-1]
        if osx:
            out[..., 3] = 0xFF
        return out.view(np.uint32).reshape(-1)
    r, g, b = (rgb[:, ::-1, c].T.reshape(-1).astype(np.uint32) for c in range(3))
    if osx:
        return (b << 16) + (g << 8) + r + np.uint32(0xFF000000)
    return (r << 16) + (g << 8) + b


class GUI:
    """Taichi's ``ti.GUI(name, res, background_color, show_gui, fullscreen, fast_gui)``.

    ``res`` is an int or (width, height).  Radii and widths are in pixels; positions are
    normalised with (0, 0) at the bottom-left.  ``fullscreen`` is accepted for compatibility; ``fast_gui``
    keeps Taichi's packed ``img`` buffer (it takes any image ``set_image`` takes, where Taichi's takes only
    3- or 4-vector fields).
    """

    class Event:
        """An input event: ``type`` (PRESS/RELEASE/MOTION), ``key``, ``pos``, ``modifier``, ``delta``."""

        def __init__(self):
            self.type = None
            self.modifier = None
            self.pos = None
            self.key = None
            self.delta = None

        def __repr__(self):
            return f"GUI.Event(type={self.type!r}, key={self.key!r}, pos={self.pos!r})"

    class WidgetValue:
        """Handle to a slider/label value, read and written through ``.value``."""

        def __init__(self, gui, wid):
            self.gui = gui
            self.wid = wid

        @property
        def value(self):
            return self.gui._widgets[self.wid]

        @value.setter
        def value(self, value):
            self.gui._widgets[self.wid] = value

    class EventFilter:
        """Matches events by type, key, or (type, key) pairs, as ``get_events`` filters do."""

        def __init__(self, *e_filter):
            self.filter = {tuple(ent) if isinstance(ent, (list, tuple)) else ent for ent in e_filter}

        def match(self, e):
            return (e.type, e.key) in self.filter or e.type in self.filter or e.key in self.filter

    # Keys
    SHIFT = "Shift"
    ALT = "Alt"
    CTRL = "Control"
    ESCAPE = "Escape"
    RETURN = "Return"
    TAB = "Tab"
    BACKSPACE = "BackSpace"
    SPACE = " "
    UP = "Up"
    DOWN = "Down"
    LEFT = "Left"
    RIGHT = "Right"
    CAPSLOCK = "Caps_Lock"
    LMB = "LMB"
    MMB = "MMB"
    RMB = "RMB"
    EXIT = "WMClose"
    WHEEL = "Wheel"
    MOVE = "Motion"
    # Event types
    MOTION = _tk.MOTION
    PRESS = _tk.PRESS
    RELEASE = _tk.RELEASE

    def __init__(
        self, name="Taichi", res=512, background_color=0x0, show_gui=True, fullscreen=False, fast_gui=False
    ):
        show_gui = self.get_bool_environ("TI_GUI_SHOW", show_gui)
        self.fullscreen = self.get_bool_environ("TI_GUI_FULLSCREEN", fullscreen)
        self.fast_gui = self.get_bool_environ("TI_GUI_FAST", fast_gui)
        self.name = name
        if isinstance(res, numbers.Number):
            res = (res, res)
        self.res = (int(res[0]), int(res[1]))
        self.background_color = background_color
        self.canvas = ImageCanvas(self.res, background_color)
        # fast_gui: Taichi's window reads packed 0x00RRGGBB words (top row first) that set_image writes
        self._fast = np.zeros(self.res[0] * self.res[1], np.uint32) if self.fast_gui else None
        self._rgba: np.ndarray | None = None  # get_image's buffer, made at its first call
        self.key_pressed = set()
        self.event = None
        self.frame = 0
        self._widgets = []
        self._should_close = False
        self._closed = False
        self._frame_delta_limit = 1.0 / 60
        self._last_frame_time = time.perf_counter()
        self._window = _tk.open_window(name, self.res) if show_gui else None
        self.show_gui = self._window is not None

    def __enter__(self):
        return self

    def __exit__(self, e_type, val, tb):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    @staticmethod
    def get_bool_environ(key, default):
        """``bool(int(os.environ[key]))`` when set, else ``default`` (Taichi's TI_GUI_* overrides)."""
        if key not in os.environ:
            return default
        return bool(int(os.environ[key]))

    def close(self):
        """Close the window (if any); ``running`` becomes False."""
        if getattr(self, "_window", None) is not None:
            self._window.close()
            self._window = None
        self._closed = True

    # -- widgets: values only, nothing is drawn ----------------------------------------------
    def slider(self, text, minimum, maximum, step=1):
        """A slider value handle starting at ``minimum``."""
        self._widgets.append(minimum)
        return GUI.WidgetValue(self, len(self._widgets) - 1)

    def label(self, text):
        """A label value handle starting at 0."""
        self._widgets.append(0)
        return GUI.WidgetValue(self, len(self._widgets) - 1)

    def button(self, text, event_name=None):
        """Register a button; returns the key its (never, when headless) press events carry."""
        return event_name or f"WidgetButton_{text}"

    # -- drawing ----------------------------------------------------------------------------
    def clear(self, color=None):
        """Fill the canvas with ``color`` (default: the background colour)."""
        self.canvas.clear(self.background_color if color is None else color)

    def set_image(self, img):
        """Show an image of shape (W, H[, C]) matching ``res``: floats in [0, 1] or unsigned ints.

        With ``fast_gui`` the pixels become 8-bit first as Taichi's fast path makes them (floats
        ``clamp(int(c * 255), 0, 255)``, truncated, in the image's own precision), and ``img`` holds them packed.
        """
        if self._fast is not None:
            from . import fastpack

            if fastpack.packable(img):
                if tuple(img.shape) != self.res:
                    raise ValueError(f"Image resolution {tuple(img.shape)} does not match GUI resolution {self.res}")
                fastpack.pack_words(img, self._fast)
                words, res = self._fast, self.res  # the canvas follows the window's words when looked at
                self.canvas.replace_later(lambda: fastpack.unpack_words(words, res))
                return
            img = _fast_pixels(to_numpy(img))
        arr = cook_image(img)
        if arr.shape[:2] != self.res:
            raise ValueError(f"Image resolution {arr.shape[:2]} does not match GUI resolution {self.res}")
        self.canvas.replace(arr)
        if self._fast is not None:
            # 8-bit RGB already: the canvas would quantise its float copy back to these very bytes
            rgb = img if img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 else self.canvas.to_uint8()
            self._fast[:] = _pack_fast(rgb)

    def get_image(self):
        """The canvas as float32 RGBA of shape (W, H, 4), like Taichi's: one buffer, written again at each call
        (a 4 MB allocation and free per frame made the next frame's Python work several times slower)."""
        if self._rgba is None:
            self._rgba = np.ones(self.res + (4,), np.float32)
        rgba, img = self._rgba, self.canvas.img
        for c in range(3):  # a channel at a time: long strided runs (rgba[..., :3] = img: 525 -> 144 us, 400 x 400)
            rgba[..., c] = img[..., c]
        rgba[..., 3] = 1.0
        return rgba

    @property
    def img(self):
        """Taichi's ``gui.img``: with ``fast_gui`` the (W * H,) uint32 words the window shows (0x00RRGGBB, the
        top row first; 0xFFBBGGRR on macOS), else the canvas as float32 RGBA (W, H, 4)."""
        return self._fast if self._fast is not None else self.get_image()

    def contour(self, scalar_field, normalize=False):
        """Show a scalar field as a grey image, optionally normalised to [0, 1]."""
        arr = to_numpy(scalar_field).astype(np.float32)
        if normalize:
            arr = (arr - arr.min()) / (arr.max() - arr.min() + 1e-16)
        self.set_image(arr)

    def circle(self, pos, color=0xFFFFFF, radius=1):
        """One filled circle; ``radius`` in pixels."""
        p = _xy(pos)
        if p is not None and type(color) is int and _real(radius):
            self.canvas.circle1(p[0], p[1], float(radius), _hex_rgb(color))
            return
        self.canvas.circles(_points(pos)[:1], radius, _colors_arg(color, 1))

    def circles(self, pos, radius=1, color=0xFFFFFF, palette=None, palette_indices=None):
        """Filled circles at ``pos`` (n, 2); ``radius`` and ``color`` scalar or per circle.

        With ``palette`` (a list of 0xRRGGBB) each circle takes ``palette[palette_indices[i]]``.
        """
        pos = _points(pos)
        n = len(pos)
        if palette is not None:
            if palette_indices is None:
                raise ValueError("palette must be used together with palette_indices")
            ind = to_numpy(palette_indices)
            if ind.dtype.kind not in "iu":
                raise ValueError("palette_indices must be an integer array")
            ind = ind.reshape(-1).astype(np.int64)
            if ind.shape != (n,):
                raise ValueError(f"palette_indices must have shape ({n},), got {ind.shape}")
            if n and (ind.min() < 0 or ind.max() >= len(palette)):
                raise ValueError("palette_indices must lie in [0, len(palette))")
            color = np.asarray(palette, dtype=np.int64)[ind]
        self.canvas.circles(pos, radius, _colors_arg(color, n))

    def line(self, begin, end, radius=1, color=0xFFFFFF):
        """One segment; ``radius`` is its half-width in pixels."""
        a, b = _xy(begin), _xy(end)
        if a is not None and b is not None and type(color) is int and _real(radius):
            self.canvas.line1(a[0], a[1], b[0], b[1], float(radius), _hex_rgb(color))
            return
        self.canvas.lines(_points(begin)[:1], _points(end)[:1], radius, _colors_arg(color, 1))

    def lines(self, begin, end, radius=1, color=0xFFFFFF):
        """Segments from ``begin[i]`` to ``end[i]``; ``radius`` and ``color`` scalar or per line."""
        begin = _points(begin)
        self.canvas.lines(begin, end, radius, _colors_arg(color, len(begin)))

    def triangle(self, a, b, c, color=0xFFFFFF):
        """One filled triangle."""
        self.canvas.triangles(_points(a)[:1], _points(b)[:1], _points(c)[:1], _colors_arg(color, 1))

    def triangles(self, a, b, c, color=0xFFFFFF):
        """Filled triangles (a[i], b[i], c[i]); ``color`` scalar or per triangle."""
        a = _points(a)
        self.canvas.triangles(a, b, c, _colors_arg(color, len(a)))

    def rect(self, topleft, bottomright, radius=1, color=0xFFFFFF):
        """Rectangle outline with sides ``radius`` pixels thick."""
        self.canvas.rect(topleft, bottomright, radius, _colors_arg(color, 1)[0])

    def arrows(self, orig, direction, radius=1, color=0xFFFFFF, **kwargs):
        """Arrows from ``orig`` (n, 2) along ``direction``; ``tip_scale``/``angle`` shape the tip."""
        orig = _points(orig)
        self.canvas.arrows(orig, direction, radius, _colors_arg(color, len(orig)), **kwargs)

    def arrow(self, orig, direction, radius=1, color=0xFFFFFF, **kwargs):
        """One arrow."""
        self.canvas.arrows(_points(orig)[:1], _points(direction)[:1], radius, _colors_arg(color, 1), **kwargs)

    def text(self, content, pos, font_size=15, color=0xFFFFFF):
        """Text with its top-left corner at ``pos``; ``font_size`` in pixels."""
        self.canvas.text(content, pos, font_size, _colors_arg(color, 1)[0])

    @staticmethod
    def _make_field_base(w, h, bound):
        x = np.linspace(bound / w, 1 - bound / w, w)
        y = np.linspace(bound / h, 1 - bound / h, h)
        return np.stack(np.meshgrid(x, y, indexing="ij"), axis=-1).reshape(w * h, 2)

    def point_field(self, radius, color=0xFFFFFF, bound=0.5):
        """A grid of circles, one per entry of the 2D ``radius`` array."""
        radius = to_numpy(radius)
        base = self._make_field_base(radius.shape[0], radius.shape[1], bound)
        self.circles(base, radius=radius.reshape(-1), color=color)

    def arrow_field(self, direction, radius=1, color=0xFFFFFF, bound=0.5, **kwargs):
        """A grid of arrows, one per entry of the (w, h, 2) ``direction`` array."""
        direction = to_numpy(direction)
        base = self._make_field_base(direction.shape[0], direction.shape[1], bound)
        self.arrows(base, direction.reshape(-1, 2), radius=radius, color=color, **kwargs)

    def show(self, file=None):
        """Present the frame, save it to ``file`` if given, then clear to the background colour."""
        if self._window is not None:
            self._window.update(self.canvas.to_uint8())
            if self._frame_delta_limit:
                wait = self._last_frame_time + self._frame_delta_limit - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
            self._last_frame_time = time.perf_counter()
            if self._window.closed:
                self._should_close = True
        if file:
            self.canvas.save(file)
        self.frame += 1
        self.clear()

    # -- events -----------------------------------------------------------------------------
    def has_key_event(self):
        """Whether an input event is waiting (never, when headless)."""
        if self._window is None:
            return False
        self._window.poll()
        return bool(self._window.events)

    def get_event(self, *e_filter):
        """Take the first waiting event matching the filter into ``self.event``; True if found."""
        if self._window is None:  # headless: never an event (asked every frame)
            return False
        for e in self.get_events(*e_filter):
            self.event = e
            return True
        return False

    def get_events(self, *e_filter):
        """Iterate over waiting events matching the filter (by type, key or (type, key))."""
        e_filter = GUI.EventFilter(*e_filter) if e_filter else None
        while self.has_key_event():
            e = self.get_key_event()
            if e_filter is None or e_filter.match(e):
                yield e

    def get_key_event(self):
        """Wait for and return the next event; headless there are none, so this returns None."""
        if self._window is None:
            return None
        while not self._window.events and not self._window.closed:
            self._window.poll()
            time.sleep(0.005)
        if not self._window.events:
            return None
        kind, key, pos, delta = self._window.events.popleft()
        e = GUI.Event()
        e.type, e.key, e.pos = kind, key, (float(pos[0]), float(pos[1]))
        e.delta = delta if key == GUI.WHEEL else (0, 0)
        e.modifier = [m for m in (GUI.SHIFT, GUI.ALT, GUI.CTRL) if self.is_pressed(m)]
        if key == GUI.EXIT:
            self._should_close = True
        if kind == GUI.PRESS:
            self.key_pressed.add(key)
        elif kind == GUI.RELEASE:
            self.key_pressed.discard(key)
        return e

    def is_pressed(self, *keys):
        """Whether any of ``keys`` is held (Shift/Alt/Control match either side)."""
        if not self.key_pressed:  # (nothing held, and always so headless: asked for several keys a frame)
            return False
        for key in keys:
            if key in (GUI.SHIFT, GUI.ALT, GUI.CTRL) and (
                key + "_L" in self.key_pressed or key + "_R" in self.key_pressed
            ):
                return True
            if key in self.key_pressed:
                return True
        return False

    def get_cursor_pos(self):
        """Cursor position in [0, 1]^2 with y up; (0, 0) when headless, as Taichi's GUI gives (its cursor
        starts there), so programs steered by the cursor (mciso_advanced.py) compute the same."""
        if self._window is None:
            return 0.0, 0.0
        return tuple(float(v) for v in self._window.cursor)

    # -- state ------------------------------------------------------------------------------
    @property
    def running(self):
        """False once the window was closed, ``close()`` was called, or ``running = False``; also after
        ``SIMGRAD_UI_MAX_FRAMES`` shown frames (as ``ti.ui.Window``), so a headless ``while gui.running``
        loop ends (oit_renderer.py's ran until a harness killed it)."""
        limit = os.environ.get("SIMGRAD_UI_MAX_FRAMES")
        if limit and self.frame >= int(limit):
            return False
        return not (self._should_close or self._closed)

    @running.setter
    def running(self, value):
        self._should_close = not value

    @property
    def fps_limit(self):
        """Maximum frames per second when a window is shown (None: unlimited)."""
        return None if self._frame_delta_limit == 0 else 1 / self._frame_delta_limit

    @fps_limit.setter
    def fps_limit(self, value):
        self._frame_delta_limit = 0 if value is None else 1 / value
