"""Shared plumbing of the examples: command line, progress bar, loss plot, frames."""

from __future__ import annotations

import argparse
import os


def parse_args(description: str, iters: int, **extra):
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--iters", type=int, default=iters, help="optimisation iterations")
    p.add_argument("--out", default=None, help="output folder for frames and plots")
    for name, default in extra.items():
        p.add_argument(f"--{name.replace('_', '-')}", type=type(default), default=default)
    return p.parse_args()


def out_dir(path: str | None, name: str) -> str:
    path = path or os.path.join("out", name)
    os.makedirs(path, exist_ok=True)
    return path


def progress(n: int, desc: str):
    try:
        from tqdm import trange

        return trange(n, desc=desc)
    except ImportError:
        return range(n)


def plot_losses(losses, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(range(len(losses)), losses, marker="o", markersize=3)
    ax.set_xlabel("iteration")
    ax.set_ylabel("loss")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def text_mask(text: str, width: int, height: int | None = None, margin: float = 0.08, stroke: int = 0):
    """`text` drawn with Pillow's built-in font, as large as fits, white on black.

    Returns float32 values in [0, 1] of shape (width, height), indexed [x, y] with y going up (the
    layout of Taichi fields and ti.GUI images).
    """
    import numpy as np
    from PIL import Image, ImageDraw, ImageFont

    height = height or width
    box_w, box_h = width * (1 - 2 * margin), height * (1 - 2 * margin)
    img = Image.new("L", (width, height), 0)
    draw = ImageDraw.Draw(img)
    size = max(4, height)
    while True:
        font = ImageFont.load_default(size=size)
        left, top, right, bottom = draw.multiline_textbbox((0, 0), text, font=font, align="center",
                                                           stroke_width=stroke)
        if (right - left <= box_w and bottom - top <= box_h) or size <= 4:
            break
        size -= 1
    draw.multiline_text((width / 2, height / 2), text, font=font, fill=255, anchor="mm", align="center",
                        stroke_width=stroke, stroke_fill=255)
    rows = np.asarray(img, dtype=np.float32) / 255.0
    return np.ascontiguousarray(rows[::-1].T)


def actuation_colors(act, active, passive=0x404040):
    """0xRRGGBB per particle: actuated ones red when extending (act < 0), blue when contracting (act > 0)."""
    import numpy as np

    a = np.clip(np.asarray(act, dtype=np.float64), -1.0, 1.0)
    r = np.clip(0.5 - 0.5 * a, 0, 1)
    g = np.clip(0.5 - 0.5 * np.abs(a), 0, 1)
    b = np.clip(0.5 + 0.5 * a, 0, 1)
    rgb = ((r * 255).astype(np.uint32) << 16) | ((g * 255).astype(np.uint32) << 8) | (b * 255).astype(np.uint32)
    return np.where(np.asarray(active), rgb, np.uint32(passive)).astype(np.uint32)


def write_gif(ti, images, out: str, name: str, framerate: int = 20) -> str:
    """Assemble frames ((W, H, 3) floats in [0, 1]) into out/<name>.gif through ti.tools.VideoManager, then
    delete the frame PNGs it wrote. Returns the GIF's path."""
    video = ti.tools.VideoManager(out, video_filename=name, framerate=framerate, automatic_build=False)
    for img in images:
        video.write_frame(img)
    video.make_video(gif=True, mp4=False)
    for fn in video.frame_fns:  # (not video.clean_frames(): Taichi's removes paths relative to the cwd)
        path = os.path.join(video.get_frame_directory(), fn)
        if os.path.exists(path):
            os.remove(path)
    try:
        os.rmdir(video.get_frame_directory())
    except OSError:  # not empty: frames of someone else
        pass
    return os.path.join(out, name + ".gif")


def plot_losses_smoothed(losses, path: str, title: str, window: int = 50) -> None:
    """Like plot_losses, for noisy losses: every value faintly, and their moving average over `window`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    losses = np.asarray(losses, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(range(len(losses)), losses, color="C0", alpha=0.25, linewidth=0.8, label="per iteration")
    w = max(1, min(window, len(losses)))
    avg = np.convolve(losses, np.ones(w) / w, mode="valid")
    ax.plot(range(w - 1, len(losses)), avg, color="C1", linewidth=2, label=f"mean of {w}")
    ax.set_xlabel("iteration")
    ax.set_ylabel("loss")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def finish_gif(video) -> None:
    """Build only the GIF of a ti.tools.VideoManager, then delete its frame PNGs and their empty folder."""
    video.make_video(gif=True, mp4=False)
    for fn in video.frame_fns:  # (not video.clean_frames(): Taichi's removes paths relative to the cwd)
        path = os.path.join(video.get_frame_directory(), fn)
        if os.path.exists(path):
            os.remove(path)
    try:
        os.rmdir(video.get_frame_directory())
    except OSError:
        pass
