"""Mass-spring robots that learn to walk (DiffTaichi's mass_spring experiment, written from the paper).

A robot is a 2-D lattice of point masses joined by stiff springs; some springs are "muscles" whose rest
length is scaled by (1 + a * act(t)) with act(t) in [-1, 1]. The actuation comes from a small neural
network controller: an open-loop one, whose inputs are `n_sin_waves` phase-shifted sine waves of time,
one tanh hidden layer of `n_hidden` units, and one tanh output per spring. The whole episode is simulated
with every step stored (x[t, i], v[t, i]) and the controller's weights are trained with gradients from
`ti.ad.Tape`. The loss is minus the distance the robot's centre of mass travels in +x during the episode.

Physics: springs act through velocity impulses (Hooke's law on the actuated rest length), gravity,
exponential damping, and a ground at y = 0.1 with full friction; contacts are resolved at the time of
impact inside a step (TOI). `--no-toi` switches to a plain projection at the start of the step, whose
gradients are much worse: with it robots 1 and 2 do not learn to move forward in 100 iterations.

Robots (`--robot`): 1 = a small two-legged robot on triangular feet, 2 = two square legs under a body with
a tall neck (nine squares), 3 = robot 2 with a third leg in front (twelve squares); these are the paper's
robots 1-3: lattice spacing 0.05, spring stiffness 3e4, muscles are the vertical edges of the marked squares
with a = 0.15.

Sizes are the paper's: dt = 0.004, 682 steps per episode (doubled in --test), 10 sine inputs of angular
frequency 10, 32 hidden units, 100 iterations; each iteration moves the weights a fixed distance 0.2 along
the negative normalised gradient. Since the controller is open-loop it does not depend on the state, so all
of its outputs are computed by one kernel before the simulation rather than once per step (the same numbers,
far fewer kernel launches). One iteration takes about 0.06-0.1 s here (forward and backward).

    python examples/mass_spring.py [--robot 2] [--iters 100] [--out out/mass_spring/robot2]
    python examples/mass_spring.py --robot 2 --test   # reload the trained controller, run twice as long
"""

import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import finish_gif, out_dir, plot_losses, progress  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32

GROUND = 0.1
SPACING = 0.05
STIFFNESS = 3e4
MUSCLE = 0.15


class RobotShape:
    """Lattice robot made of squares (4 corners, all 6 pairs joined) and triangles (3 corners)."""

    def __init__(self):
        self.index = {}  # lattice coordinates -> particle id
        self.points = []
        self.springs = {}  # frozenset(a, b) -> (a, b, actuation); the first spring added for a pair stays

    def point(self, u, v):
        key = (float(u), float(v))
        if key not in self.index:
            self.index[key] = len(self.points)
            self.points.append((0.1 + SPACING * key[0], GROUND + SPACING * key[1]))
        return self.index[key]

    def spring(self, a, b, actuation=0.0):
        self.springs.setdefault(frozenset((a, b)), (a, b, actuation))

    def square(self, i, j, muscle=False):
        ll, ul, lr, ur = self.point(i, j), self.point(i, j + 1), self.point(i + 1, j), self.point(i + 1, j + 1)
        act = MUSCLE if muscle else 0.0
        self.spring(ll, ul, act)  # the two vertical edges are the muscles
        self.spring(lr, ur, act)
        corners = (ll, ul, lr, ur)
        for p in range(4):
            for q in range(p + 1, 4):
                self.spring(corners[p], corners[q])

    def triangle(self, i, j):
        c = (self.point(i + 0.5, j + 0.5), self.point(i, j + 1), self.point(i + 1, j + 1))
        for p in range(3):
            for q in range(p + 1, 3):
                self.spring(c[p], c[q])

    def arrays(self):
        pts = np.array(self.points, dtype=np.float64)
        sp = list(self.springs.values())
        a = np.array([s[0] for s in sp], dtype=np.int32)
        b = np.array([s[1] for s in sp], dtype=np.int32)
        rest = np.linalg.norm(pts[a] - pts[b], axis=1)
        act = np.array([s[2] for s in sp], dtype=np.float64)
        return pts, a, b, rest, act


