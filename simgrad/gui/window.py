"""``ti.ui`` (GGUI) ``Window`` and ``Canvas`` on top of the numpy canvas ``ti.GUI`` uses.

GGUI programs draw vertex fields each frame and call ``window.show()``.  The pixels live in the numpy
canvas ``ti.GUI`` uses; the 2D primitives (circles, lines, triangles) are drawn into it by the kernels of
:mod:`.render2d`, 3D scenes by those of :mod:`.render3d`, so GGUI programs run headless and can save
frames; a Tk window shows them where a display exists.  Sizes follow ``ti.ui``: 2D radii and line widths
are fractions of the window height, colours are float RGB tuples.

Two environment variables help running GGUI programs unattended: ``SIMGRAD_UI_FRAMES=<folder>``
records every shown frame there (and assembles ``<folder>/<window name>.gif`` when the window is
destroyed or the program exits), ``SIMGRAD_UI_MAX_FRAMES=<n>`` makes ``window.running`` False after
``n`` frames, so a ``while window.running`` loop ends headless.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import re

import numpy as np

import simgrad as ti

from . import _tk, render2d
from .canvas import ImageCanvas, _per_item, cook_image, to_numpy
from .colors import as_rgb
from .gui import GUI as _GUI
from .image import imresize

__all__ = ["Window", "Canvas", "Gui"]

PRESS = _tk.PRESS
RELEASE = _tk.RELEASE
# key names are the GUI's (ti.ui and ti.GUI share them)
SHIFT, ALT, CTRL, ESCAPE = _GUI.SHIFT, _GUI.ALT, _GUI.CTRL, _GUI.ESCAPE
RETURN, TAB, BACKSPACE, SPACE = _GUI.RETURN, _GUI.TAB, _GUI.BACKSPACE, _GUI.SPACE
UP, DOWN, LEFT, RIGHT, CAPSLOCK = _GUI.UP, _GUI.DOWN, _GUI.LEFT, _GUI.RIGHT, _GUI.CAPSLOCK
LMB, MMB, RMB = _GUI.LMB, _GUI.MMB, _GUI.RMB


def _vertices(v):
    arr = to_numpy(v).astype(np.float64)
    return arr.reshape(-1, arr.shape[-1])[:, :2]


def _indices(indices, arity):
    if indices is None:
        return None
    return to_numpy(indices).astype(np.int64).reshape(-1, arity)


def _vertex_colors(per_vertex_color):
    arr = to_numpy(per_vertex_color).astype(np.float64)
    return arr.reshape(-1, arr.shape[-1])[:, :3]


class Canvas:
    """The 2D canvas of a :class:`Window` (``window.get_canvas()``)."""

    def __init__(self, image_canvas: ImageCanvas):
        self._canvas = image_canvas
        self._background = (0.0, 0.0, 0.0)
        # depth keys of the last canvas.scene() (this window's own buffer) and its camera
        self._depth: np.ndarray | None = None
        self._depth_cam: np.ndarray | None = None

    def set_background_color(self, color):
        """Set the clear colour (float RGB) and fill the canvas with it."""
        self._background = tuple(float(c) for c in color[:3])
        self._canvas.clear(self._background)

    def set_image(self, img):
        """Draw an image (W, H[, C]) stretched over the whole canvas."""
        arr = cook_image(img)
        if arr.shape[:2] != self._canvas.res:
            arr = imresize(arr, *self._canvas.res)
        self._canvas.replace(arr)

    def circles(self, centers, radius, color=(0.5, 0.5, 0.5), per_vertex_color=None, per_vertex_radius=None):
        """Circles at ``centers`` with ``radius`` (or ``per_vertex_radius``) a fraction of the window height."""
        c = _vertices(centers) * self._scale()
        n = len(c)
        rgb = as_rgb(_vertex_colors(per_vertex_color) if per_vertex_color is not None else _rgb(color), n)
        if per_vertex_radius is not None:
            r = _per_item(to_numpy(per_vertex_radius).reshape(-1), n, "per_vertex_radius") * self._canvas.res[1]
        else:
            r = np.full(n, float(radius) * self._canvas.res[1])
        self._canvas.defer(lambda img: render2d.circles(img, c, r, rgb))

    def lines(self, vertices, width, indices=None, color=(0.5, 0.5, 0.5), per_vertex_color=None):
        """Segments between vertex pairs (or index pairs); ``width`` a fraction of the height."""
        v = _vertices(vertices) * self._scale()
        idx = _indices(indices, 2)
        if idx is None:
            idx = np.arange(len(v) - len(v) % 2).reshape(-1, 2)
        n = len(idx)
        vc = _vertex_colors(per_vertex_color)[idx] if per_vertex_color is not None else None
        rgb = as_rgb(_rgb(color), n)
        r = np.full(n, 0.5 * float(width) * self._canvas.res[1])
        A, B = v[idx[:, 0]], v[idx[:, 1]]
        self._canvas.defer(lambda img: render2d.lines(img, A, B, r, rgb, vertex_colors=vc))

    def triangles(self, vertices, color=(0.5, 0.5, 0.5), indices=None, per_vertex_color=None):
        """Filled triangles from vertex triples (or index triples)."""
        v = _vertices(vertices) * self._scale()
        idx = _indices(indices, 3)
        if idx is None:
            idx = np.arange(len(v) - len(v) % 3).reshape(-1, 3)
        vc = _vertex_colors(per_vertex_color)[idx] if per_vertex_color is not None else None
        rgb = as_rgb(_rgb(color), len(idx))
        P = v[idx]
        self._canvas.defer(lambda img: render2d.triangles(img, P, rgb, vertex_colors=vc))

    def _scale(self):
        return np.array(self._canvas.res, np.float64)

    def scene(self, scene):
        """Render a :class:`~.scene.Scene` over the canvas (z-buffered; uncovered pixels are kept)."""
        from . import render3d

        frame = scene._take_frame(self._canvas.res)
        if self._depth is None:
            self._depth = np.empty(self._canvas.res, np.int64)
        render3d.render(self._canvas.pixels(), frame, self._depth)
        self._depth_cam = frame.cam


def _rgb(color):
    return np.asarray(color, dtype=np.float64).reshape(-1)[:3]


class Gui:
    """Headless stand-in for ``window.get_gui()``: widgets return their current values."""

    def sub_window(self, name, x, y, width, height):
        return contextlib.nullcontext(self)

    def begin(self, name, x, y, width, height):
        return True

    def end(self):
        pass

    def text(self, text, color=None):
        pass

    def checkbox(self, text, old_value):
        return old_value

    def slider_int(self, text, old_value, minimum, maximum):
        return old_value

    def slider_float(self, text, old_value, minimum, maximum):
        return old_value

    def color_edit_3(self, text, old_value):
        return old_value

    def button(self, text):
        return False


class Window:
    """``ti.ui.Window(name, res, vsync=False, show_window=True)``; headless without a display."""

    def __init__(self, name, res, vsync=False, show_window=True, fps_limit=1000, pos=(100, 100),
                 frames_dir=None, max_frames=None):
        self.name = name
        self.res = (int(res[0]), int(res[1]))
        self._image = ImageCanvas(self.res)
        self._canvas = Canvas(self._image)
        self._scene = None
        self._gui = Gui()
        self._running = True
        self._window = _tk.open_window(name, self.res) if show_window else None
        self.event = None
        self.frame = 0
        if max_frames is None and os.environ.get("SIMGRAD_UI_MAX_FRAMES"):
            max_frames = int(os.environ["SIMGRAD_UI_MAX_FRAMES"])
        self.max_frames = max_frames
        frames_dir = frames_dir or os.environ.get("SIMGRAD_UI_FRAMES")
        self._video = None
        if frames_dir:
            from .image import VideoManager

            video_name = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)) or "video"
            self._video = VideoManager(frames_dir, video_filename=video_name, automatic_build=False)
            atexit.register(self.make_video)

    @property
    def running(self):
        """False once closed (window closed, ``destroy()``, ``running = False``, or ``max_frames`` shown)."""
        if self.max_frames is not None and self.frame >= self.max_frames:
            return False
        return self._running and not (self._window is not None and self._window.closed)

    @running.setter
    def running(self, value):
        self._running = bool(value)

    def get_canvas(self):
        return self._canvas

    def get_gui(self):
        return self._gui

    GUI = property(get_gui)

    def get_scene(self):
        """The window's 3D :class:`~.scene.Scene` (one per window, drawn by ``canvas.scene(scene)``)."""
        if self._scene is None:
            from .scene import Scene

            self._scene = Scene._for_window()
        return self._scene

    def get_window_shape(self):
        return self.res

    def show(self):
        """Present the frame (and record it, when recording), then start the next one from the background
        colour."""
        if self._window is not None:
            self._window.update(self._image.to_uint8())
        if self._video is not None:
            self._video.write_frame(self._image.to_uint8())
        self.frame += 1
        self._image.clear(self._canvas._background)

    def save_image(self, filename):
        """Write the current frame (call before ``show()``) to an image file."""
        self._image.save(filename)

    write_image = save_image

    def get_image_buffer_as_numpy(self):
        """The current frame as float32 RGBA of shape (W, H, 4)."""
        rgba = np.ones(self.res + (4,), np.float32)
        rgba[..., :3] = self._image.img
        return rgba

    def get_depth_buffer_as_numpy(self):
        """The depth of the last 3-D scene drawn on the canvas as float32 (W, H), Taichi's convention: reversed Z
        in [0, 1] (1 at the camera's near plane, 0 at its far plane and where the scene drew nothing); zeros
        before any scene was drawn."""
        from . import render3d

        canvas = self._canvas
        if canvas._depth is None or canvas._depth_cam is None:
            return np.zeros(self.res, np.float32)
        return render3d.depth_buffer(canvas._depth, canvas._depth_cam)

    def get_depth_buffer(self, depth):
        """Copy :meth:`get_depth_buffer_as_numpy` into ``depth``, a 2-D f32 field or ndarray of the window's
        shape."""
        shape = tuple(getattr(depth, "shape", ()))
        if len(shape) != 2 or getattr(depth, "dtype", None) != ti.f32:
            raise TypeError(f"get_depth_buffer needs a 2-D ti.f32 field or ndarray, got shape {shape}")
        if shape != self.res:
            raise ValueError(f"get_depth_buffer: depth has shape {shape}, the window is {self.res}")
        depth.from_numpy(self.get_depth_buffer_as_numpy())

    def _take_events(self, tag, limit=None):
        """Pop waiting key/mouse events of type ``tag`` (all types if None), keeping the others."""
        if self._window is None:
            return []
        self._window.poll()
        taken, kept = [], []
        while self._window.events:
            kind, key, pos, delta = item = self._window.events.popleft()
            if kind == _tk.MOTION:
                continue
            if (tag is None or tag == kind) and (limit is None or len(taken) < limit):
                taken.append(_Event(kind, key))
            else:
                kept.append(item)
        self._window.events.extend(kept)
        return taken

    def get_events(self, tag=None):
        """The list of waiting key/mouse events (optionally only PRESS or RELEASE); empty headless."""
        return self._take_events(tag)

    def get_event(self, tag=None):
        """Whether an event (matching ``tag``) is waiting; it becomes ``window.event``."""
        events = self._take_events(tag, limit=1)
        if events:
            self.event = events[0]
        return bool(events)

    def is_pressed(self, *keys):
        """Whether any of ``keys`` is held; always False headless."""
        held = set() if self._window is None else self._window.pressed
        return any(k in held or k + "_L" in held or k + "_R" in held for k in keys)

    def get_cursor_pos(self):
        """Cursor position in [0, 1]^2 with y up; the centre when headless."""
        return (0.5, 0.5) if self._window is None else tuple(self._window.cursor)

    def make_video(self, gif=True, mp4=False):
        """Assemble the recorded frames into ``<frames_dir>/<name>.gif`` (and ``.mp4`` on request); the
        frame PNGs stay in ``<frames_dir>/frames``.  Returns the GIF's path, None when not recording."""
        if self._video is None or not self._video.frame_fns:
            return None
        self._video.make_video(gif=gif, mp4=mp4)
        return self._video.get_output_filename(".gif")

    def destroy(self):
        if self._window is not None:
            self._window.close()
            self._window = None
        self._running = False
        self.make_video()
        if self._video is not None:
            atexit.unregister(self.make_video)
            self._video = None


class _Event:
    def __init__(self, kind, key):
        self.type = kind
        self.key = key

    def __repr__(self):
        return f"Event(type={self.type!r}, key={self.key!r})"
