"""Image files and videos in Taichi's layout (``ti.tools.imwrite/imread/imresize/VideoManager``).

Taichi images are indexed ``img[x, y]`` with y going up, while image files store rows top to bottom;
these helpers do that conversion so arrays written here come back unchanged, and so simulation
frames can be collected into a GIF (and an MP4 when imageio's ffmpeg plugin is installed).
"""

from __future__ import annotations

import importlib.util
import os
import warnings

import numpy as np

from .canvas import to_numpy

__all__ = ["imwrite", "imread", "imresize", "imshow", "VideoManager"]

_MODES = {1: "L", 2: "LA", 3: "RGB", 4: "RGBA"}


def _to_uint8(img) -> np.ndarray:
    arr = to_numpy(img)
    if arr.dtype.kind == "f":
        return (np.clip(np.nan_to_num(arr), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    if arr.dtype == np.uint8:
        return arr
    if arr.dtype in (np.uint16, np.uint32, np.uint64):  # scaled to [0, 255] by their bound, as Taichi's imwrite
        return (arr // (np.iinfo(arr.dtype).max // 256)).astype(np.uint8)
    if arr.dtype.kind in "ui":
        return np.clip(arr, 0, 255).astype(np.uint8)
    raise ValueError(f"Data type {arr.dtype} not supported in imwrite")


def imwrite(img, filename):
    """Save an image in (W, H[, C]) layout, C in {1, 3, 4}; floats are taken as [0, 1]."""
    from PIL import Image

    arr = _to_uint8(img)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 3, 4):
        raise ValueError(f"Image must be either RGB/RGBA or greyscale, got shape {arr.shape}")
    rows = np.ascontiguousarray(arr.swapaxes(0, 1)[::-1])
    if rows.shape[2] == 1:
        rows = rows[..., 0]
    ext = os.path.splitext(str(filename))[1].lower()
    fmt = None if ext in Image.registered_extensions() else "PNG"
    Image.fromarray(rows, _MODES[arr.shape[2]]).save(filename, format=fmt)


def imread(filename, channels=0):
    """Load an image as uint8 of shape (W, H, C); ``channels`` 0 keeps the file's channel count."""
    from PIL import Image

    with Image.open(filename) as im:
        if channels:
            if channels not in _MODES:
                raise ValueError(f"channels must be 0, 1, 2, 3 or 4, got {channels}")
            im = im.convert(_MODES[channels])
        elif im.mode not in _MODES.values():
            im = im.convert("RGBA" if "transparency" in im.info or im.mode.endswith("A") else "RGB")
        rows = np.asarray(im)
    if rows.ndim == 2:
        rows = rows[..., None]
    return np.ascontiguousarray(rows[::-1].swapaxes(0, 1))


def imresize(img, w, h=None):
    """Nearest-neighbour resize of a (W, H[, C]) image to (w, h) (``h`` defaults to ``w``)."""
    arr = to_numpy(img)
    h = w if h is None else h
    if (w, h) == arr.shape[:2]:
        return arr
    x = np.minimum((np.arange(w) * (arr.shape[0] / w)).astype(np.int64), arr.shape[0] - 1)
    y = np.minimum((np.arange(h) * (arr.shape[1] / h)).astype(np.int64), arr.shape[1] - 1)
    return arr[x[:, None], y[None, :]]


def imshow(img, title="imshow"):
    """Show an image (W, H[, C]) in a window until it is closed or Escape is pressed.  Without a display
    there is nothing to show and it returns at once (Taichi's would wait forever for a closed window)."""
    from .gui import GUI

    arr = to_numpy(img)
    if arr.ndim not in (2, 3):
        raise ValueError(f"Image must be either RGB/RGBA or greyscale of shape (W, H[, C]), got {arr.shape}")
    gui = GUI(title, res=arr.shape[:2])
    try:
        if not gui.show_gui:
            return
        gui.set_image(arr)
        while gui.running:
            if gui.get_event(GUI.ESCAPE):
                break
            gui.set_image(arr)
            gui.show()
    finally:
        gui.close()


class VideoManager:
    """Collect frames as PNGs in ``output_dir/frames`` and assemble them into a GIF / MP4.

    With ``automatic_build`` the video is rebuilt after 4, 8, 16, ... frames, as in Taichi.
    ``post_processor`` (an object with ``process(img)``) is applied to each frame.
    """

    def __init__(
        self,
        output_dir,
        video_filename="video",
        width=None,
        height=None,
        post_processor=None,
        framerate=24,
        automatic_build=True,
    ):
        self.output_dir = self.directory = str(output_dir)
        self.video_filename = video_filename or "video"
        self.width = width
        self.height = height
        self.post_processor = post_processor
        self.framerate = framerate
        self.automatic_build = automatic_build
        self.frame_directory = os.path.join(self.directory, "frames")
        os.makedirs(self.frame_directory, exist_ok=True)
        self.frame_counter = 0
        self.frame_fns = []
        self.next_video_checkpoint = 4

    def get_frame_directory(self):
        return self.frame_directory

    def get_output_filename(self, suffix):
        """``output_dir/<video_filename without extension><suffix>``."""
        return os.path.join(self.directory, os.path.splitext(self.video_filename)[0] + suffix)

    def write_frame(self, img):
        """Save one frame ((W, H[, C]) floats in [0, 1] or uint8, or a field)."""
        img = to_numpy(img)
        if self.post_processor is not None:
            img = self.post_processor.process(img)
        if self.width is None:
            self.width, self.height = img.shape[0], img.shape[1]
        fn = f"{self.frame_counter:06d}.png"
        imwrite(img, os.path.join(self.frame_directory, fn))
        self.frame_fns.append(fn)
        self.frame_counter += 1
        if self.automatic_build and self.frame_counter % self.next_video_checkpoint == 0:
            self.make_video()
            self.next_video_checkpoint *= 2

    def write_frames(self, images):
        for img in images:
            self.write_frame(img)

    def clean_frames(self):
        """Delete the frame PNGs written by this manager."""
        for fn in self.frame_fns:
            path = os.path.join(self.frame_directory, fn)
            if os.path.exists(path):
                os.remove(path)
        self.frame_fns = []

    def _frames(self):
        frames = []
        for fn in self.frame_fns:
            frame = imread(os.path.join(self.frame_directory, fn), channels=3)
            if self.width is not None and frame.shape[:2] != (self.width, self.height):
                frame = imresize(frame, self.width, self.height)
            frames.append(np.ascontiguousarray(frame.swapaxes(0, 1)[::-1]))
        return frames

    def make_video(self, mp4=True, gif=True):
        """Write ``<name>.gif`` and, when imageio's ffmpeg plugin is installed, ``<name>.mp4``.

        Note that GIF encoding merges consecutive identical frames into one longer frame.
        """
        import imageio.v2 as imageio
        import imageio.v3 as iio

        frames = self._frames()
        if not frames:
            return
        if gif:  # the pillow plugin takes the frame duration in milliseconds
            iio.imwrite(
                self.get_output_filename(".gif"),
                np.stack(frames),
                extension=".gif",
                plugin="pillow",
                duration=1000.0 / self.framerate,
                loop=0,
            )
        if mp4:
            if importlib.util.find_spec("imageio_ffmpeg") is None:
                warnings.warn("imageio-ffmpeg is not installed; skipping the MP4 video", stacklevel=2)
                return
            try:
                imageio.mimsave(
                    self.get_output_filename(".mp4"),
                    frames,
                    format="FFMPEG",
                    fps=self.framerate,
                    macro_block_size=1,
                )
            except Exception as exc:  # codec or plugin trouble must not lose the GIF/frames
                warnings.warn(f"could not write the MP4 video: {exc}", stacklevel=2)
