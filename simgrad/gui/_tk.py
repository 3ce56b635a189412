"""Optional on-screen window for the GUI, built on tkinter.

Everything draws into a numpy canvas; this module only shows that canvas and turns Tk input into
Taichi-style events.  It is best-effort: when there is no display, tkinter is missing, or Tk fails
to start, :func:`open_window` returns ``None`` and the caller stays headless.
"""

from __future__ import annotations

import collections
import os
import sys

import numpy as np

PRESS = "Press"
RELEASE = "Release"
MOTION = "Move"

_KEY_NAMES = {"space": " ", "ISO_Left_Tab": "Tab"}
_BUTTONS = {1: "LMB", 2: "MMB", 3: "RMB"}


def display_available() -> bool:
    """True when a window could be shown (an X11/Wayland display, or a non-X11 desktop OS)."""
    if sys.platform in ("win32", "darwin"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def open_window(name, res):
    """A :class:`TkWindow`, or ``None`` when no window can be opened."""
    if not display_available():
        return None
    try:
        return TkWindow(name, res)
    except Exception:  # no tkinter, no Tk, display refused: stay headless
        return None


class TkWindow:
    """A Tk window showing an RGB frame and queueing (type, key, pos, delta) events."""

    def __init__(self, name, res):
        import tkinter

        self.res = (int(res[0]), int(res[1]))
        self.root = tkinter.Tk()
        self.root.title(str(name))
        self.root.resizable(False, False)
        self.label = tkinter.Label(self.root, borderwidth=0, highlightthickness=0)
        self.label.pack()
        self.photo = None
        self.events = collections.deque()
        self.pressed = set()
        self.cursor = (0.5, 0.5)
        self.closed = False
        self.root.protocol("WM_DELETE_WINDOW", self._on_close)
        self.root.bind("<KeyPress>", lambda e: self._key(PRESS, e))
        self.root.bind("<KeyRelease>", lambda e: self._key(RELEASE, e))
        self.label.bind("<ButtonPress>", lambda e: self._button(PRESS, e))
        self.label.bind("<ButtonRelease>", lambda e: self._button(RELEASE, e))
        self.label.bind("<Motion>", self._motion)
        self.label.bind("<MouseWheel>", lambda e: self._push(PRESS, "Wheel", e, (0, e.delta)))

    def _pos(self, e):
        return (e.x / max(1, self.res[0]), 1.0 - e.y / max(1, self.res[1]))

    def _record(self, kind, key, delta=(0, 0)):
        if kind == PRESS and key != "Wheel":
            self.pressed.add(key)
        elif kind == RELEASE:
            self.pressed.discard(key)
        self.events.append((kind, key, self.cursor, delta))

    def _push(self, kind, key, e, delta=(0, 0)):
        self.cursor = self._pos(e)
        self._record(kind, key, delta)

    def _key(self, kind, e):
        key = _KEY_NAMES.get(e.keysym, e.keysym)
        self._record(kind, key.lower() if len(key) == 1 else key)

    def _button(self, kind, e):
        if e.num in (4, 5):  # X11 reports the wheel as buttons 4 and 5
            if kind == PRESS:
                self._push(PRESS, "Wheel", e, (0, 120 if e.num == 4 else -120))
            return
        self._push(kind, _BUTTONS.get(e.num, f"Button{e.num}"), e)

    def _motion(self, e):
        self._push(MOTION, "Motion", e)

    def _on_close(self):
        self.closed = True
        self.events.append((PRESS, "WMClose", self.cursor, (0, 0)))

    def update(self, rgb: np.ndarray):
        """Show a uint8 frame in Taichi's (W, H, 3) layout and process pending input."""
        import tkinter

        if self.closed:
            return
        rows = np.ascontiguousarray(rgb.transpose(1, 0, 2)[::-1])
        h, w = rows.shape[:2]
        self.photo = tkinter.PhotoImage(data=b"P6 %d %d 255\n" % (w, h) + rows.tobytes(), format="PPM")
        self.label.configure(image=self.photo)
        self.poll()

    def poll(self):
        """Let Tk deliver input events."""
        if not self.closed:
            try:
                self.root.update()
            except Exception:
                self.closed = True

    def close(self):
        if self.root is not None:
            try:
                self.root.destroy()
            except Exception:
                pass
            self.root = None
        self.closed = True
