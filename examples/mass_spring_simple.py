"""A tiny differentiable mass-spring system (DiffTaichi's mass_spring_simple, written from the paper).

Three particles joined by springs oscillate; we optimise the springs' rest lengths so that particle 0
ends at a target point after `steps` steps. Semi-implicit Euler with damping; the
state of every step is stored (x[t, i], v[t, i]) so that the backward pass can replay each step.

    python examples/mass_spring_simple.py [--iters 100] [--out out/mass_spring_simple]
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402


def build(steps: int = 512, dt: float = 0.002, real=ti.f32):
    n_particles, n_springs = 3, 3
    damping = 2.0
    gravity = 0.0
    target = (0.25, 0.55)
    x = ti.Vector.field(2, real, shape=(steps, n_particles), needs_grad=True)
    v = ti.Vector.field(2, real, shape=(steps, n_particles), needs_grad=True)
    f = ti.Vector.field(2, real, shape=(steps, n_particles), needs_grad=True)
    anchor_a = ti.field(ti.i32, shape=n_springs)
    anchor_b = ti.field(ti.i32, shape=n_springs)
    rest_length = ti.field(real, shape=n_springs, needs_grad=True)
    stiffness = ti.field(real, shape=n_springs, needs_grad=True)
    loss = ti.field(real, shape=(), needs_grad=True)

    @ti.kernel
    def apply_spring_force(t: ti.i32):
        for i in range(n_springs):
            a = anchor_a[i]
            b = anchor_b[i]
            d = x[t, a] - x[t, b]
            force = -stiffness[i] * (d.norm() - rest_length[i]) * d.normalized()
            f[t, a] += force
            f[t, b] -= force

    @ti.kernel
    def integrate(t: ti.i32):
        for i in range(n_particles):
            s = ti.exp(-dt * damping)
            new_v = s * v[t, i] + dt * (f[t, i] + ti.Vector([0.0, gravity]))
            v[t + 1, i] = new_v
            x[t + 1, i] = x[t, i] + dt * new_v

    @ti.kernel
    def compute_loss(t: ti.i32):
        c = x[t, 0]
        loss[None] = (c[0] - target[0]) ** 2 + (c[1] - target[1]) ** 2

    np_real = np.float64 if real == ti.f64 else np.float32

    def setup():
        x0 = np.zeros((steps, n_particles, 2))
        x0[0] = [[0.3, 0.5], [0.3, 0.4], [0.4, 0.4]]
        x.from_numpy(x0.astype(np_real))
        v.fill(0)
        anchor_a.from_numpy(np.array([0, 1, 2], dtype=np.int32))
        anchor_b.from_numpy(np.array([1, 2, 0], dtype=np.int32))
        rest_length.from_numpy(np.array([0.1, 0.1, 0.14], dtype=np_real))
        stiffness.fill(100.0)

    def forward():
        f.fill(0)
        for t in range(steps - 1):
            apply_spring_force(t)
            integrate(t)
        compute_loss(steps - 1)

    return type("Sim", (), dict(locals()))


def train(iters: int, out: str | None, steps: int = 512, lr: float = 0.5):
    sim = build(steps)
    sim.setup()
    losses = []
    t0 = time.time()
    for _ in progress(iters, "mass_spring_simple"):
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        sim.rest_length.from_numpy(sim.rest_length.to_numpy() - lr * sim.rest_length.grad.to_numpy())
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), "mass_spring_simple: squared distance to target")
        gui = ti.GUI("mass_spring_simple", res=512, background_color=0xFFFFFF, show_gui=False)
        xs = sim.x.to_numpy()
        for t in range(0, steps, max(1, steps // 8)):
            for a, b in ((0, 1), (1, 2), (2, 0)):
                gui.line(xs[t, a], xs[t, b], radius=2, color=0x444444)
            gui.circles(xs[t], radius=6, color=0x3366CC)
            gui.circle(sim.target, radius=5, color=0xEE3333)
            gui.show(os.path.join(out, f"frame_{t:04d}.png"))
    return losses, seconds


def main():
    args = parse_args("Optimise spring rest lengths of a 3-particle mass-spring system", iters=100)
    ti.init(arch=ti.cpu)
    out = out_dir(args.out, "mass_spring_simple")
    losses, sec = train(args.iters, out)
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
