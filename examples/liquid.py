"""A 3-D soft robot carrying liquid learns to walk (DiffTaichi's liquid, written from the paper's description).

The 3-D robot of examples/diffmpm3d.py (four legs of 2 x 2 actuated blocks and a passive middle strip,
open-loop sine-wave controller, neo-Hookean MLS-MPM) with a slab of weakly compressible liquid dropped on
top of it: the liquid splashes over and around the robot, and the two are coupled through the shared
MPM grid. The loss is minus the x-displacement of the robot's centre of mass (the liquid is not counted);
gradient descent on the controller's weights and biases, through the liquid's dynamics.

Sizes. The paper's run (64^3 grid, 3 particles per cell width, block size 0.08: 43.5K particles, 512 steps
of dt = 2e-3, 450 iterations with learning rate 10) would take tens of seconds per iteration on this
2-core CPU (estimated from diffmpm3d at that resolution), and 450 iterations of it. The default keeps the
paper's geometry (blocks of 0.08, a 0.2 x 0.05 x 0.2 slab of liquid), time step, 512 steps and physical
constants, but uses a 48^3 grid with 2 particles per cell width (4.3K particles, ~3.5 s per iteration)
and 30 iterations with learning rate 30 instead of 450 with 10.

    python examples/liquid.py [--iters 30] [--out out/liquid] [--steps 512] [--n-grid 48] [--per-cell 2]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args  # noqa: E402
from diffmpm3d import FLUID, Scene, build, real, robot, run  # noqa: E402

import simgrad as ti  # noqa: E402


def robot_with_liquid(scene: Scene, block: float = 0.08) -> None:
    robot(scene, block)
    scene.add_rect(0.1, 0.15, 0.1, 0.2, 0.05, 0.2, -1, FLUID)


def train(iters: int, out, n_grid: int = 48, steps: int = 512, per_cell: float = 2, block: float = 0.08,
          dt: float = 2e-3, lr: float = 30.0, frames: int = 6, gif_frames: int = 48, timings: dict | None = None):
    """Optimise the robot's controller for `iters` iterations; returns (losses, seconds per iteration)."""
    scene = Scene(1 / n_grid, per_cell)
    robot_with_liquid(scene, block)
    sim = build(scene, n_grid=n_grid, steps=steps, dt=dt)
    return run(sim, "liquid", iters, out, lr, frames, gif_frames, timings)


def main():
    args = parse_args("Teach a 3-D MPM soft robot carrying liquid to walk", iters=30, steps=512, n_grid=48,
                      per_cell=2.0)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "liquid")
    timings = {}
    losses, sec = train(args.iters, out, n_grid=args.n_grid, steps=args.steps, per_cell=args.per_cell,
                        timings=timings)
    print(f"{timings['n_particles']} particles, {args.steps} steps: loss {losses[0]:.5f} -> {losses[-1]:.5f} "
          f"in {len(losses)} iterations; first iteration {timings['first']:.2f} s (compile included), then "
          f"{sec:.2f} s/iteration; pictures in {out}")


if __name__ == "__main__":
    main()
