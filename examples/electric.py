"""A charged ball steered by electrodes (DiffTaichi's "electric" experiment, written from the paper).

Eight electrodes sit around the border of the unit square. A closed-loop neural network controller (8
inputs: the ball's position and velocity, the goal's position and velocity; one tanh hidden layer of 64
units; 8 tanh outputs) sets every electrode's charge in [-1, 1] at every time step; an electrode pushes
the ball with the Coulomb force K q r / |r|^3 (|r| clamped at 0.1), the ball's velocity decays
exponentially. The goal (blue dot) moves along a random polyline of `steps // seg_size` straight segments;
the loss is the time integral of the squared distance between ball and goal, and the controller's weights
are trained through the whole episode with `ti.ad.Tape` and plain gradient descent.

Sizes are the paper's: 512 steps of dt = 0.03 (two segments of 256 steps), K = 1e-3, damping 0.2, 64 hidden
units, learning rate 2e-2, and a fresh random path every iteration (`--tasks N` cycles through N fixed
paths instead). The loss then varies with the path, so the loss plot shows a moving average, and the
controller is also measured on 8 held-out paths before and after training. The paper trains for 200000
iterations; the default here is 2000 (0.04-0.06 s each), after which the mean loss on the held-out paths is
about 4x lower than before training (the ball follows new paths roughly; it keeps improving with more
iterations). `--tasks 1` (one fixed path) shows the optimisation itself: 1.44 -> 0.11 in 200 iterations.

    python examples/electric.py [--iters 2000] [--tasks 0] [--out out/electric]
"""

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import finish_gif, out_dir, parse_args, plot_losses, plot_losses_smoothed, progress  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32

PAD = 0.1
ELECTRODES = [(PAD, PAD), (PAD, 1 - PAD), (1 - PAD, 1 - PAD), (1 - PAD, PAD), (0.5, 1 - PAD), (0.5, PAD),
              (PAD, 0.5), (1 - PAD, 0.5)]


