"""Differentiable volume rendering (DiffTaichi's volume_renderer experiment, written from the paper).

A density field on a D^3 grid fills the unit box [-0.5, 0.5]^3. A pinhole camera circles the box at
distance 1 (a 90-degree field of view); for each pixel we march the ray through the box with a fixed
number of samples, trilinearly interpolating the density, and the pixel is the opacity 1 - exp(-tau) of
the absorbing medium (tau the optical depth along the ray). Target images of a reference density (a
procedural shape: a tilted torus with a ball on top and a small ball beside it, built locally) are
rendered from `n_views` directions over half a turn. Starting from an empty volume we optimise the
density by projected gradient descent (density >= 0) on the L2 distance between the renderings and the
targets.

Each view's optical depths are accumulated into a field (`tau[view, x, y] += ...` inside the march), so
no value lives across iterations of the inner loop; a second kernel turns them into opacity and loss.

Sizes: the paper renders 7 views of 512^2 pixels from a 128^3 density with 1000 march steps per ray.
On this 2-core CPU we use 7 views of 128^2 pixels, a 64^3 density and 96 samples per ray (only the part
of the ray inside the box is marched, so 96 samples are about 1.5 samples per cell): about 2 s per
iteration (the paper's size would be ~200x the work); the paper's 100 iterations are kept.

    python examples/volume_renderer.py [--iters 100] [--out out/volume_renderer]
"""

import contextlib
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def reference_density(d: int, peak: float = 12.0) -> np.ndarray:
    """The shape to recover, as a (d, d, d) array indexed [x, y, z], cell centres in [-0.5, 0.5]."""
    c = (np.arange(d) + 0.5) / d - 0.5
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    # a torus around a tilted axis
    tilt = 0.5
    yr = y * math.cos(tilt) - x * math.sin(tilt)
    xr = y * math.sin(tilt) + x * math.cos(tilt)
    ring = np.sqrt((np.sqrt(xr ** 2 + z ** 2) - 0.26) ** 2 + (yr + 0.05) ** 2) - 0.07
    ball = np.sqrt(x ** 2 + (y - 0.2) ** 2 + z ** 2) - 0.13
    small = np.sqrt((x + 0.05) ** 2 + (y + 0.1) ** 2 + (z - 0.3) ** 2) - 0.08
    dist = np.minimum(np.minimum(ring, ball), small)
    soft = 1.5 / d  # a smooth edge about a cell and a half wide
    return (peak * np.clip(0.5 - dist / soft, 0.0, 1.0)).astype(np.float32)


def build(res: int = 128, d: int = 64, n_views: int = 7, samples: int = 96):
    """Fields and kernels of the renderer; returns a namespace of them."""
    density = ti.field(real, shape=(d, d, d), needs_grad=True)
    tau = ti.field(real, shape=(n_views, res, res), needs_grad=True)  # optical depth per pixel
    image = ti.field(real, shape=(n_views, res, res), needs_grad=True)  # opacity per pixel
    target = ti.field(real, shape=(n_views, res, res))
    loss = ti.field(real, shape=(), needs_grad=True)
    angles = [math.pi * v / n_views for v in range(n_views)]
    cam_dist, half_fov = 1.5, 0.38 # camera distance from the centre, tan of half the field of view

    @ti.func
    def sample(p):
        """Trilinear interpolation of the density at a point p of the unit box."""
        g = (p + 0.5) * d - 0.5
        g = ti.min(ti.max(g, 0.0), d - 1.001)
        i = ti.cast(ti.floor(g), ti.i32)
        f = g - i
        value = 0.0
        for a, b, c in ti.static(ti.ndrange(2, 2, 2)):
            # weight f along an axis where the corner is the upper one (a = 1), 1 - f where it is the lower
            w = ((1 - a) + (2 * a - 1) * f[0]) * ((1 - b) + (2 * b - 1) * f[1]) * ((1 - c) + (2 * c - 1) * f[2])
            value += w * density[i[0] + a, i[1] + b, i[2] + c]
        return value

    @ti.kernel
    def march(view: ti.i32, angle: real):
        for px, py in ti.ndrange(res, res):
            ca, sa = ti.cos(angle), ti.sin(angle)
            origin = ti.Vector([cam_dist * sa, 0.0, cam_dist * ca])
            # camera looks at the origin along -z before the rotation about the y axis
            u = ((px + 0.5) / res * 2 - 1) * half_fov
            v = ((py + 0.5) / res * 2 - 1) * half_fov
            local = ti.Vector([u, v, -1.0]).normalized()
            direction = ti.Vector([local[0] * ca + local[2] * sa, local[1], -local[0] * sa + local[2] * ca])
            # slab test against the box [-0.5, 0.5]^3
            t_near, t_far = 0.0, 10.0
            for k in ti.static(range(3)):
                inv = 1.0 / direction[k]
                t0 = (-0.5 - origin[k]) * inv
                t1 = (0.5 - origin[k]) * inv
                t_near = ti.max(t_near, ti.min(t0, t1))
                t_far = ti.min(t_far, ti.max(t0, t1))
            if t_near < t_far:
                ds = (t_far - t_near) / samples
                for s in range(samples):
                    p = origin + (t_near + (s + 0.5) * ds) * direction
                    tau[view, px, py] += sample(p) * ds

    @ti.kernel
    def shade_and_loss():
        for view, px, py in image:
            image[view, px, py] = 1 - ti.exp(-tau[view, px, py])
            loss[None] += (image[view, px, py] - target[view, px, py]) ** 2 * (1.0 / (res * res))

    @ti.kernel
    def descend(lr: real):
        for i, j, k in density:
            density[i, j, k] = ti.max(density[i, j, k] - lr * density.grad[i, j, k], 0.0)

    def render():
        """Optical depths, opacities and the loss; `tau` must be zero before (it is filled outside a Tape:
        Taichi records field.fill on a Tape and cannot differentiate its kernel)."""
        for view in range(n_views):
            march(view, angles[view])
        shade_and_loss()

    def make_targets():
        density.from_numpy(reference_density(d))
        tau.fill(0)
        render()
        target.from_numpy(image.to_numpy())
        density.fill(0)

    return type("VolumeRenderer", (), dict(locals()))


