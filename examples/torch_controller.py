"""A torch MLP learns to make a simgrad mass-spring robot walk (the torch bridge, issue 24).

The simulation is ordinary simgrad kernels over ndarray arguments (spring forces, semi-implicit Euler,
ground contact with friction); one time step is a `@simgrad.torch.function` taking the state tensors and
the actuation, so the controller closes the loop: at every step a torch MLP reads the state (positions and
velocities relative to the centre, a clock) and sets the actuated springs' target lengths. The loss, the
distance the centre moved to the right, negated, is computed in torch; `loss.backward()` runs torch's
backward through the MLP and the bridge's through the kernels' adjoints, and a torch optimiser (Adam)
updates the network.

    python examples/torch_controller.py [--iters 60] [--steps 300] [--out out/torch_controller]
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402

# the robot: a 2 x 4 grid of particles, springs along the grid and its diagonals; the horizontal and
# diagonal springs are muscles (their rest length scales by 1 + 0.25 * actuation)
ROWS, COLS, SPACING = 2, 4, 0.05
DT, DAMPING, STIFFNESS, GRAVITY, GROUND, FRICTION = 0.004, 6.0, 400.0, -4.8, 0.1, 0.6


def robot():
    pos = [(0.1 + c * SPACING, GROUND + 0.001 + r * SPACING) for r in range(ROWS) for c in range(COLS)]
    springs, muscles = [], []

    def idx(r, c):
        return r * COLS + c

    for r in range(ROWS):
        for c in range(COLS):
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
                r2, c2 = r + dr, c + dc
                if 0 <= r2 < ROWS and 0 <= c2 < COLS:
                    muscles.append(len(springs) if (dr, dc) != (1, 0) else -1)
                    springs.append((idx(r, c), idx(r2, c2)))
    n_act = sum(m >= 0 for m in muscles)
    act_index, k = [], 0
    for m in muscles:
        act_index.append(k if m >= 0 else -1)
        k += m >= 0
    return np.array(pos), np.array(springs, dtype=np.int32), np.array(act_index, dtype=np.int32), n_act


def build():
    import torch

    pos0, springs, act_index, n_act = robot()
    n, m = len(pos0), len(springs)
    a = ti.field(ti.i32, shape=m)
    b = ti.field(ti.i32, shape=m)
    act_of = ti.field(ti.i32, shape=m)
    rest = ti.field(ti.f32, shape=m)
    a.from_numpy(springs[:, 0])
    b.from_numpy(springs[:, 1])
    act_of.from_numpy(act_index)
    rest.from_numpy(np.linalg.norm(pos0[springs[:, 0]] - pos0[springs[:, 1]], axis=1).astype(np.float32))

    @ti.kernel
    def spring_forces(x: ti.types.ndarray(dtype=ti.math.vec2, ndim=1), act: ti.types.ndarray(dtype=ti.f32, ndim=1),
                      f: ti.types.ndarray(dtype=ti.math.vec2, ndim=1)):
        for s in range(m):
            d = x[a[s]] - x[b[s]]
            length = d.norm() + 1e-6
            target = rest[s]
            if act_of[s] >= 0:
                target = rest[s] * (1.0 + 0.25 * act[act_of[s]])
            force = -STIFFNESS * (length - target) / length * d
            f[a[s]] += force
            f[b[s]] -= force

    @ti.kernel
    def advance(x: ti.types.ndarray(dtype=ti.math.vec2, ndim=1), v: ti.types.ndarray(dtype=ti.math.vec2, ndim=1),
                f: ti.types.ndarray(dtype=ti.math.vec2, ndim=1), x1: ti.types.ndarray(dtype=ti.math.vec2, ndim=1),
                v1: ti.types.ndarray(dtype=ti.math.vec2, ndim=1)):
        for i in range(n):
            nv = ti.exp(-DT * DAMPING) * v[i] + DT * (f[i] + ti.Vector([0.0, GRAVITY]))
            nx = x[i] + DT * nv
            if nx[1] < GROUND:  # ground: stop the fall, friction on the slide
                nx = ti.Vector([x[i][0] + DT * nv[0] * (1.0 - FRICTION), GROUND])
                nv = ti.Vector([nv[0] * (1.0 - FRICTION), 0.0])
            x1[i] = nx
            v1[i] = nv

    @ti.torch.function
    def step(x, v, act):
        f = torch.zeros_like(x)
        spring_forces(x, act, f)
        x1, v1 = torch.empty_like(x), torch.empty_like(v)
        advance(x, v, f, x1, v1)
        return x1, v1

    return step, torch.tensor(pos0, dtype=torch.float32), n_act


def make_controller(n_particles: int, n_act: int, hidden: int, seed: int):
    import torch

    torch.manual_seed(seed)
    return torch.nn.Sequential(torch.nn.Linear(4 * n_particles + 2, hidden), torch.nn.Tanh(),
                               torch.nn.Linear(hidden, n_act), torch.nn.Tanh())


def rollout(step, controller, x0, steps: int, keep: bool = False):
    """The distance the centre moved right (a torch scalar) and, with `keep`, the positions over time."""
    import torch

    x, v = x0, torch.zeros_like(x0)
    frames = []
    for t in range(steps):
        centre = x.mean(0)
        phase = torch.tensor([np.sin(t * DT * 20.0), np.cos(t * DT * 20.0)], dtype=torch.float32)
        state = torch.cat([(x - centre).reshape(-1) * 10.0, v.reshape(-1), phase])
        x, v = step(x, v, controller(state))
        if keep:
            frames.append(x.detach().numpy().copy())
    return x.mean(0)[0] - x0.mean(0)[0], frames


def train(iters: int, out: str | None, steps: int = 300, hidden: int = 32, lr: float = 0.005, seed: int = 0):
    import torch

    step, x0, n_act = build()
    controller = make_controller(len(x0), n_act, hidden, seed)
    opt = torch.optim.Adam(controller.parameters(), lr=lr)
    losses = []
    t0 = time.time()
    for _ in progress(iters, "torch_controller"):
        opt.zero_grad()
        dist, _ = rollout(step, controller, x0, steps)
        loss = -dist
        loss.backward()
        torch.nn.utils.clip_grad_norm_(controller.parameters(), 1.0)  # contact makes a few gradients spike
        opt.step()
        losses.append(loss.item())
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), "torch_controller: -(distance moved right)")
        with torch.no_grad():
            _, frames = rollout(step, controller, x0, steps, keep=True)
        _, springs, _, _ = robot()
        gui = ti.GUI("torch_controller", res=512, background_color=0xFFFFFF, show_gui=False)
        for t in range(0, steps, max(1, steps // 6)):
            xs = frames[t]
            gui.line((0.0, GROUND), (1.0, GROUND), radius=2, color=0x888888)
            for i, j in springs:
                gui.line(xs[i], xs[j], radius=2, color=0x444444)
            gui.circles(xs, radius=5, color=0x3366CC)
            gui.show(os.path.join(out, f"frame_{t:04d}.png"))
    return losses, seconds


def main():
    args = parse_args("Train a torch MLP controller through a simgrad mass-spring simulation", iters=60, steps=300)
    ti.init(arch=ti.cpu)
    out = out_dir(args.out, "torch_controller")
    losses, sec = train(args.iters, out, steps=args.steps)
    print(f"loss {losses[0]:.4f} -> {losses[-1]:.4f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
