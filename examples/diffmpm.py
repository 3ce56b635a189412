"""A 2-D soft robot that learns to walk (DiffTaichi's diffmpm, written from the paper's description).

The robot is built from rectangles of particles (`Scene.add_rect`): a passive body on four leg blocks, each
leg block one actuator. An actuator's activation follows an open-loop controller, a tanh of a learned
combination of sine waves of fixed frequency and phase plus a learned bias; it adds an active stress along
the (deformed) vertical material fibre of its particles, so a block contracts or extends. The material
is a fixed-corotated elastic solid simulated with MLS-MPM (quadratic B-splines, APIC transfer) on a grid
whose floor is sticky. The loss is minus the x-displacement of the robot's centre of mass after `steps`
steps, so gradient descent on the controller's weights and biases makes the robot move right.

The particle state of every step is stored (x, v, C, F indexed [step, particle]); the grid is one
buffer, so each substep is @ti.ad.grad_replaced and its gradient recomputes the grid from the stored
particles (checkpointing by recomputation) before running the adjoint kernels.

Defaults are the paper's: a 128 x 128 grid, dt = 1e-3, 1024 steps, 2 particles per cell width (2976
particles), E = 10, gravity 3.8, 4 sine waves at omega = 20, actuation strength 4, learning rate 0.1;
they take about 0.8 s per iteration on this 2-core CPU, so all of them are kept. The paper trains 80-100
iterations; the default here is 40 (run with --iters 100 for the full optimisation).

    python examples/diffmpm.py [--iters 40] [--out out/diffmpm] [--steps 1024] [--n-grid 128]
"""

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import actuation_colors, out_dir, parse_args, plot_losses, progress, write_gif  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


class Scene:
    """Particles of a robot, added rectangle by rectangle on a regular lattice."""

    def __init__(self, dx: float, per_cell: int = 2):
        self.dx = dx
        self.per_cell = per_cell  # particles per grid cell width
        self.offset = (0.0, 0.0)
        self.pos: list[np.ndarray] = []
        self.act_ids: list[np.ndarray] = []
        self.n_actuators = 0

    def set_offset(self, x: float, y: float) -> None:
        self.offset = (x, y)

    def add_rect(self, x: float, y: float, w: float, h: float, actuation: int) -> None:
        """Fill the rectangle [x, x+w] x [y, y+h] (shifted by the offset); actuation -1 is passive."""
        nx = max(1, int(w / self.dx) * self.per_cell)
        ny = max(1, int(h / self.dx) * self.per_cell)
        gx = x + self.offset[0] + (np.arange(nx) + 0.5) * (w / nx)
        gy = y + self.offset[1] + (np.arange(ny) + 0.5) * (h / ny)
        px, py = np.meshgrid(gx, gy, indexing="ij")
        self.pos.append(np.stack([px.ravel(), py.ravel()], axis=1))
        self.act_ids.append(np.full(nx * ny, actuation, dtype=np.int32))
        self.n_actuators = max(self.n_actuators, actuation + 1)

    def arrays(self):
        return np.concatenate(self.pos).astype(np.float32), np.concatenate(self.act_ids)


def robot(scene: Scene) -> None:
    """A flat body on four legs; each leg is split into a front and a back actuator.

    The robot starts just above the floor (which is 3 grid cells thick)."""
    scene.set_offset(0.1, 3 * scene.dx + 0.0066)
    scene.add_rect(0.0, 0.1, 0.3, 0.1, -1)
    for k, left in enumerate((0.0, 0.05, 0.2, 0.25)):
        scene.add_rect(left, 0.0, 0.05, 0.1, k)