def train(iters: int, out: str | None, res: int = 128, d: int = 64, n_views: int = 7, samples: int = 96,
          lr: float | None = None):
    """Recover the density from the target views; returns (losses, seconds per iteration).

    The default learning rate keeps the step the same in relative terms across sizes: the gradient of a
    cell scales like 1 / (d * res^2) (the loss is a per-pixel mean) and with the number of views.
    """
    if lr is None:
        lr = 8e4 * (d / 64) * (res / 128) ** 2 * (7 / n_views)
    vr = build(res, d, n_views, samples)
    vr.make_targets()
    losses = []
    snapshots = {}
    t0 = time.time()
    for it in progress(iters, "volume_renderer"):
        vr.tau.fill(0)
        with ti.ad.Tape(loss=vr.loss):
            vr.render()
        losses.append(float(vr.loss[None]))
        if out is not None and it in (1, iters // 2):
            snapshots[it] = vr.image.to_numpy()
        vr.descend(lr)
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        os.makedirs(out, exist_ok=True)
        save_pictures(vr, out, losses, snapshots)
    return losses, seconds


def save_pictures(vr, out, losses, snapshots):
    plot_losses(losses, os.path.join(out, "loss.png"), "volume_renderer: L2 image loss over views")
    vr.tau.fill(0)
    vr.render()
    snapshots[len(losses)] = vr.image.to_numpy()
    targets = vr.target.to_numpy()
    # one picture per iteration shown: all views in a row (dark medium on white), the targets above them
    for it, views in snapshots.items():
        rows = np.concatenate([np.concatenate(list(1 - views), axis=0), np.concatenate(list(1 - targets), axis=0)],
                              axis=1)
        ti.tools.imwrite(np.clip(rows, 0, 1), os.path.join(out, f"views_iter{it:04d}.png"))
    # the optimised and the reference density, summed along z
    ref = reference_density(vr.d).sum(axis=2)
    mine = vr.density.to_numpy().sum(axis=2)
    both = np.concatenate([mine, ref], axis=0) / max(float(ref.max()), 1e-6)
    scale = max(1, 256 // vr.d)
    ti.tools.imwrite(np.clip(1 - np.kron(both, np.ones((scale, scale))), 0, 1),
                     os.path.join(out, "density_projection.png"))
    video = ti.tools.VideoManager(out, video_filename="volume_renderer", framerate=4, automatic_build=False)
    for it in sorted(snapshots):
        mid = snapshots[it][vr.n_views // 2]
        video.write_frame(np.concatenate([1 - targets[vr.n_views // 2], 1 - np.clip(mid, 0, 1)], axis=0))
    video.make_video(mp4=False)
    video.clean_frames()  # keep the GIF, not its frame PNGs
    with contextlib.suppress(OSError):  # not empty: other files are there
        os.rmdir(video.get_frame_directory())


def main():
    args = parse_args("Recover a density volume from rendered views by differentiable ray marching", iters=100,
                      res=128, d=64, samples=96)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "volume_renderer")
    losses, sec = train(args.iters, out, res=args.res, d=args.d, samples=args.samples)
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
