"""``ti.tools``: image files, videos and PLY export, Taichi's utility namespace."""

from .image import VideoManager, imread, imresize, imshow, imwrite
from .ply import PLYWriter

__all__ = ["PLYWriter", "VideoManager", "imread", "imresize", "imshow", "imwrite"]