def build(n_grid: int = 128, steps: int = 1024, dt: float = 1e-3, per_cell: int = 2):
    """Allocate the fields and kernels of one robot simulation; returns a namespace of them."""
    dx = 1 / n_grid
    inv_dx = float(n_grid)
    scene = Scene(dx, per_cell)
    robot(scene)
    pos0, act_id0 = scene.arrays()
    n_particles, n_actuators = len(pos0), scene.n_actuators
    p_vol, p_mass = 1.0, 1.0
    E = 10.0
    mu, la = E, E
    gravity = 3.8
    n_sin = 4
    omega = 20.0
    act_strength = 4.0
    bound = 3

    x = ti.Vector.field(2, dtype=real, shape=(steps, n_particles), needs_grad=True)
    v = ti.Vector.field(2, dtype=real, shape=(steps, n_particles), needs_grad=True)
    C = ti.Matrix.field(2, 2, dtype=real, shape=(steps, n_particles), needs_grad=True)
    F = ti.Matrix.field(2, 2, dtype=real, shape=(steps, n_particles), needs_grad=True)
    actuator_id = ti.field(ti.i32, shape=n_particles)
    grid_mv = ti.Vector.field(2, dtype=real, shape=(n_grid, n_grid), needs_grad=True)  # momentum in
    grid_m = ti.field(dtype=real, shape=(n_grid, n_grid), needs_grad=True)
    grid_v = ti.Vector.field(2, dtype=real, shape=(n_grid, n_grid), needs_grad=True)  # velocity out
    weights = ti.field(dtype=real, shape=(n_actuators, n_sin), needs_grad=True)
    bias = ti.field(dtype=real, shape=n_actuators, needs_grad=True)
    actuation = ti.field(dtype=real, shape=(steps, n_actuators), needs_grad=True)
    loss = ti.field(dtype=real, shape=(), needs_grad=True)

    @ti.kernel
    def init_particles(pos: ti.types.ndarray(), ids: ti.types.ndarray()):
        for p in range(n_particles):
            x[0, p] = [pos[p, 0], pos[p, 1]]
            v[0, p] = [0.0, 0.0]
            C[0, p] = [[0.0, 0.0], [0.0, 0.0]]
            F[0, p] = [[1.0, 0.0], [0.0, 1.0]]
            actuator_id[p] = ids[p]

    @ti.kernel
    def compute_actuation():
        # the open-loop controller for every step at once: tanh(sum_k w_ak sin(omega t + phase_k) + b_a)
        for t, a in actuation:
            u = bias[a]
            for k in ti.static(range(n_sin)):
                u += weights[a, k] * ti.sin(omega * dt * t + 2 * math.pi * k / n_sin)
            actuation[t, a] = ti.tanh(u)

    @ti.kernel
    def clear_grid():
        for i, j in grid_m:
            grid_mv[i, j] = [0.0, 0.0]
            grid_m[i, j] = 0.0
            grid_mv.grad[i, j] = [0.0, 0.0]
            grid_m.grad[i, j] = 0.0
            grid_v.grad[i, j] = [0.0, 0.0]

    @ti.kernel
    def p2g(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, real)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_F = (ti.Matrix([[1.0, 0.0], [0.0, 1.0]]) + dt * C[f, p]) @ F[f, p]
            F[f + 1, p] = new_F
            J = new_F.determinant()
            r, _s = ti.polar_decompose(new_F)
            # fixed-corotated Kirchhoff stress
            tau = 2 * mu * (new_F - r) @ new_F.transpose() + ti.Matrix([[1.0, 0.0], [0.0, 1.0]]) * (la * (J - 1) * J)
            aid = actuator_id[p]
            if aid >= 0:
                # active stress along the deformed vertical fibre F e_y
                fibre = ti.Vector([new_F[0, 1], new_F[1, 1]])
                tau += (act_strength * actuation[f, aid]) * fibre.outer_product(fibre)
            affine = -(dt * p_vol * 4 * inv_dx * inv_dx) * tau + p_mass * C[f, p]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    offset = ti.Vector([i, j])
                    dpos = (ti.cast(offset, real) - fx) * dx
                    weight = w[i][0] * w[j][1]
                    grid_mv[base + offset] += weight * (p_mass * v[f, p] + affine @ dpos)
                    grid_m[base + offset] += weight * p_mass

    @ti.kernel
    def grid_op():
        for i, j in grid_m:
            vel = grid_mv[i, j] / (grid_m[i, j] + 1e-10)
            vel[1] -= dt * gravity
            if i < bound and vel[0] < 0:
                vel[0] = 0.0
            if i > n_grid - bound and vel[0] > 0:
                vel[0] = 0.0
            if j > n_grid - bound and vel[1] > 0:
                vel[1] = 0.0
            if j < bound and vel[1] < 0:  # sticky floor
                vel = ti.Vector([0.0, 0.0])
            grid_v[i, j] = vel

    @ti.kernel
    def g2p(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, real)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.Vector([0.0, 0.0])
            new_C = ti.Matrix([[0.0, 0.0], [0.0, 0.0]])
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    dpos = ti.cast(ti.Vector([i, j]), real) - fx
                    g_v = grid_v[base[0] + i, base[1] + j]
                    weight = w[i][0] * w[j][1]
                    new_v += weight * g_v
                    new_C += 4 * inv_dx * weight * g_v.outer_product(dpos)
            v[f + 1, p] = new_v
            x[f + 1, p] = x[f, p] + dt * new_v
            C[f + 1, p] = new_C

    @ti.kernel
    def compute_loss():
        for p in range(n_particles):
            loss[None] += -(x[steps - 1, p][0] - x[0, p][0]) / n_particles

    @ti.ad.grad_replaced
    def substep(s):
        clear_grid()
        p2g(s)
        grid_op()
        g2p(s)

    @ti.ad.grad_for(substep)
    def substep_grad(s):
        clear_grid()
        p2g(s)
        grid_op()
        g2p.grad(s)
        grid_op.grad()
        p2g.grad(s)

    def reset(seed: int = 0):
        init_particles(pos0, act_id0)
        rng = np.random.default_rng(seed)
        weights.from_numpy((0.01 * rng.standard_normal((n_actuators, n_sin))).astype(np.float32))
        bias.fill(0.0)

    def forward():
        loss[None] = 0.0
        compute_actuation()
        for s in range(steps - 1):
            substep(s)
        compute_loss()

    ns = dict(locals())
    return type("Sim", (), ns)


