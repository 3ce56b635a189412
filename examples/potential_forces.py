"""Forces from a potential energy, by differentiating it (the DiffTaichi talk's "forces from potential").

A kernel computes only the total potential energy U of a particle system; running it under
`ti.ad.Tape(loss=U)` gives dU/dx in `x.grad`, and the forces are f_i = -dU/dx_i: no force code is written.
The system is `n` equal charges in a 2-D harmonic trap:

    U = sum_i k/2 |x_i - c|^2 + sum_{i<j} q / sqrt(|x_i - x_j|^2 + eps^2)

(a softened Coulomb repulsion, so that close pairs stay finite). The example

1. checks the autodiff forces against the analytic derivative of U (maximum error relative to the largest
   force, printed and returned);
2. runs a small damped simulation from random positions (semi-implicit Euler, forces from the Tape every
   step), written as a GIF: the cloud contracts and oscillates until it settles into a round cluster;
3. minimises U by gradient descent from the same start (x -= lr * dU/dx; the "loss" is the energy), which
   finds the cluster's crystal-like minimum-energy arrangement (concentric rings with a triangular core).

Sizes: 1024 particles (about a million pair terms per energy evaluation, a few ms here forward and backward
together; the talk's example is the Taichi gallery's N-body one, any N works), 300 simulation steps of
dt = 0.05, 200 descent iterations with lr = 0.02. The charge q is chosen so that the equilibrium cluster
has radius about 0.35 (for a 2-D Coulomb cluster in a trap of stiffness k, R = (3 pi n q / (4 k))^(1/3)).

    python examples/potential_forces.py [--iters 200] [--n 1024] [--sim-steps 300] [--out out/potential_forces]
"""

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import finish_gif, out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def build(n: int = 1024, radius: float = 0.35, k: float = 1.0, eps: float = 0.005):
    q = 4 * k * radius**3 / (3 * math.pi * n)
    center = (0.5, 0.5)
    x = ti.Vector.field(2, real, shape=n, needs_grad=True)
    v = ti.Vector.field(2, real, shape=n)
    U = ti.field(real, shape=(), needs_grad=True)

    @ti.kernel
    def compute_energy():
        for i in range(n):
            d = x[i] - ti.Vector(center)
            e = 0.5 * k * d.dot(d)
            for j in range(n):  # each pair is seen twice, hence the factor 1/2
                if i != j:
                    r = x[i] - x[j]
                    e += 0.5 * q / ti.sqrt(r.dot(r) + eps * eps)
            U[None] += e

    @ti.kernel
    def advance(dt: real, damping: real):
        for i in range(n):
            v[i] = ti.exp(-dt * damping) * v[i] - dt * x.grad[i]  # unit masses: a = f = -dU/dx
            x[i] += dt * v[i]

    @ti.kernel
    def descend(lr: real):
        for i in range(n):
            x[i] -= lr * x.grad[i]

    def energy_and_forces():
        """U (a float) and the forces -dU/dx (n x 2 numpy array) at the current positions."""
        with ti.ad.Tape(loss=U):
            compute_energy()
        return float(U[None]), -x.grad.to_numpy()

    def analytic_forces(p):
        """The same forces by hand, in float64 numpy."""
        p = p.astype(np.float64)
        r = p[:, None, :] - p[None, :, :]
        s = (r**2).sum(-1) + eps * eps
        coulomb = q * r / s[..., None] ** 1.5  # on i from j; the diagonal has r = 0
        return -k * (p - np.array(center)) + coulomb.sum(1)

    def analytic_energy(p):
        p = p.astype(np.float64)
        r = p[:, None, :] - p[None, :, :]
        inv = 1 / np.sqrt((r**2).sum(-1) + eps * eps)
        np.fill_diagonal(inv, 0)
        return 0.5 * k * ((p - np.array(center)) ** 2).sum() + 0.5 * q * inv.sum()

    def reset(seed: int = 0):
        rng = np.random.RandomState(seed)
        x.from_numpy((0.2 + 0.6 * rng.rand(n, 2)).astype(np.float32))
        v.fill(0)

    return type("Sim", (), dict(locals()))


def force_error(sim) -> float:
    """Largest deviation of the autodiff forces from the analytic ones, relative to the largest force."""
    u, f = sim.energy_and_forces()
    f_ref = sim.analytic_forces(sim.x.to_numpy())
    u_ref = sim.analytic_energy(sim.x.to_numpy())
    assert abs(u - u_ref) <= 1e-4 * abs(u_ref), (u, u_ref)
    return float(np.abs(f - f_ref).max() / np.abs(f_ref).max())


