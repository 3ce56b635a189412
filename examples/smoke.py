"""Differentiable 2-D smoke (DiffTaichi's smoke experiment, written from the paper's description).

Ink is carried by an incompressible velocity field on a periodic 110 x 110 grid. Each of the 99 steps
advects the velocity by itself (semi-Lagrangian, bilinear), projects it to be divergence-free with 6
Jacobi iterations of the pressure Poisson equation (warm-started from the previous step's pressure), and
then advects the ink with the projected velocity. We optimise the *initial velocity field* by gradient
descent so that the ink at the last step matches a target picture, text drawn locally with Pillow.

Every intermediate state is kept (indexed by step, and by step and Jacobi iteration for the pressure), so
the whole simulation is one ti.ad.Tape and each kernel only reads what earlier kernels wrote.

Sizes: those of the original CPU program (110 x 110 cells, 100 states = 99 steps, 6 Jacobi iterations,
learning rate 100; the paper's GPU run used 128 x 128 cells and 10 iterations); its 150 optimisation
iterations are reduced to 100 by default (about 1 s each here), which already shows the text.

    python examples/smoke.py [--iters 100] [--out out/smoke]
"""

import contextlib
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress, text_mask  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def initial_ink(n: int) -> np.ndarray:
    """A checkerboard of ink blocks (about ten per side)."""
    block = max(1, n // 10)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return (((i // block) + (j // block)) % 2).astype(np.float32)


def build(n: int = 110, steps: int = 100, jacobi: int = 6):
    """Fields and kernels of one smoke simulation with `steps` states; returns a namespace of them."""
    v = ti.Vector.field(2, real, shape=(steps, n, n), needs_grad=True)  # projected velocity
    v_adv = ti.Vector.field(2, real, shape=(steps, n, n), needs_grad=True)  # advected, before projection
    div = ti.field(real, shape=(steps, n, n), needs_grad=True)
    # pressure iterates: step t, Jacobi iteration k writes p[t * jacobi + k + 1]; p[t * jacobi] is the
    # last iterate of step t - 1, so each step starts from the previous pressure
    p = ti.field(real, shape=(steps * jacobi + 1, n, n), needs_grad=True)
    ink = ti.field(real, shape=(steps, n, n), needs_grad=True)
    target = ti.field(real, shape=(n, n))
    loss = ti.field(real, shape=(), needs_grad=True)

    # Periodic indices are wrapped with comparisons rather than an integer `%`: at the time of writing,
    # simgrad's LLVM codegen could name two values alike in a kernel with several integer `%` (%m1<k> of
    # one and %m<1k> of another), which LLVM rejects.
    @ti.func
    def wrap(i):
        """An index in [-n, 2n) brought into [0, n)."""
        j = i
        if j < 0:
            j += n
        if j >= n:
            j -= n
        return j

    @ti.func
    def bilerp(f: ti.template(), t, x, y):
        """Sample f[t] at the continuous cell position (x, y), periodic in both axes."""
        x0 = ti.floor(x)
        y0 = ti.floor(y)
        fx = x - x0
        fy = y - y0
        i0 = wrap(ti.cast(x0 - n * ti.floor(x0 / n), ti.i32))
        j0 = wrap(ti.cast(y0 - n * ti.floor(y0 / n), ti.i32))
        i1 = wrap(i0 + 1)
        j1 = wrap(j0 + 1)
        return (1 - fx) * ((1 - fy) * f[t, i0, j0] + fy * f[t, i0, j1]) + fx * (
            (1 - fy) * f[t, i1, j0] + fy * f[t, i1, j1])

    @ti.kernel
    def advect_velocity(t: ti.i32):
        for i, j in ti.ndrange(n, n):
            vel = v[t - 1, i, j]
            v_adv[t, i, j] = bilerp(v, t - 1, i - vel[0], j - vel[1])

    @ti.kernel
    def divergence(t: ti.i32):
        for i, j in ti.ndrange(n, n):
            div[t, i, j] = 0.5 * (v_adv[t, wrap(i + 1), j][0] - v_adv[t, wrap(i - 1), j][0]
                                  + v_adv[t, i, wrap(j + 1)][1] - v_adv[t, i, wrap(j - 1)][1])

    @ti.kernel
    def jacobi_step(t: ti.i32, k: ti.i32):
        for i, j in ti.ndrange(n, n):
            a = t * jacobi + k
            around = p[a, wrap(i + 1), j] + p[a, wrap(i - 1), j] + p[a, i, wrap(j + 1)] + p[a, i, wrap(j - 1)]
            p[a + 1, i, j] = 0.25 * (around - div[t, i, j])

    @ti.kernel
    def project(t: ti.i32):
        for i, j in ti.ndrange(n, n):
            a = t * jacobi + jacobi
            grad_p = 0.5 * ti.Vector([p[a, wrap(i + 1), j] - p[a, wrap(i - 1), j],
                                      p[a, i, wrap(j + 1)] - p[a, i, wrap(j - 1)]])
            v[t, i, j] = v_adv[t, i, j] - grad_p

    @ti.kernel
    def advect_ink(t: ti.i32):
        for i, j in ti.ndrange(n, n):
            vel = v[t, i, j]
            ink[t, i, j] = bilerp(ink, t - 1, i - vel[0], j - vel[1])

    @ti.kernel
    def compute_loss():
        for i, j in ti.ndrange(n, n):
            loss[None] += (ink[steps - 1, i, j] - target[i, j]) ** 2 * (1.0 / (n * n))

    @ti.kernel
    def descend(lr: real):
        for i, j in ti.ndrange(n, n):
            v[0, i, j] -= lr * v.grad[0, i, j]

    def forward():
        for t in range(1, steps):
            advect_velocity(t)
            divergence(t)
            for k in range(jacobi):
                jacobi_step(t, k)
            project(t)
            advect_ink(t)
        compute_loss()

    def setup(target_image: np.ndarray):
        ink0 = np.zeros((steps, n, n), np.float32)
        ink0[0] = initial_ink(n)
        ink.from_numpy(ink0)
        target.from_numpy(target_image.astype(np.float32))
        v.fill(0)

    return type("Smoke", (), dict(locals()))


def train(iters: int, out: str | None, n: int = 110, steps: int = 100, jacobi: int = 6, lr: float = 100.0,
          text: str = "Diff\nTaichi", frames: bool = True):
    """Optimise the initial velocity; returns (losses, seconds per iteration)."""
    sim = build(n, steps, jacobi)
    sim.setup(text_mask(text, n, stroke=max(1, n // 55)))
    losses = []
    t0 = time.time()
    snapshots = {}
    for it in progress(iters, "smoke"):
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        if it in (0, iters // 2):
            snapshots[it] = sim.ink.to_numpy()[steps - 1]
        sim.descend(lr)
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        os.makedirs(out, exist_ok=True)
        save_pictures(sim, out, losses, snapshots, frames)
    return losses, seconds


def save_pictures(sim, out, losses, snapshots, frames=True):
    plot_losses(losses, os.path.join(out, "loss.png"), "smoke: ink vs target (mean squared)")
    sim.forward()  # the simulation with the optimised initial velocity
    ink = sim.ink.to_numpy()
    ti.tools.imwrite(sim.target.to_numpy(), os.path.join(out, "target.png"))
    ti.tools.imwrite(ink[0], os.path.join(out, "ink_initial.png"))
    for it, img in snapshots.items():
        ti.tools.imwrite(np.clip(img, 0, 1), os.path.join(out, f"ink_final_iter{it:04d}.png"))
    ti.tools.imwrite(np.clip(ink[-1], 0, 1), os.path.join(out, f"ink_final_iter{len(losses):04d}.png"))
    speed = np.linalg.norm(sim.v.to_numpy()[0], axis=-1)
    ti.tools.imwrite(speed / max(float(speed.max()), 1e-6), os.path.join(out, "initial_speed.png"))
    if frames:
        video = ti.tools.VideoManager(out, video_filename="smoke", framerate=12, automatic_build=False)
        scale = max(1, 256 // sim.n)
        for t in range(0, sim.steps, max(1, sim.steps // 25)):
            img = np.clip(ink[t], 0, 1)
            video.write_frame(np.kron(img, np.ones((scale, scale), np.float32)))
        video.write_frame(np.kron(np.clip(ink[-1], 0, 1), np.ones((scale, scale), np.float32)))
        video.make_video(mp4=False)
        video.clean_frames()  # keep the GIF, not its frame PNGs
        with contextlib.suppress(OSError):  # not empty: other files are there
            os.rmdir(video.get_frame_directory())


def main():
    args = parse_args("Optimise the initial velocity of 2-D smoke so the ink forms a picture", iters=100,
                      n=110, steps=100)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "smoke")
    losses, sec = train(args.iters, out, n=args.n, steps=args.steps)
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
