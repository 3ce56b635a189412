"""Differentiable MLS-MPM (DiffTaichi's diffmpm_simple, written from the paper's description).

An elastic square is thrown; we optimise its initial velocity so that its centre of mass ends at a target
point. p2g / grid / g2p use quadratic B-splines, the stress is fixed-corotated through ti.polar_decompose.
The grid is a single buffer: each substep is @ti.ad.grad_replaced and its gradient recomputes the grid
(checkpointing by recomputation) before running the adjoint kernels.

    python examples/diffmpm_simple.py [--iters 20] [--out out/diffmpm_simple] [--steps 512]
"""


import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def build(n_side: int = 40, n_grid: int = 64, steps: int = 512, dt: float = 2e-4):
    """Allocate the fields and kernels of one simulation; returns a namespace of them."""
    dim = 2
    n_particles = n_side * n_side
    dx = 1 / n_grid
    inv_dx = float(n_grid)
    p_vol, p_rho = (dx * 0.5) ** 2, 1.0
    p_mass = p_vol * p_rho
    E = 100.0
    mu, la = E, E
    gravity = 9.8
    target = ti.Vector([0.6, 0.6])

    x = ti.Vector.field(dim, dtype=real, shape=(steps, n_particles), needs_grad=True)
    v = ti.Vector.field(dim, dtype=real, shape=(steps, n_particles), needs_grad=True)
    C = ti.Matrix.field(dim, dim, dtype=real, shape=(steps, n_particles), needs_grad=True)
    F = ti.Matrix.field(dim, dim, dtype=real, shape=(steps, n_particles), needs_grad=True)
    grid_v_in = ti.Vector.field(dim, dtype=real, shape=(n_grid, n_grid), needs_grad=True)
    grid_m_in = ti.field(dtype=real, shape=(n_grid, n_grid), needs_grad=True)
    grid_v_out = ti.Vector.field(dim, dtype=real, shape=(n_grid, n_grid), needs_grad=True)
    init_v = ti.Vector.field(dim, dtype=real, shape=(), needs_grad=True)
    x_avg = ti.Vector.field(dim, dtype=real, shape=(), needs_grad=True)
    loss = ti.field(dtype=real, shape=(), needs_grad=True)

    @ti.kernel
    def set_v():
        for i in range(n_particles):
            v[0, i] = init_v[None]

    @ti.kernel
    def clear_grid():
        for i, j in grid_m_in:
            grid_v_in[i, j] = [0, 0]
            grid_m_in[i, j] = 0
            grid_v_in.grad[i, j] = [0, 0]
            grid_m_in.grad[i, j] = 0
            grid_v_out.grad[i, j] = [0, 0]

    @ti.kernel
    def p2g(f: ti.i32):
        for p in range(n_particles):
            base = ti.cast(x[f, p] * inv_dx - 0.5, ti.i32)
            fx = x[f, p] * inv_dx - ti.cast(base, real)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_F = (ti.Matrix.diag(dim=2, val=1) + dt * C[f, p]) @ F[f, p]
            F[f + 1, p] = new_F
            J = new_F.determinant()
            r, s = ti.polar_decompose(new_F)
            cauchy = 2 * mu * (new_F - r) @ new_F.transpose() + ti.Matrix.diag(2, la * (J - 1) * J)
            stress = -(dt * p_vol * 4 * inv_dx * inv_dx) * cauchy
            affine = stress + p_mass * C[f, p]
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    offset = ti.Vector([i, j])
                    dpos = (ti.cast(offset, real) - fx) * dx
                    weight = w[i][0] * w[j][1]
                    grid_v_in[base + offset] += weight * (p_mass * v[f, p] + affine @ dpos)
                    grid_m_in[base + offset] += weight * p_mass

    bound = 3

    @ti.kernel
    def grid_op():
        for i, j in grid_m_in:
            inv_m = 1 / (grid_m_in[i, j] + 1e-10)
            v_out = inv_m * grid_v_in[i, j]
            v_out[1] -= dt * gravity
            if i < bound and v_out[0] < 0:
                v_out[0] = 0
            if i > n_grid - bound and v_out[0] > 0:
                v_out[0] = 0
            if j < bound and v_out[1] < 0:
                v_out[1] = 0
            if j > n_grid - bound and v_out[1] > 0:
                v_out[1] = 0
            grid_v_out[i, j] = v_out

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
                    g_v = grid_v_out[base[0] + i, base[1] + j]
                    weight = w[i][0] * w[j][1]
                    new_v += weight * g_v
                    new_C += 4 * weight * g_v.outer_product(dpos) * inv_dx
            v[f + 1, p] = new_v
            x[f + 1, p] = x[f, p] + dt * v[f + 1, p]
            C[f + 1, p] = new_C

    @ti.kernel
    def compute_x_avg():
        for i in range(n_particles):
            x_avg[None] += (1 / n_particles) * x[steps - 1, i]

    @ti.kernel
    def compute_loss():
        dist = (x_avg[None] - target) ** 2
        loss[None] = 0.5 * (dist[0] + dist[1])

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

    def reset():
        i, j = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij")
        pos = np.stack([i.ravel(), j.ravel()], axis=1) * (dx * 0.5) + np.array([0.2, 0.2])
        xs = x.to_numpy()
        xs[0] = pos
        x.from_numpy(xs.astype(np.float32))
        fs = F.to_numpy()
        fs[0] = np.eye(2)
        F.from_numpy(fs.astype(np.float32))

    def forward():
        set_v()
        for s in range(steps - 1):
            substep(s)
        x_avg[None] = [0, 0]
        compute_x_avg()
        compute_loss()

    ns = dict(locals())
    return type("Sim", (), ns)


def train(iters: int, out: str | None, n_side=40, n_grid=64, steps=512, lr=10.0, frames=True):
    sim = build(n_side, n_grid, steps)
    sim.reset()
    sim.init_v[None] = [0.0, 0.0]
    losses = []
    t0 = time.time()
    for _ in progress(iters, "diffmpm_simple"):
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        g = sim.init_v.grad[None]
        sim.init_v[None] = [sim.init_v[None][0] - lr * g[0], sim.init_v[None][1] - lr * g[1]]
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), "diffmpm_simple: distance to target")
        if frames:
            gui = ti.GUI("diffmpm_simple", res=512, background_color=0xFFFFFF, show_gui=False)
            xs = sim.x.to_numpy()
            snaps = list(range(0, steps, max(1, steps // 6))) + [steps - 1]
            for k, s in enumerate(snaps):  # one picture: the throw, darker as time goes on
                shade = int(0xCC - 0xAA * k / max(len(snaps) - 1, 1))
                gui.circles(xs[s], radius=1.2, color=(shade << 16) | (shade << 8) | 0xFF)
            gui.circle(sim.target.to_numpy(), radius=7, color=0xEE3333)
            gui.show(os.path.join(out, "trajectory.png"))
    return losses, seconds


def main():
    args = parse_args("Optimise the initial velocity of an MPM elastic square", iters=20, steps=512)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "diffmpm_simple")
    losses, sec = train(args.iters, out, steps=args.steps)
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.2f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
