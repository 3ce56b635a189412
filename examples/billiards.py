"""Differentiable billiards (DiffTaichi's billiards, written from the paper's description).

A white cue ball is shot into a triangle of ten red balls; we optimise the cue ball's initial position and
velocity by gradient descent so that one chosen ball (blue, a far corner of the triangle) ends at a goal
point. Balls move freely (no friction, no walls); ball-ball contacts are resolved with impulses
(restitution 0.8) plus the time-of-impact (TOI) correction the paper describes: a pair that would overlap by
the end of a step exchanges its impulse at the moment of contact inside the step (the first root of
|dx + s dv| = 2r, with the contact normal taken at that moment), so each ball travels with its old velocity
until the contact and with its new one afterwards. The final state is then a continuous function of the
cue parameters (a central difference agrees with the reverse-mode gradient from h = 1e-2 down to 1e-6 in
f64); without the correction it depends on the step at which a contact happens to be detected, and the
gradient is a saw-tooth.

Every step's state is kept (x[t, i], v[t, i]) and the per-step impulses / TOI position corrections are
accumulated in their own fields, so the reverse pass can replay each step (the global data access rules).

Sizes: the paper's: 4 layers (11 balls), 1024 steps of dt = 0.003, radius 0.03, goal (0.9, 0.75), plain
gradient descent with learning rate 0.01 for 200 iterations, cue ball from (0.1, 0.5) at (0.3, 0). (A larger
rate overshoots into shots that miss the blue ball entirely, where the gradient is zero.)

    python examples/billiards.py [--iters 200] [--out out/billiards] [--steps 1024] [--toi 1]
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress, write_gif  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def build(steps: int = 1024, layers: int = 4, dt: float = 0.003, goal=(0.9, 0.75), target_ball: int = -1,
          use_toi: bool = True):
    """Allocate the fields and kernels of one table; returns a namespace of them. use_toi=False drops the
    time-of-impact correction (for comparison)."""
    n_balls = 1 + layers * (layers + 1) // 2
    target_ball = target_ball % n_balls
    radius = 0.03
    restitution = 0.8

    x = ti.Vector.field(2, real, shape=(steps, n_balls), needs_grad=True)
    v = ti.Vector.field(2, real, shape=(steps, n_balls), needs_grad=True)
    dv = ti.Vector.field(2, real, shape=(steps, n_balls), needs_grad=True)  # impulse (per unit mass) into step t
    dx_toi = ti.Vector.field(2, real, shape=(steps, n_balls), needs_grad=True)  # TOI position correction
    cue_x = ti.Vector.field(2, real, shape=(), needs_grad=True)
    cue_v = ti.Vector.field(2, real, shape=(), needs_grad=True)
    loss = ti.field(real, shape=(), needs_grad=True)

    @ti.kernel
    def reset_contacts():
        for t, i in dv:
            dv[t, i] = ti.Vector([0.0, 0.0])
            dx_toi[t, i] = ti.Vector([0.0, 0.0])

    @ti.kernel
    def place_cue():
        x[0, 0] = cue_x[None]
        v[0, 0] = cue_v[None]

    @ti.kernel
    def contacts(t: ti.i32):
        # each ball gathers the impulses of its contacts during step t -> t + 1 (both balls of a pair
        # compute the same contact, so nothing is shared between threads)
        for i in range(n_balls):
            for j in range(n_balls):
                if j != i:
                    rel_x = x[t, i] - x[t, j]
                    rel_v = v[t, i] - v[t, j]
                    end = rel_x + dt * rel_v  # relative position at the end of the step, if nothing happens
                    if end.norm() < 2 * radius and rel_x.dot(rel_v) < 0:
                        # time of impact s in [0, dt]: the first root of |rel_x + s rel_v| = 2 radius
                        # (0 when the balls already touch)
                        a = rel_v.dot(rel_v)
                        b = rel_x.dot(rel_v)
                        c = rel_x.dot(rel_x) - 4 * radius * radius
                        root = ti.sqrt(ti.max(b * b - a * c, 0.0))
                        toi = ti.min(ti.max((-b - root) / ti.max(a, 1e-12), 0.0), dt)
                        if ti.static(not use_toi):  # the naive integrator: impulse at the start of the step
                            toi = 0.0
                        # the normal at the moment of contact
                        n = (rel_x + toi * rel_v).normalized(1e-6)
                        approach = n.dot(rel_v)
                        if approach < 0:
                            # equal masses: each ball takes half of the (1 + e) normal momentum change
                            delta = -0.5 * (1 + restitution) * approach * n
                            dv[t + 1, i] += delta
                            # old velocity until toi, new one afterwards: x + toi v + (dt - toi)(v + delta)
                            dx_toi[t + 1, i] -= toi * delta

    @ti.kernel
    def advance(t: ti.i32):
        for i in range(n_balls):
            v[t, i] = v[t - 1, i] + dv[t, i]
            x[t, i] = x[t - 1, i] + dt * v[t, i] + dx_toi[t, i]

    @ti.kernel
    def compute_loss():
        d = x[steps - 1, target_ball] - ti.Vector([goal[0], goal[1]])
        loss[None] = d.dot(d)

    def rack():
        """Initial positions: the cue ball is set by place_cue; the triangle points left with its apex at
        (0.5, 0.5), each row 2r further right and 0.7r lower than a symmetric rack (as in the paper's scene,
        so the break is not symmetric)."""
        xs = np.zeros((steps, n_balls, 2), np.float32)
        k = 1
        for row in range(layers):
            for j in range(row + 1):
                xs[0, k] = (0.5 + row * 2 * radius, 0.5 + j * 2 * radius - row * 0.7 * radius)
                k += 1
        x.from_numpy(xs)
        v.fill(0)

    def forward():
        reset_contacts()
        place_cue()
        for t in range(1, steps):
            contacts(t - 1)
            advance(t)
        compute_loss()

    ns = dict(locals())
    return type("Table", (), ns)


def draw(gui, table, xs, t):
    gui.clear(0x2E6B3A)
    px = table.radius * gui.res[0]
    colors = [0xD8303C] * table.n_balls
    colors[0], colors[table.target_ball] = 0xEEEEEE, 0x3355DD
    gui.circles(xs[t], radius=px, color=np.array(colors, dtype=np.uint32))
    gui.circle(table.goal, radius=5, color=0x111111)


def render(table, out: str, tag: str, gif: bool) -> None:
    """A few PNG frames of the current trajectory (and a GIF of it)."""
    gui = ti.GUI("billiards", res=512, background_color=0x2E6B3A, show_gui=False)
    xs = table.x.to_numpy()
    steps = table.steps
    for t in np.linspace(0, steps - 1, 4).astype(int):
        draw(gui, table, xs, t)
        gui.show(os.path.join(out, f"{tag}_{t:04d}.png"))
    if gif:  # a smaller canvas and 40 frames: GIF encoding costs ~0.1 s per 512 x 512 frame
        gui = ti.GUI("billiards", res=320, background_color=0x2E6B3A, show_gui=False)
        images = []
        for t in range(0, steps, max(1, steps // 40)):
            draw(gui, table, xs, t)
            images.append(gui.get_image()[..., :3].copy())
        write_gif(ti, images, out, tag)


def train(iters: int, out, steps: int = 1024, layers: int = 4, lr: float = 0.01, use_toi: bool = True,
          frames=True):
    table = build(steps, layers, use_toi=use_toi)
    table.rack()
    table.cue_x[None] = [0.1, 0.5]
    table.cue_v[None] = [0.3, 0.0]
    if out is not None and frames:
        table.forward()
        render(table, out, "initial", gif=False)
    losses = []
    t0 = time.time()
    for _ in progress(iters, "billiards"):
        with ti.ad.Tape(loss=table.loss):
            table.forward()
        losses.append(float(table.loss[None]))
        gx, gv = table.cue_x.grad.to_numpy(), table.cue_v.grad.to_numpy()
        table.cue_x.from_numpy(table.cue_x.to_numpy() - lr * gx)
        table.cue_v.from_numpy(table.cue_v.to_numpy() - lr * gv)
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), "billiards: squared distance of the blue ball to goal")
        if frames:
            table.forward()  # the trajectory of the final cue parameters
            render(table, out, "optimized", gif=True)
    return losses, seconds


def main():
    args = parse_args("Optimise the cue ball of a billiards break so the blue ball reaches the goal", iters=200,
                      steps=1024, toi=1)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "billiards")
    losses, sec = train(args.iters, out, steps=args.steps, use_toi=bool(args.toi))
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
