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
