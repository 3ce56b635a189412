"""Taichi-compatible GUI and image tools: ``ti.GUI``, ``ti.ui``, ``ti.tools.imwrite`` and friends.

Everything renders into a numpy canvas (``ti.ui``'s 2-D primitives and 3-D scenes by simgrad kernels,
render2d.py and render3d.py), so it works headless (servers, CI) and needs only numpy, Pillow and imageio;
a tkinter window is opened only when a display is available.
"""

from . import tools, ui
from .canvas import ImageCanvas
from .colors import hex_to_rgb, rgb_to_hex
from .gui import GUI
from .image import VideoManager, imread, imresize, imshow, imwrite
from .ply import PLYWriter
from .scene import Camera, Scene
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
    "imshow",
    "PLYWriter",
    "tools",
    "ui",
    "Scene",
    "Camera",
    "Window",
    "Canvas",
]