def render(sim, xs: np.ndarray, acts: np.ndarray, out: str, prefix: str, n_png: int, n_gif: int = 0):
    """Draw a trajectory xs[step, particle]: `n_png` states as PNGs, `n_gif` states into out/diffmpm.gif."""
    gui = ti.GUI("diffmpm", res=512, background_color=0xFFFFFF, show_gui=False)
    ids = sim.act_id0
    n = len(xs)
    png_steps = set(np.linspace(0, n - 1, max(n_png, 1)).astype(int).tolist()) if n_png else set()
    gif_steps = set(np.linspace(0, n - 1, n_gif).astype(int).tolist()) if n_gif else set()
    frames = []
    for s in sorted(png_steps | gif_steps):
        act = acts[max(s - 1, 0)][np.maximum(ids, 0)]
        gui.circles(xs[s], radius=1.5, color=actuation_colors(act, ids >= 0))
        gui.line((0.0, 3 / sim.n_grid), (1.0, 3 / sim.n_grid), radius=2, color=0x222222)
        if s in gif_steps:
            frames.append(gui.get_image()[:, :, :3])
        gui.show(os.path.join(out, f"{prefix}{s:04d}.png") if s in png_steps else None)
    if frames:
        write_gif(ti, frames, out, "diffmpm")


def train(iters: int, out: str | None, n_grid: int = 128, steps: int = 1024, lr: float = 0.1,
          frames: int = 6, gif_frames: int = 48, timings: dict | None = None):
    """Optimise the controller for `iters` iterations; returns (losses, seconds per iteration).

    The time step grows as the grid coarsens (1e-3 at 128 cells), so that few steps still make a gait."""
    dt = 1e-3 * 128 / n_grid
    if out is not None:
        os.makedirs(out, exist_ok=True)
    sim = build(n_grid=n_grid, steps=steps, dt=dt)
    sim.reset()
    losses, durations = [], []
    for it in progress(iters, "diffmpm"):
        t0 = time.time()
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        sim.weights.from_numpy(sim.weights.to_numpy() - lr * sim.weights.grad.to_numpy())
        sim.bias.from_numpy(sim.bias.to_numpy() - lr * sim.bias.grad.to_numpy())
        durations.append(time.time() - t0)
        if it == 0 and out is not None and frames:
            render(sim, sim.x.to_numpy(), sim.actuation.to_numpy(), out, "iter0000_", frames)
    seconds = float(np.mean(durations[1:] if iters > 1 else durations))
    if timings is not None:
        timings.update(first=durations[0], per_iteration=seconds, n_particles=sim.n_particles)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), "diffmpm: -(x-displacement of the robot)")
        if frames:
            render(sim, sim.x.to_numpy(), sim.actuation.to_numpy(), out, f"iter{iters - 1:04d}_", frames,
                   n_gif=gif_frames)
    return losses, seconds


def main():
    args = parse_args("Teach a 2-D MPM soft robot to walk (open-loop sine controller)", iters=40, steps=1024,
                      n_grid=128)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "diffmpm")
    timings = {}
    losses, sec = train(args.iters, out, n_grid=args.n_grid, steps=args.steps, timings=timings)
    print(f"{timings['n_particles']} particles, {args.steps} steps: loss {losses[0]:.5f} -> {losses[-1]:.5f} "
          f"in {len(losses)} iterations; first iteration {timings['first']:.2f} s (compile included), then "
          f"{sec:.2f} s/iteration; pictures in {out}")


if __name__ == "__main__":
    main()
