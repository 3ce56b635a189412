"""A 3-D soft robot that learns to walk (DiffTaichi's diffmpm3d, written from the paper's description).

The robot is a flat slab of blocks: four corner legs, each made of 2 x 2 actuated blocks (front/back,
lower/upper), joined by a passive middle strip. Each actuator follows an open-loop controller, a tanh of a
learned combination of 4 sine waves plus a learned bias, and adds an active stress along its blocks'
(deformed) vertical fibre. The material is neo-Hookean, simulated with MLS-MPM (quadratic B-splines,
APIC transfer) on a grid with a sticky floor. The loss is minus the x-displacement of the robot's centre of
mass after `steps` steps; plain gradient descent on the controller's weights and biases.

The simulator also knows weakly compressible fluid particles (particle type 0, only their volume change
J is kept, as a uniform stretch J^(1/3)); examples/liquid.py reuses it with a block of liquid on the robot.

As in examples/diffmpm.py, the particle state of every step is stored and each substep is
@ti.ad.grad_replaced with a gradient that recomputes the grid before running the adjoint kernels.

Sizes. The paper's run (64^3 grid, 3 particles per cell width, block size 0.1: 30.5K particles, 512 steps
of dt = 2e-3, 40-100 iterations with learning rate 30) takes tens of seconds per iteration on this 2-core
CPU (35K particles with our rounding of the block sizes) and 3.5 GB for the stored states and their
gradients. The default keeps the paper's robot geometry, time step, 512 steps, physical constants (E = 10,
gravity 10, omega = 40, actuation strength 5) and learning rate, but uses a 48^3 grid seeded with 2
particles per cell width (4.5K particles, ~3.5 s per iteration) and 30 iterations; --n-grid 64 --per-cell 3
gives the paper's resolution.

    python examples/diffmpm3d.py [--iters 30] [--out out/diffmpm3d] [--steps 512] [--n-grid 48] [--per-cell 2]
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
SOLID, FLUID = 1, 0


class Scene:
    """Particles of a 3-D scene, added box by box: solids on a regular lattice, fluids at random."""

    def __init__(self, dx: float, per_cell: float = 1, seed: int = 0):
        self.dx = dx
        self.per_cell = per_cell  # particles per grid cell width
        self.offset = (0.0, 0.0, 0.0)
        self.pos, self.act_ids, self.types = [], [], []
        self.n_actuators = 0
        self.rng = np.random.default_rng(seed)

    def set_offset(self, x: float, y: float, z: float) -> None:
        self.offset = (x, y, z)

    def new_actuator(self) -> int:
        self.n_actuators += 1
        return self.n_actuators - 1

    def add_rect(self, x, y, z, w, h, d, actuation: int, ptype: int = SOLID) -> None:
        """Fill the box [x, x+w] x [y, y+h] x [z, z+d] (shifted by the offset); actuation -1 is passive."""
        counts = [max(1, int(round(size / self.dx * self.per_cell))) for size in (w, h, d)]
        lo = np.array([x, y, z]) + np.array(self.offset)
        size = np.array([w, h, d])
        n = counts[0] * counts[1] * counts[2]
        if ptype == SOLID:
            axes = [(np.arange(c) + 0.5) / c for c in counts]
            unit = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
        else:
            assert actuation == -1, "fluid particles are not actuated"
            unit = self.rng.random((n, 3))
        self.pos.append(lo + unit * size)
        self.act_ids.append(np.full(n, actuation, dtype=np.int32))
        self.types.append(np.full(n, ptype, dtype=np.int32))

    def arrays(self):
        return (np.concatenate(self.pos).astype(np.float32), np.concatenate(self.act_ids),
                np.concatenate(self.types))


def robot(scene: Scene, block: float = 0.1) -> None:
    """Four legs of 2 x 2 actuated blocks at the corners, a passive strip of 3 blocks between them.

    The robot starts just above the floor (which is 3 grid cells thick)."""
    scene.set_offset(0.1, 3 * scene.dx + 0.003, 0.3)
    height = 0.7 * block
    for leg in range(4):
        lx, lz = (leg // 2) * 2 * block, (leg % 2) * 2 * block
        for part in range(4):
            scene.add_rect(lx + (part // 2) * block / 2, (part % 2) * height / 2, lz,
                           block / 2, height / 2, block, scene.new_actuator())
    for k in range(3):
        scene.add_rect(k * block, 0.0, block, block, height, block, -1)


def build(scene: Scene, n_grid: int = 64, steps: int = 512, dt: float = 2e-3):
    """Allocate the fields and kernels of one simulation of `scene`; returns a namespace of them."""
    dx = 1 / n_grid
    inv_dx = float(n_grid)
    pos0, act_id0, type0 = scene.arrays()
    n_particles, n_actuators = len(pos0), max(scene.n_actuators, 1)
    n_solid = max(int((type0 == SOLID).sum()), 1)
    p_vol = 1.0
    E = 10.0
    mu, la = E, E
    gravity = 10.0
    n_sin = 4
    omega = 40.0
    act_strength = 5.0
    bound = 3

    x = ti.Vector.field(3, dtype=real, shape=(steps, n_particles), needs_grad=True)
    v = ti.Vector.field(3, dtype=real, shape=(steps, n_particles), needs_grad=True)
    C = ti.Matrix.field(3, 3, dtype=real, shape=(steps, n_particles), needs_grad=True)
    F = ti.Matrix.field(3, 3, dtype=real, shape=(steps, n_particles), needs_grad=True)
    actuator_id = ti.field(ti.i32, shape=n_particles)
    particle_type = ti.field(ti.i32, shape=n_particles)
    grid_mv = ti.Vector.field(3, dtype=real, shape=(n_grid, n_grid, n_grid), needs_grad=True)
    grid_m = ti.field(dtype=real, shape=(n_grid, n_grid, n_grid), needs_grad=True)
    grid_v = ti.Vector.field(3, dtype=real, shape=(n_grid, n_grid, n_grid), needs_grad=True)
    weights = ti.field(dtype=real, shape=(n_actuators, n_sin), needs_grad=True)
    bias = ti.field(dtype=real, shape=n_actuators, needs_grad=True)
    actuation = ti.field(dtype=real, shape=(steps, n_actuators), needs_grad=True)
    loss = ti.field(dtype=real, shape=(), needs_grad=True)

    @ti.kernel
    def init_particles(pos: ti.types.ndarray(), ids: ti.types.ndarray(), types: ti.types.ndarray()):
        for p in range(n_particles):
            x[0, p] = [pos[p, 0], pos[p, 1], pos[p, 2]]
            v[0, p] = [0.0, 0.0, 0.0]
            C[0, p] = ti.Matrix.zero(real, 3, 3)
            F[0, p] = ti.Matrix.identity(real, 3)
            actuator_id[p] = ids[p]
            particle_type[p] = types[p]

    @ti.kernel
    def compute_actuation():
        for t, a in actuation:
            u = bias[a]
            for k in ti.static(range(n_sin)):
                u += weights[a, k] * ti.sin(omega * dt * t + 2 * math.pi * k / n_sin)
            actuation[t, a] = ti.tanh(u)

    @ti.kernel
    def clear_grid():
        for i, j, k in grid_m:
            grid_mv[i, j, k] = [0.0, 0.0, 0.0]
            grid_m[i, j, k] = 0.0
            grid_mv.grad[i, j, k] = [0.0, 0.0, 0.0]
            grid_m.grad[i, j, k] = 0.0
            grid_v.grad[i, j, k] = [0.0, 0.0, 0.0]

    @ti.kernel
    def p2g(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, real)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            ident = ti.Matrix.identity(real, 3)
            new_F = (ident + dt * C[f, p]) @ F[f, p]
            J = new_F.determinant()
            mass = 1.0
            tau = ti.Matrix.zero(real, 3, 3)
            if particle_type[p] == FLUID:
                # a fluid keeps only its volume change, as a uniform stretch
                new_F = ident * J ** (1.0 / 3.0)
                mass = 4.0
                tau = ident * (E * (J - 1.0) * J)
            else:
                # neo-Hookean Kirchhoff stress
                tau = mu * (new_F @ new_F.transpose() - ident) + ident * (la * ti.log(J))
                aid = actuator_id[p]
                if aid >= 0:
                    fibre = ti.Vector([new_F[0, 1], new_F[1, 1], new_F[2, 1]])
                    tau += (act_strength * actuation[f, aid]) * fibre.outer_product(fibre)
            F[f + 1, p] = new_F
            affine = -(dt * p_vol * 4 * inv_dx * inv_dx) * tau + mass * C[f, p]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    for k in ti.static(range(3)):
                        offset = ti.Vector([i, j, k])
                        dpos = (ti.cast(offset, real) - fx) * dx
                        weight = w[i][0] * w[j][1] * w[k][2]
                        grid_mv[base + offset] += weight * (mass * v[f, p] + affine @ dpos)
                        grid_m[base + offset] += weight * mass

    @ti.kernel
    def grid_op():
        for i, j, k in grid_m:
            vel = grid_mv[i, j, k] / (grid_m[i, j, k] + 1e-10)
            vel[1] -= dt * gravity
            if i < bound and vel[0] < 0:
                vel[0] = 0.0
            if i > n_grid - bound and vel[0] > 0:
                vel[0] = 0.0
            if k < bound and vel[2] < 0:
                vel[2] = 0.0
            if k > n_grid - bound and vel[2] > 0:
                vel[2] = 0.0
            if j > n_grid - bound and vel[1] > 0:
                vel[1] = 0.0
            if j < bound and vel[1] < 0:  # sticky floor
                vel = ti.Vector([0.0, 0.0, 0.0])
            grid_v[i, j, k] = vel

    @ti.kernel
    def g2p(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, real)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.Vector([0.0, 0.0, 0.0])
            new_C = ti.Matrix.zero(real, 3, 3)
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    for k in ti.static(range(3)):
                        dpos = ti.cast(ti.Vector([i, j, k]), real) - fx
                        g_v = grid_v[base[0] + i, base[1] + j, base[2] + k]
                        weight = w[i][0] * w[j][1] * w[k][2]
                        new_v += weight * g_v
                        new_C += 4 * inv_dx * weight * g_v.outer_product(dpos)
            v[f + 1, p] = new_v
            x[f + 1, p] = x[f, p] + dt * new_v
            C[f + 1, p] = new_C

    @ti.kernel
    def compute_loss():
        for p in range(n_particles):
            if particle_type[p] == SOLID:
                loss[None] += -(x[steps - 1, p][0] - x[0, p][0]) / n_solid

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
        init_particles(pos0, act_id0, type0)
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


def render(sim, xs: np.ndarray, acts: np.ndarray, out: str, prefix: str, n_png: int, n_gif: int = 0,
           name: str = "diffmpm3d"):
    """Draw a trajectory xs[step, particle] in 3-D through ti.ui.Scene: `n_png` states as PNGs, `n_gif`
    states into out/<name>.gif. Particles are spheres coloured by their actuator's signal (red extending,
    blue contracting, grey passive, light blue liquid) above the floor of the walking region."""
    window = ti.ui.Window(name, (640, 400), show_window=False)
    canvas, scene = window.get_canvas(), window.get_scene()
    camera = ti.ui.Camera()
    camera.position(0.5, 0.38, 1.2)
    camera.lookat(0.4, 0.1, 0.45)
    camera.fov(40)
    ids, types = sim.act_id0, sim.type0
    n = len(xs)
    png_steps = set(np.linspace(0, n - 1, n_png).astype(int).tolist()) if n_png else set()
    gif_steps = set(np.linspace(0, n - 1, n_gif).astype(int).tolist()) if n_gif else set()
    y0 = 3 / sim.n_grid
    floor = np.array([[-0.2, y0, 0.0], [1.2, y0, 0.0], [1.2, y0, 0.9], [-0.2, y0, 0.9]], dtype=np.float32)
    floor_tris = np.array([0, 2, 1, 0, 3, 2], dtype=np.int32)  # counter-clockwise seen from above
    radius = 0.6 * sim.dx / sim.scene.per_cell  # a little over half the spacing: no gaps between spheres
    frames = []
    for s in sorted(png_steps | gif_steps):
        act = acts[max(s - 1, 0)][np.maximum(ids, 0)]
        colors = ti.hex_to_rgb(np.where(types == FLUID, np.uint32(0x4499EE), actuation_colors(act, ids >= 0)))
        canvas.set_background_color((1.0, 1.0, 1.0))
        scene.set_camera(camera)
        scene.ambient_light((0.35, 0.35, 0.35))
        scene.point_light(pos=(0.3, 2.0, 1.5), color=(0.75, 0.75, 0.75))
        scene.mesh(floor, indices=floor_tris, color=(0.55, 0.6, 0.55))
        scene.particles(xs[s].astype(np.float32), radius=radius, per_vertex_color=colors.astype(np.float32))
        canvas.scene(scene)
        if s in png_steps:
            window.save_image(os.path.join(out, f"{prefix}{s:04d}.png"))
        if s in gif_steps:
            frames.append(window.get_image_buffer_as_numpy()[:, :, :3])
        window.show()
    if frames:
        write_gif(ti, frames, out, name)


def run(sim, name: str, iters: int, out, lr: float, frames: int, gif_frames: int, timings):
    """Gradient descent on the controller of `sim`; returns (losses, seconds per iteration)."""
    if out is not None:
        os.makedirs(out, exist_ok=True)
    sim.reset()
    losses, durations = [], []
    for it in progress(iters, name):
        t0 = time.time()
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        sim.weights.from_numpy(sim.weights.to_numpy() - lr * sim.weights.grad.to_numpy())
        sim.bias.from_numpy(sim.bias.to_numpy() - lr * sim.bias.grad.to_numpy())
        durations.append(time.time() - t0)
        if it == 0 and out is not None and frames:
            render(sim, sim.x.to_numpy(), sim.actuation.to_numpy(), out, "iter0000_", frames, name=name)
    seconds = float(np.mean(durations[1:] if iters > 1 else durations))
    if timings is not None:
        timings.update(first=durations[0], per_iteration=seconds, n_particles=sim.n_particles)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), f"{name}: -(x-displacement of the robot)")
        if frames:
            render(sim, sim.x.to_numpy(), sim.actuation.to_numpy(), out, f"iter{iters - 1:04d}_", frames,
                   n_gif=gif_frames, name=name)
    return losses, seconds


def train(iters: int, out, n_grid: int = 48, steps: int = 512, per_cell: float = 2, block: float = 0.1,
          dt: float = 2e-3, lr: float = 30.0, frames: int = 6, gif_frames: int = 48, timings: dict | None = None):
    """Optimise the robot's controller for `iters` iterations; returns (losses, seconds per iteration)."""
    scene = Scene(1 / n_grid, per_cell)
    robot(scene, block)
    sim = build(scene, n_grid=n_grid, steps=steps, dt=dt)
    return run(sim, "diffmpm3d", iters, out, lr, frames, gif_frames, timings)


def main():
    args = parse_args("Teach a 3-D MPM soft robot to walk (open-loop sine controller)", iters=30, steps=512,
                      n_grid=48, per_cell=2.0)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "diffmpm3d")
    timings = {}
    losses, sec = train(args.iters, out, n_grid=args.n_grid, steps=args.steps, per_cell=args.per_cell,
                        timings=timings)
    print(f"{timings['n_particles']} particles, {args.steps} steps: loss {losses[0]:.5f} -> {losses[-1]:.5f} "
          f"in {len(losses)} iterations; first iteration {timings['first']:.2f} s (compile included), then "
          f"{sec:.2f} s/iteration; pictures in {out}")


if __name__ == "__main__":
    main()
