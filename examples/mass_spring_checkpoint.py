"""A long in-place mass-spring simulation trained through ti.ad.checkpoint.

A hanging rope of particles joined by springs swings for `steps` steps (1000 by default). The state (x, v) is
advanced *in place*, one field each, as a simulation written without autodiff in mind would do
(`v[i] = v[i] * damping + dt * f[i] / m`, `x[i] += dt * v[i]`); the forces are a temporary recomputed every
step. We optimise the rope's initial velocities so that its free end is at a target point at the end.
`ti.ad.checkpoint` differentiates the whole simulation while keeping only `budget` snapshots of the state
(binomial schedule) instead of every step's state, and prints the memory it used next to what a
time-indexed program (x[t, i], v[t, i], f[t, i]) would hold.

    python examples/mass_spring_checkpoint.py [--iters 30] [--steps 1000] [--budget 10] [--out DIR]
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402


def build(n: int = 24, dt: float = 2e-3, real=ti.f32):
    stiffness, damping, mass, rest = 3000.0, 0.999, 1.0, 0.5 / n
    target = (0.5, 0.35)
    x = ti.Vector.field(2, real, shape=n, needs_grad=True)
    v = ti.Vector.field(2, real, shape=n, needs_grad=True)
    f = ti.Vector.field(2, real, shape=n, needs_grad=True)  # temporary: overwritten every step before use
    init_v = ti.Vector.field(2, real, shape=n, needs_grad=True)  # the parameters
    loss = ti.field(real, shape=(), needs_grad=True)

    @ti.kernel
    def start():
        for i in range(n):
            x[i] = ti.Vector([0.3 + i * rest, 0.8])
            v[i] = init_v[i]

    @ti.kernel
    def forces():
        for i in range(n):
            acc = ti.Vector([0.0, -9.8 * mass])
            for d in ti.static((-1, 1)):
                j = i + d
                if 0 <= j < n:
                    e = x[j] - x[i]
                    length = e.norm(1e-9)
                    acc += stiffness * (length - rest) * e / length
            f[i] = acc

    @ti.kernel
    def advance():
        for i in range(1, n):  # particle 0 is pinned
            v[i] = v[i] * damping + dt * f[i] / mass
            x[i] += dt * v[i]

    @ti.kernel
    def compute_loss():
        d = x[n - 1] - ti.Vector(target)
        loss[None] = d.dot(d)

    def step(t):
        forces()
        advance()

    return dict(x=x, v=v, f=f, init_v=init_v, loss=loss, start=start, step=step, compute_loss=compute_loss,
                target=target, n=n)


def main():
    args = parse_args(__doc__.splitlines()[0], iters=30, steps=1000, budget=10, lr=4.0)
    ti.init(arch=ti.cpu)
    sim = build()
    out = out_dir(args.out, "mass_spring_checkpoint")
    losses = []
    t0 = time.time()
    for _ in progress(args.iters, "mass_spring_checkpoint"):
        with ti.ad.Tape(loss=sim["loss"]):
            sim["start"]()
            cp = ti.ad.checkpoint(sim["step"], args.steps, state=[sim["x"], sim["v"]], budget=args.budget)
            sim["compute_loss"]()
        losses.append(sim["loss"][None])
        g = sim["init_v"].grad.to_numpy()
        sim["init_v"].from_numpy(sim["init_v"].to_numpy() - args.lr * g / (np.abs(g).max() + 1e-12))
    per_iter = (time.time() - t0) / max(args.iters, 1)
    state_bytes = sum(f.to_numpy().nbytes for f in (sim["x"], sim["v"]))
    indexed_bytes = 3 * state_bytes * (args.steps + 1)  # x, v and f for every step
    kept = (cp.peak + 3) * state_bytes
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {args.iters} iterations, {per_iter:.3f} s/iter")
    print(f"state {state_bytes} B: checkpointing kept at most {cp.peak} snapshots + 3 copies = {kept} B; "
          f"a time-indexed program would hold {indexed_bytes} B ({indexed_bytes / kept:.0f}x more); "
          f"{cp.recomputed} steps recomputed in the last backward pass")
    plot_losses(losses, os.path.join(out, "loss.png"), "mass_spring_checkpoint")
    return losses


if __name__ == "__main__":
    main()