def build(steps: int = 512, seg_size: int = 256, n_hidden: int = 64, dt: float = 0.03):
    n_el = len(ELECTRODES)
    n_in = 8
    damping = 0.2
    decay = math.exp(-dt * damping)  # velocity decay per step
    K = 1e-3

    x = ti.Vector.field(2, real, shape=steps, needs_grad=True)
    v = ti.Vector.field(2, real, shape=steps, needs_grad=True)
    goal = ti.Vector.field(2, real, shape=steps)
    goal_v = ti.Vector.field(2, real, shape=steps)
    hidden = ti.field(real, shape=(steps, n_hidden), needs_grad=True)
    charge = ti.field(real, shape=(steps, n_el), needs_grad=True)
    weight1 = ti.field(real, shape=(n_in, n_hidden), needs_grad=True)
    bias1 = ti.field(real, shape=n_hidden, needs_grad=True)
    weight2 = ti.field(real, shape=(n_hidden, n_el), needs_grad=True)
    bias2 = ti.field(real, shape=n_el, needs_grad=True)
    loss = ti.field(real, shape=(), needs_grad=True)
    params = (weight1, bias1, weight2, bias2)

    @ti.kernel
    def nn1(t: ti.i32):
        for i in range(n_hidden):
            # the state at the end of step t-1 and the goal at step t, centred on the middle of the box
            s = bias1[i]
            s += (x[t - 1][0] - 0.5) * weight1[0, i] + (x[t - 1][1] - 0.5) * weight1[1, i]
            s += v[t - 1][0] * weight1[2, i] + v[t - 1][1] * weight1[3, i]
            s += (goal[t][0] - 0.5) * weight1[4, i] + (goal[t][1] - 0.5) * weight1[5, i]
            s += goal_v[t][0] * weight1[6, i] + goal_v[t][1] * weight1[7, i]
            hidden[t, i] = ti.tanh(s)

    @ti.kernel
    def nn2(t: ti.i32):
        for e in range(n_el):
            s = bias2[e]
            for j in ti.static(range(n_hidden)):
                s += hidden[t, j] * weight2[j, e]
            charge[t, e] = ti.tanh(s)

    @ti.kernel
    def advance(t: ti.i32):
        for _ in range(1):  # one ball: a single-iteration loop keeps the kernel one parallel task
            force = ti.Vector([0.0, 0.0])
            for e in ti.static(range(n_el)):
                r = x[t - 1] - ti.Vector(ELECTRODES[e])
                dist = ti.max(r.norm(), 0.1)
                force += (K * charge[t, e] / (dist * dist * dist)) * r
            v[t] = decay * v[t - 1] + dt * force
            x[t] = x[t - 1] + dt * v[t]

    @ti.kernel
    def compute_loss(t: ti.i32):
        for _ in range(1):
            d = x[t] - goal[t]
            loss[None] += dt * (d[0] * d[0] + d[1] * d[1])

    def set_task(points):
        """The goal runs along the polyline `points` (n_segments + 1 points), seg_size steps a segment."""
        points = np.asarray(points, dtype=np.float64)
        t = np.arange(steps)
        k = np.minimum(t // seg_size, len(points) - 2)  # the segment of each step
        frac = ((t - k * seg_size) / seg_size)[:, None]
        g = (1 - frac) * points[k] + frac * points[k + 1]
        gv = points[k + 1] - points[k]
        goal.from_numpy(g.astype(np.float32))
        goal_v.from_numpy(gv.astype(np.float32))
        xs = np.zeros((steps, 2), dtype=np.float32)
        xs[0] = points[0]
        x.from_numpy(xs)
        v.fill(0)

    def random_task(rng):
        return 0.2 + 0.6 * rng.rand(max(steps // seg_size, 1) + 1, 2)

    def init_weights(seed: int = 0):
        rng = np.random.RandomState(seed)
        weight1.from_numpy(((rng.rand(n_in, n_hidden) - 0.5) * 0.3).astype(np.float32))
        weight2.from_numpy(((rng.rand(n_hidden, n_el) - 0.5) * 0.3).astype(np.float32))
        bias1.fill(0)
        bias2.fill(0)

    def forward():
        for t in range(1, steps):
            nn1(t)
            nn2(t)
            advance(t)
            compute_loss(t)

    def sgd(lr: float):
        for p in params:
            p.from_numpy((p.to_numpy() - lr * p.grad.to_numpy()).astype(np.float32))

    return type("Sim", (), dict(locals()))


def draw(sim, out: str, name: str, every: int = 8, pngs: int = 4):
    xs, goals, q = sim.x.to_numpy(), sim.goal.to_numpy(), sim.charge.to_numpy()
    n = sim.steps
    gui = ti.GUI("electric", res=512, background_color=0x3C733F, show_gui=False)
    video = ti.tools.VideoManager(out, video_filename=name, framerate=20, automatic_build=False)
    stills = set(np.linspace(1, n - 1, pngs).astype(int) // every * every)
    for t in range(every, n, every):
        path = goals[::4]
        gui.lines(path[:-1], path[1:], radius=1, color=0x7788DD)  # the goal's path
        gui.lines(xs[: t - 1], xs[1:t], radius=1.5, color=0xF28090)  # the ball's trail
        gui.circles(np.array(ELECTRODES), radius=(q[t] + 1) * 15 + 1, color=0xCCAA44)
        gui.circle(xs[t], radius=12, color=0xF20530)
        gui.circle(goals[t], radius=6, color=0x3344CC)
        gui.text(f"t = {t}", (0.02, 0.99), font_size=16, color=0xFFFFFF)
        video.write_frame(gui.get_image())
        gui.show(os.path.join(out, f"{name}_{t:04d}.png") if t in stills else None)
    finish_gif(video)


def evaluate(sim, paths) -> float:
    """Mean loss of the current controller over `paths` (no gradients)."""
    total = 0.0
    for pts in paths:
        sim.set_task(pts)
        sim.loss[None] = 0
        sim.forward()
        total += float(sim.loss[None])
    return total / len(paths)


def train(iters: int, out: str | None, steps: int = 512, seg_size: int = 256, n_hidden: int = 64, lr: float = 2e-2,
          tasks: int = 0, n_val: int = 8, seed: int = 0, frames: bool = True, frame_every: int = 8):
    """Train the controller; returns (losses, seconds per iteration).

    `tasks` = 0: a new random path every iteration (the paper's setting); n > 0: cycle through n fixed
    random paths. `n_val` held-out paths measure the controller before and after training
    (`train.val_before`, `train.val_after`).
    """
    sim = build(steps, seg_size, n_hidden)
    sim.init_weights(seed)
    rng = np.random.RandomState(seed + 1)
    pool = [sim.random_task(rng) for _ in range(tasks)]
    val_rng = np.random.RandomState(seed + 1000)
    val = [sim.random_task(val_rng) for _ in range(n_val)]
    train.val_before = evaluate(sim, val) if n_val else None
    show = pool[0] if tasks else (val[0] if val else sim.random_task(np.random.RandomState(seed + 2)))
    if out is not None and frames:  # the untrained controller, for comparison
        sim.set_task(show)
        sim.loss[None] = 0
        sim.forward()
        draw(sim, out, "initial", every=frame_every, pngs=2)
    losses = []
    t0 = time.time()
    for it in progress(iters, "electric"):
        sim.set_task(pool[it % tasks] if tasks else sim.random_task(rng))
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        sim.sgd(lr)
        if len(losses) == 1:
            train.first_seconds = time.time() - t0  # includes compiling the kernels
    seconds = (time.time() - t0) / max(iters, 1)
    train.val_after = evaluate(sim, val) if n_val else None
    train.sim = sim
    if out is not None:
        if tasks:
            plot_losses(losses, os.path.join(out, "loss.png"), f"electric: loss on {tasks} fixed path(s)")
        else:
            plot_losses_smoothed(losses, os.path.join(out, "loss.png"), "electric: loss (a new random path each iter.)",
                                 window=max(1, min(100, iters // 10)))
        if frames:
            # the trained controller on a training path (or, with random paths, a held-out one)
            sim.set_task(show)
            sim.loss[None] = 0
            sim.forward()
            draw(sim, out, "trained", every=frame_every)
    return losses, seconds


def main():
    args = parse_args("Train a neural controller of electrode charges to steer a charged ball", iters=2000, tasks=0)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "electric")
    losses, sec = train(args.iters, out, tasks=args.tasks)
    k = max(1, min(100, len(losses) // 10))
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} (mean of first/last {k}: {np.mean(losses[:k]):.5f} -> "
          f"{np.mean(losses[-k:]):.5f}) in {len(losses)} iterations ({sec:.4f} s/iteration, the first "
          f"{train.first_seconds:.2f} s with compilation); "
          f"held-out paths: {train.val_before:.5f} -> {train.val_after:.5f}; pictures in {out}")


if __name__ == "__main__":
    main()