def robot(robot_id: int) -> RobotShape:
    r = RobotShape()
    if robot_id == 1:
        r.triangle(0, 0)
        r.triangle(2, 0)
        for i, j, m in ((0, 1, True), (0, 2, False), (1, 2, False), (2, 1, True), (2, 2, False)):
            r.square(i, j, m)
    else:
        squares = [(2, 0, True), (0, 0, True), (0, 1, True), (0, 2, False), (1, 2, False), (2, 1, True),
                   (2, 2, False), (2, 3, False), (2, 4, False)]
        if robot_id == 3:
            squares += [(3, 1, False), (4, 0, True), (4, 1, True)]
        elif robot_id != 2:
            raise ValueError(f"robot must be 1, 2 or 3, not {robot_id}")
        for i, j, m in squares:
            r.square(i, j, m)
    return r


def build(robot_id: int = 2, steps: int = 682, n_hidden: int = 32, n_sin_waves: int = 10, toi: bool = True):
    """Fields and kernels of one robot; the episode has `steps` steps, fields hold twice that (test mode)."""
    pts, anchor_a_np, anchor_b_np, rest_np, act_np = robot(robot_id).arrays()
    n_objects, n_springs = len(pts), len(rest_np)
    max_steps = 2 * steps
    dt = 0.004
    gravity = -4.8
    damping = 15.0
    omega = 10.0

    x = ti.Vector.field(2, real, shape=(max_steps, n_objects), needs_grad=True)
    v = ti.Vector.field(2, real, shape=(max_steps, n_objects), needs_grad=True)
    v_inc = ti.Vector.field(2, real, shape=(max_steps, n_objects), needs_grad=True)
    anchor_a = ti.field(ti.i32, shape=n_springs)
    anchor_b = ti.field(ti.i32, shape=n_springs)
    rest_length = ti.field(real, shape=n_springs)
    stiffness = ti.field(real, shape=n_springs)
    actuation = ti.field(real, shape=n_springs)
    weights1 = ti.field(real, shape=(n_hidden, n_sin_waves), needs_grad=True)
    bias1 = ti.field(real, shape=n_hidden, needs_grad=True)
    weights2 = ti.field(real, shape=(n_springs, n_hidden), needs_grad=True)
    bias2 = ti.field(real, shape=n_springs, needs_grad=True)
    hidden = ti.field(real, shape=(max_steps, n_hidden), needs_grad=True)
    act = ti.field(real, shape=(max_steps, n_springs), needs_grad=True)
    loss = ti.field(real, shape=(), needs_grad=True)
    params = (weights1, bias1, weights2, bias2)

    @ti.kernel
    def controller(n: ti.i32):
        # open loop: the network sees only sine waves of time, so every step's actuation is known upfront
        for t, i in ti.ndrange(n, n_hidden):
            s = bias1[i]
            for j in ti.static(range(n_sin_waves)):
                s += weights1[i, j] * ti.sin(omega * dt * t + 2 * math.pi * j / n_sin_waves)
            hidden[t, i] = ti.tanh(s)
        for t, i in ti.ndrange(n, n_springs):
            s = bias2[i]
            for j in ti.static(range(n_hidden)):
                s += weights2[i, j] * hidden[t, j]
            act[t, i] = ti.tanh(s)

    @ti.kernel
    def apply_spring_force(t: ti.i32):
        for k in range(n_springs):
            a = anchor_a[k]
            b = anchor_b[k]
            d = x[t, a] - x[t, b]
            length = d.norm() + 1e-4
            target = rest_length[k] * (1.0 + actuation[k] * act[t, k])
            impulse = (dt * stiffness[k] * (length - target) / length) * d
            v_inc[t + 1, a] -= impulse
            v_inc[t + 1, b] += impulse

    @ti.kernel
    def advance(t: ti.i32):
        for i in range(n_objects):
            vel = ti.exp(-dt * damping) * v[t - 1, i] + v_inc[t, i] + ti.Vector([0.0, dt * gravity])
            pos = x[t - 1, i]
            toi_time = 0.0
            keep = 1.0  # 0 after a contact: full friction, the particle sticks
            if ti.static(toi):
                if pos[1] + dt * vel[1] < GROUND and vel[1] < -1e-4:
                    toi_time = -(pos[1] - GROUND) / vel[1]  # move freely until the impact, then stick
                    keep = 0.0
            else:
                if pos[1] < GROUND and vel[1] < 0:
                    keep = 0.0
            v[t, i] = keep * vel
            x[t, i] = pos + (toi_time + keep * (dt - toi_time)) * vel

    @ti.kernel
    def compute_loss(t: ti.i32):
        for i in range(n_objects):
            loss[None] -= (x[t, i][0] - x[0, i][0]) / n_objects

    def setup():
        xs = np.zeros((max_steps, n_objects, 2), dtype=np.float32)
        xs[0] = pts
        x.from_numpy(xs)
        v.fill(0)
        anchor_a.from_numpy(anchor_a_np)
        anchor_b.from_numpy(anchor_b_np)
        rest_length.from_numpy(rest_np.astype(np.float32))
        stiffness.fill(STIFFNESS)
        actuation.from_numpy(act_np.astype(np.float32))

    def init_weights(seed: int = 0):
        rng = np.random.RandomState(seed)
        w1 = rng.randn(n_hidden, n_sin_waves) * math.sqrt(2 / (n_hidden + n_sin_waves)) * 2
        w2 = rng.randn(n_springs, n_hidden) * math.sqrt(2 / (n_hidden + n_springs)) * 3
        weights1.from_numpy(w1.astype(np.float32))
        weights2.from_numpy(w2.astype(np.float32))
        bias1.fill(0)
        bias2.fill(0)

    def forward(n: int = steps):
        v_inc.fill(0)
        controller(n)
        for t in range(1, n):
            apply_spring_force(t - 1)
            advance(t)
        compute_loss(n - 1)

    def step_weights(lr: float):
        """Move the weights by `lr` along the negative normalised gradient; returns the gradient norm."""
        grads = [p.grad.to_numpy() for p in params]
        norm = math.sqrt(sum(float((g.astype(np.float64) ** 2).sum()) for g in grads))
        for p, g in zip(params, grads):
            p.from_numpy((p.to_numpy() - (lr / (norm + 1e-6)) * g).astype(np.float32))
        return norm

    def save(path):
        np.savez(path, **{name: p.to_numpy() for name, p in zip(("w1", "b1", "w2", "b2"), params)})

    def load(path):
        data = np.load(path)
        for name, p in zip(("w1", "b1", "w2", "b2"), params):
            p.from_numpy(data[name])

    return type("Sim", (), dict(locals()))


