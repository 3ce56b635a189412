"""Taichi-compatible GUI and image tools: ``ti.GUI``, ``ti.ui``, ``ti.tools.imwrite`` and friends.

Everything renders into a numpy canvas, so it works headless (servers, CI) and needs only numpy,
Pillow and imageio; a tkinter window is opened only when a display is available.
"""

from . import ui
from .canvas import ImageCanvas
from .colors import hex_to_rgb, rgb_to_hex
from .gui import GUI
from .image import VideoManager, imread, imresize, imwrite
from .ui import Canvas, Window

__all__ = [
    "GUI",
    "ImageCanvas",
    "rgb_to_hex",
    "hex_to_rgb",
    "imwrite",
    "imread",
    "imresize",
    "VideoManager",
    "ui",
    "Window",
    "Canvas",
]