def _colors(f):
    """Blue (weak force) to red (strong) per particle."""
    m = np.linalg.norm(f, axis=1)
    s = np.clip(m / (np.percentile(m, 95) + 1e-12), 0, 1)
    return ((60 + 190 * s).astype(np.int64) << 16) + (80 << 8) + (230 - 190 * s).astype(np.int64)


def simulate(sim, steps: int, out: str | None, dt: float = 0.05, damping: float = 0.3, every: int = 5):
    """Damped dynamics with autodiff forces; frames (GIF and a few PNGs) go to `out`. Returns the energies."""
    gui = video = None
    if out is not None:
        gui = ti.GUI("potential_forces", res=512, background_color=0x112233, show_gui=False)
        video = ti.tools.VideoManager(out, video_filename="simulation", framerate=20, automatic_build=False)
    energies = []
    stills = {0, steps // 8 // every * every, steps // 2 // every * every}
    for t in range(steps + 1):
        u, f = sim.energy_and_forces()  # fills x.grad, which advance() reads
        energies.append(u)
        if gui is not None and t % every == 0:
            gui.circles(sim.x.to_numpy(), radius=2.5, color=_colors(f))
            gui.text(f"step {t}  U = {u:.4f}", (0.02, 0.98), font_size=16, color=0xFFFFFF)
            video.write_frame(gui.get_image())
            gui.show(os.path.join(out, f"simulation_{t:04d}.png") if t in stills else None)
        if t < steps:
            sim.advance(dt, damping)
    if video is not None:
        finish_gif(video)
    return energies


def train(iters: int, out: str | None, n: int = 1024, sim_steps: int = 300, lr: float = 0.02, seed: int = 0):
    """Check forces, simulate, then minimise U by gradient descent; returns (energies, seconds per iteration)."""
    sim = build(n)
    sim.reset(seed)
    t0 = time.time()
    train.force_error = force_error(sim)  # the first Tape run: compiles compute_energy and its adjoint
    train.first_forces_seconds = time.time() - t0
    train.sim_energies = simulate(sim, sim_steps, out) if sim_steps > 0 else []
    sim.reset(seed)
    losses = []
    t0 = time.time()
    for _ in progress(iters, "potential_forces"):
        with ti.ad.Tape(loss=sim.U):
            sim.compute_energy()
        losses.append(float(sim.U[None]))
        sim.descend(lr)
        if len(losses) == 1:
            train.first_seconds = time.time() - t0  # includes compiling the kernels
    seconds = (time.time() - t0) / max(iters, 1)
    train.force_error_final = force_error(sim)
    train.sim = sim
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), "potential_forces: potential energy U")
        u, f = sim.energy_and_forces()
        gui = ti.GUI("potential_forces", res=512, background_color=0x112233, show_gui=False)
        gui.circles(sim.x.to_numpy(), radius=2.5, color=0x66CCFF)
        gui.text(f"gradient descent, {iters} iterations  U = {u:.4f}", (0.02, 0.98), font_size=16, color=0xFFFFFF)
        gui.show(os.path.join(out, "minimum.png"))
    return losses, seconds


def main():
    args = parse_args("Forces as -dU/dx through autodiff; simulate, and minimise U", iters=200, n=1024, sim_steps=300)
    # Taichi sizes the reverse-mode stack of the inner j loop from ad_stack_size (it crashes without it)
    ti.init(arch=ti.cpu, default_fp=real, ad_stack_size=2 * args.n + 64)
    out = out_dir(args.out, "potential_forces")
    losses, sec = train(args.iters, out, n=args.n, sim_steps=args.sim_steps)
    print(f"forces vs analytic: max error {train.force_error:.2e} (start), {train.force_error_final:.2e} (end) "
          f"of the largest force")
    if train.sim_energies:
        print(f"simulation: U {train.sim_energies[0]:.5f} -> {train.sim_energies[-1]:.5f} in "
              f"{len(train.sim_energies) - 1} steps")
    print(f"gradient descent: U {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations "
          f"({sec:.4f} s/iteration); pictures in {out}")
    print(f"the first energy and forces took {train.first_forces_seconds:.2f} s (compilation included)")


if __name__ == "__main__":
    main()