def draw(sim, n: int, out: str, name: str, every: int = 10, pngs: int = 6):
    """Frames of the last simulated episode: a GIF of every `every`-th step, and `pngs` PNG stills."""
    xs = sim.x.to_numpy()[:n]
    acts = sim.act.to_numpy()[:n]
    muscle = sim.act_np != 0
    gui = ti.GUI("mass_spring", res=512, background_color=0xFFFFFF, show_gui=False)
    video = ti.tools.VideoManager(out, video_filename=name, framerate=30, automatic_build=False)
    stills = set(np.linspace(0, n - 1, pngs).astype(int) // every * every)
    shift = 0.0
    for t in range(0, n, every):
        # keep the robot in view: scroll the picture when its centre leaves the middle
        shift = max(shift, xs[t, :, 0].mean() - 0.5)
        p = xs[t] - np.array([shift, 0.0])
        gui.line((0, GROUND), (1, GROUND), radius=2, color=0x222222)
        marks = (np.arange(12) + np.floor(shift * 10)) * 0.1 - shift  # ground marks 0.1 apart show the motion
        gui.lines(np.stack([marks, np.full(12, GROUND)], 1), np.stack([marks - 0.03, np.full(12, GROUND - 0.03)], 1),
                  radius=1, color=0x666666)
        a = np.clip(acts[t] * 0.5, -0.5, 0.5)
        red = np.where(muscle, 0.5 + a, 0.13)
        green = np.where(muscle, 0.5 - np.abs(a), 0.13)
        blue = np.where(muscle, 0.5 - a, 0.13)
        colors = (np.clip(red, 0, 1) * 255).astype(np.int64) * 65536 + (np.clip(green, 0, 1) * 255).astype(
            np.int64) * 256 + (np.clip(blue, 0, 1) * 255).astype(np.int64)
        gui.lines(p[sim.anchor_a_np], p[sim.anchor_b_np], radius=np.where(muscle, 3, 1.5), color=colors)
        gui.circles(p, radius=5, color=0x66AA99)
        gui.text(f"t = {t}  distance = {xs[t, :, 0].mean() - xs[0, :, 0].mean():.3f}", (0.02, 0.97),
                 font_size=18, color=0x000000)
        video.write_frame(gui.get_image())
        gui.show(os.path.join(out, f"{name}_{t:04d}.png") if t in stills else None)
    finish_gif(video)


def train(iters: int, out: str | None, robot_id: int = 2, steps: int = 682, lr: float = 0.2, n_hidden: int = 32,
          toi: bool = True, frames: bool = True, frame_every: int = 10):
    """Train the controller; returns (losses, seconds per iteration) and leaves the sim in `train.sim`."""
    sim = build(robot_id, steps, n_hidden=n_hidden, toi=toi)
    sim.setup()
    sim.init_weights(0)
    losses = []
    t0 = time.time()
    for _ in progress(iters, f"mass_spring robot {robot_id}"):
        with ti.ad.Tape(loss=sim.loss):
            sim.forward()
        losses.append(float(sim.loss[None]))
        sim.step_weights(lr)
        if len(losses) == 1:
            train.first_seconds = time.time() - t0  # includes compiling the kernels
    seconds = (time.time() - t0) / max(iters, 1)
    train.sim = sim
    if out is not None:
        sim.save(os.path.join(out, f"controller_robot{robot_id}.npz"))
        plot_losses(losses, os.path.join(out, "loss.png"), f"mass_spring robot {robot_id}: -(distance moved)")
        if frames:
            sim.forward()  # the episode of the trained controller
            draw(sim, steps, out, f"robot{robot_id}_trained", every=frame_every)
    return losses, seconds


def test(out: str, robot_id: int = 2, steps: int = 682, n_hidden: int = 32, toi: bool = True,
         frame_every: int = 10) -> float:
    """Run the saved controller for twice the training episode (no optimisation); returns the distance."""
    sim = build(robot_id, steps, n_hidden=n_hidden, toi=toi)
    sim.setup()
    sim.load(os.path.join(out, f"controller_robot{robot_id}.npz"))
    sim.loss[None] = 0
    sim.forward(2 * steps)
    draw(sim, 2 * steps, out, f"robot{robot_id}_test", every=frame_every)
    return -float(sim.loss[None])


def main():
    p = argparse.ArgumentParser(description="Train an open-loop NN controller for a mass-spring robot")
    p.add_argument("--iters", type=int, default=100, help="optimisation iterations")
    p.add_argument("--out", default=None, help="output folder for frames and plots")
    p.add_argument("--robot", type=int, default=2, choices=(1, 2, 3))
    p.add_argument("--steps", type=int, default=682, help="simulation steps per training episode")
    p.add_argument("--test", action="store_true", help="run the saved controller for 2x steps, no training")
    p.add_argument("--no-toi", action="store_true", help="plain contact projection instead of time of impact")
    args = p.parse_args()
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, f"mass_spring/robot{args.robot}")
    weights = os.path.join(out, f"controller_robot{args.robot}.npz")
    if args.test:
        if not os.path.exists(weights):
            print(f"no trained controller in {weights}: training one first ({args.iters} iterations)")
            train(args.iters, out, args.robot, args.steps, toi=not args.no_toi, frames=False)
        dist = test(out, args.robot, args.steps, toi=not args.no_toi)
        print(f"robot {args.robot} moved {dist:.4f} in {2 * args.steps} steps; pictures in {out}")
        return
    losses, sec = train(args.iters, out, args.robot, args.steps, toi=not args.no_toi)
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} (best {min(losses):.5f}) in {len(losses)} iterations "
          f"({sec:.3f} s/iteration, the first {train.first_seconds:.2f} s with compilation); pictures in {out}")


if __name__ == "__main__":
    main()
