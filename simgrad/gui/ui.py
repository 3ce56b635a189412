"""``ti.ui`` namespace: the GGUI-style window, canvas, 3D scene and camera, key/event constants (and, as
in Taichi, the older ``ti.GUI``)."""

from .colors import hex_to_rgb, rgb_to_hex
from .gui import GUI
from .scene import Camera, ProjectionMode, Scene, make_camera

from .window import (
    ALT,
    BACKSPACE,
    CAPSLOCK,
    CTRL,
    DOWN,
    ESCAPE,
    LEFT,
    LMB,
    MMB,
    PRESS,
    RELEASE,
    RETURN,
    RIGHT,
    RMB,
    SHIFT,
    SPACE,
    TAB,
    UP,
    Canvas,
    Gui,
    Window,
)

__all__ = [
    "Window",
    "Canvas",
    "Gui",
    "GUI",
    "Scene",
    "Camera",
    "ProjectionMode",
    "make_camera",
    "rgb_to_hex",
    "hex_to_rgb",
    "PRESS",
    "RELEASE",
    "SHIFT",
    "ALT",
    "CTRL",
    "ESCAPE",
    "RETURN",
    "TAB",
    "BACKSPACE",
    "SPACE",
    "UP",
    "DOWN",
    "LEFT",
    "RIGHT",
    "CAPSLOCK",
    "LMB",
    "MMB",
    "RMB",
]
