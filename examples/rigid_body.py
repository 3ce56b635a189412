"""Differentiable 2-D rigid-body robots (DiffTaichi's rigid_body, written from the paper's description).

A robot is a few boxes joined by springs. Some springs are actuated: a closed-loop neural-network controller
(one hidden layer of tanh units; inputs: a bank of phase-shifted sine waves and every box's position relative
to the body, velocity, angle and angular velocity) sets each actuated spring's target length at every step.
Joints are zero-length stiff springs whose impulse also removes the relative velocity of the two anchors.
Box corners hit the ground through impulses (no bounce, Coulomb friction) with the time-of-impact (TOI)
correction the paper describes: a corner that reaches the ground within a step takes its impulse at the moment
of contact, not at the end of the step (so the state is continuous in the parameters and gradients are
useful), plus a small penalty impulse against sinking. We optimise the controller's weights by gradient
descent (gradient norm clipped) so that the robot's body moves as far right as possible in `steps` steps:
loss = -(x_final - x_initial) of the body.

All state is kept per step (x[t, i], v[t, i], angle, angular velocity, and the per-step impulses), as the
global data access rules of the reverse pass require.

Robots (--robot): 0, a plank on three feet, each foot tied to the plank by two actuated springs (the paper's
robot A without its flag); 1, a body on two legs hinged at joints and pulled by actuated springs (the
paper's robot B). Sizes: the paper's: 2048 steps of dt = 0.001, 32 hidden units, 10 sine inputs, 20
iterations with learning rate 1 and gradient norm clipped to 0.2 (a fraction of a second per iteration
here, so no reduction is needed).

    python examples/rigid_body.py [--iters 20] [--out out/rigid_body] [--steps 2048] [--robot 0] [--toi 1]
"""

import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import out_dir, parse_args, plot_losses, progress, write_gif  # noqa: E402

import simgrad as ti  # noqa: E402

real = ti.f32


def robot_boxes(robot: int):
    """(boxes, springs, body index): box = (centre, half size, angle); spring = (box a, box b, anchor offset
    in a's frame, anchor offset in b's frame, rest length or None for a joint, stiffness, actuation)."""
    boxes, springs = [], []
    if robot == 0:
        boxes.append(((0.3, 0.25), (0.15, 0.03), 0.0))
        for fx in (0.2, 0.3, 0.4):
            boxes.append(((fx, 0.15), (0.03, 0.02), 0.0))
        # each foot hangs from two points of the plank
        for foot, (oa, ob) in zip((1, 2, 3), ((-0.1, -0.03), (-0.03, 0.03), (0.03, 0.1))):
            springs.append((0, foot, (oa, 0.0), (0.0, 0.0), 0.12, 15.0, 0.05))
            springs.append((0, foot, (ob, 0.0), (0.0, 0.0), 0.12, 15.0, 0.05))
        return boxes, springs, 0
    if robot == 1:
        boxes.append(((0.15, 0.25), (0.1, 0.03), 0.0))
        boxes.append(((0.08, 0.22), (0.03, 0.1), 0.0))
        boxes.append(((0.22, 0.22), (0.03, 0.1), 0.0))
        # a muscle from the far side of the body to the foot of each leg, and a hinge at the leg's top
        springs.append((0, 1, (0.08, 0.02), (0.0, -0.08), 0.22, 50.0, 0.03))
        springs.append((0, 2, (-0.08, 0.02), (0.0, -0.08), 0.22, 50.0, 0.03))
        springs.append((0, 1, (-0.08, 0.0), (0.0, 0.03), None, 50.0, 0.0))
        springs.append((0, 2, (0.08, 0.0), (0.0, 0.03), None, 50.0, 0.0))
        return boxes, springs, 0
    raise ValueError(f"no robot {robot} (0 or 1)")


def build(robot: int = 0, steps: int = 2048, dt: float = 0.001, n_hidden: int = 32, n_sin: int = 10,
          use_toi: bool = True):
    """Allocate the fields and kernels of one robot; returns a namespace of them. use_toi=False drops the
    time-of-impact correction of ground contacts (for the paper's comparison)."""
    boxes, springs, body = robot_boxes(robot)
    n_boxes, n_springs = len(boxes), len(springs)
    n_inputs = n_sin + 6 * n_boxes
    ground = 0.1
    gravity = -9.8
    friction = 1.0
    penalty = 1e4
    damping = 10.0
    sin_omega = 30.0

    def vec():
        return ti.Vector.field(2, real, shape=(steps, n_boxes), needs_grad=True)

    def scal(*shape):
        return ti.field(real, shape=shape, needs_grad=True)

    x, v, x_inc, v_inc = vec(), vec(), vec(), vec()
    angle, omega = scal(steps, n_boxes), scal(steps, n_boxes)
    angle_inc, omega_inc = scal(steps, n_boxes), scal(steps, n_boxes)
    half = ti.Vector.field(2, real, shape=n_boxes)
    inv_mass = ti.field(real, shape=n_boxes)
    inv_inertia = ti.field(real, shape=n_boxes)

    box_a = ti.field(ti.i32, shape=n_springs)
    box_b = ti.field(ti.i32, shape=n_springs)
    offset_a = ti.Vector.field(2, real, shape=n_springs)
    offset_b = ti.Vector.field(2, real, shape=n_springs)
    rest = ti.field(real, shape=n_springs)
    joint = ti.field(ti.i32, shape=n_springs)
    stiffness = ti.field(real, shape=n_springs)
    amplitude = ti.field(real, shape=n_springs)

    w1 = scal(n_hidden, n_inputs)
    b1 = scal(n_hidden)
    w2 = scal(n_springs, n_hidden)
    b2 = scal(n_springs)
    hidden = scal(steps, n_hidden)
    act = scal(steps, n_springs)
    loss = ti.field(real, shape=(), needs_grad=True)

    @ti.func
    def cross2(a, b):
        return a[0] * b[1] - a[1] * b[0]

    @ti.func
    def world(t, i, local):
        """World position and velocity of a point given in box i's frame, and its offset from the centre."""
        c, s = ti.cos(angle[t, i]), ti.sin(angle[t, i])
        r = ti.Vector([c * local[0] - s * local[1], s * local[0] + c * local[1]])
        return x[t, i] + r, v[t, i] + omega[t, i] * ti.Vector([-r[1], r[0]]), r

    @ti.func
    def push(t, i, impulse, r, toi):
        """Apply an impulse at offset r of box i during step t; toi (in [0, dt]) is when it happens."""
        dv = impulse * inv_mass[i]
        dw = cross2(r, impulse) * inv_inertia[i]
        v_inc[t + 1, i] += dv
        omega_inc[t + 1, i] += dw
        # with the old velocity until toi and the new one afterwards, the end position is short by toi * dv
        x_inc[t + 1, i] += -toi * dv
        angle_inc[t + 1, i] += -toi * dw

    @ti.kernel
    def mass_properties():
        for i in range(n_boxes):
            area = 4 * half[i][0] * half[i][1]
            inv_mass[i] = 1.0 / area
            inv_inertia[i] = 1.0 / (area / 3 * (half[i][0] ** 2 + half[i][1] ** 2))

    @ti.kernel
    def clear_impulses():
        for t, i in angle_inc:
            x_inc[t, i] = ti.Vector([0.0, 0.0])
            v_inc[t, i] = ti.Vector([0.0, 0.0])
            angle_inc[t, i] = 0.0
            omega_inc[t, i] = 0.0

    @ti.kernel
    def controller_hidden(t: ti.i32):
        for k in range(n_hidden):
            a = b1[k]
            for j in ti.static(range(n_sin)):
                a += w1[k, j] * ti.sin(sin_omega * dt * t + 2 * math.pi / n_sin * j)
            for i in ti.static(range(n_boxes)):
                rel = x[t, i] - x[t, body]
                m = n_sin + 6 * i
                a += 0.05 * (w1[k, m] * rel[0] + w1[k, m + 1] * rel[1] + w1[k, m + 2] * v[t, i][0]
                             + w1[k, m + 3] * v[t, i][1] + w1[k, m + 4] * angle[t, i]
                             + w1[k, m + 5] * omega[t, i])
            hidden[t, k] = ti.tanh(a)

    @ti.kernel
    def controller_out(t: ti.i32):
        for s in range(n_springs):
            a = b2[s]
            for k in ti.static(range(n_hidden)):
                a += w2[s, k] * hidden[t, k]
            act[t, s] = ti.tanh(a)

    @ti.kernel
    def ground_contact(t: ti.i32):
        for i in range(n_boxes):
            for k in ti.static(range(4)):
                corner = ti.Vector([k % 2 * 2 - 1, k // 2 * 2 - 1]) * half[i]
                p, corner_v, r = world(t, i, corner)
                pv = corner_v + ti.Vector([0.0, dt * gravity])  # its velocity after this step's gravity
                p_end = p + dt * pv
                k_n = inv_mass[i] + cross2(r, ti.Vector([0.0, 1.0])) ** 2 * inv_inertia[i]
                k_t = inv_mass[i] + cross2(r, ti.Vector([1.0, 0.0])) ** 2 * inv_inertia[i]
                jn = 0.0
                jt = 0.0
                toi = 0.0
                if p_end[1] < ground and pv[1] < 0:
                    jn = -pv[1] / k_n  # stop the corner's fall (no bounce)
                    jt = ti.min(ti.max(-pv[0] / k_t, -friction * jn), friction * jn)
                    if ti.static(use_toi):
                        if p[1] > ground:  # it reaches the ground during this step
                            toi = ti.min((p[1] - ground) / -pv[1], dt)
                push(t, i, ti.Vector([jt, jn]), r, toi)
                if p_end[1] < ground:  # a little push out of the ground against drift
                    push(t, i, ti.Vector([0.0, dt * penalty * (ground - p_end[1]) / k_n]), r, 0.0)

    @ti.kernel
    def spring_forces(t: ti.i32):
        for s in range(n_springs):
            a = box_a[s]
            b = box_b[s]
            pa, va, ra = world(t, a, offset_a[s])
            pb, vb, rb = world(t, b, offset_b[s])
            d = pa - pb
            length = d.norm() + 1e-4
            target = rest[s] * (1.0 + amplitude[s] * act[t, s])
            if joint[s]:
                target = 0.0
            j = dt * stiffness[s] * (length - target) / length * d
            if joint[s]:
                # also cancel the anchors' relative velocity
                dv = va - vb
                speed = dv.norm() + 0.1
                n = dv / speed
                k_eff = inv_mass[a] + cross2(n, ra) ** 2 * inv_inertia[a] + inv_mass[b] \
                    + cross2(n, rb) ** 2 * inv_inertia[b]
                j += speed / k_eff * n
            push(t, a, -j, ra, 0.0)
            push(t, b, j, rb, 0.0)

    @ti.kernel
    def advance(t: ti.i32):
        for i in range(n_boxes):
            decay = ti.exp(-dt * damping)
            v[t, i] = decay * v[t - 1, i] + v_inc[t, i] + ti.Vector([0.0, dt * gravity])
            x[t, i] = x[t - 1, i] + dt * v[t, i] + x_inc[t, i]
            omega[t, i] = decay * omega[t - 1, i] + omega_inc[t, i]
            angle[t, i] = angle[t - 1, i] + dt * omega[t, i] + angle_inc[t, i]

    @ti.kernel
    def compute_loss():
        loss[None] = -(x[steps - 1, body][0] - x[0, body][0])

    def setup(seed: int = 0):
        xs = np.zeros((steps, n_boxes, 2), np.float32)
        ang = np.zeros((steps, n_boxes), np.float32)
        for i, (c, _, a) in enumerate(boxes):
            xs[0, i], ang[0, i] = c, a
        x.from_numpy(xs)
        angle.from_numpy(ang)
        v.fill(0)
        omega.fill(0)
        half.from_numpy(np.array([h for _, h, _ in boxes], np.float32))
        box_a.from_numpy(np.array([s[0] for s in springs], np.int32))
        box_b.from_numpy(np.array([s[1] for s in springs], np.int32))
        offset_a.from_numpy(np.array([s[2] for s in springs], np.float32))
        offset_b.from_numpy(np.array([s[3] for s in springs], np.float32))
        rest.from_numpy(np.array([s[4] or 0.0 for s in springs], np.float32))
        joint.from_numpy(np.array([s[4] is None for s in springs], np.int32))
        stiffness.from_numpy(np.array([s[5] for s in springs], np.float32))
        amplitude.from_numpy(np.array([s[6] for s in springs], np.float32))
        rng = np.random.default_rng(seed)
        w1.from_numpy((rng.standard_normal((n_hidden, n_inputs)) * 0.5
                       * math.sqrt(2 / (n_hidden + n_inputs))).astype(np.float32))
        w2.from_numpy((rng.standard_normal((n_springs, n_hidden))
                       * math.sqrt(2 / (n_hidden + n_springs))).astype(np.float32))
        b1.fill(0)
        b2.fill(0)
        mass_properties()

    def forward():
        clear_impulses()
        for t in range(1, steps):
            controller_hidden(t - 1)
            controller_out(t - 1)
            ground_contact(t - 1)
            spring_forces(t - 1)
            advance(t)
        compute_loss()

    params = (w1, b1, w2, b2)
    ns = dict(locals())
    return type("Robot", (), ns)


def draw(gui, bot, t, xs, ang, acts):
    """Boxes grey with black outlines, muscles red (extended) to blue (contracted), joints as black dots."""
    gui.clear(0xFFFFFF)
    g = bot.ground
    gui.line((0.0, g - 0.004), (1.0, g - 0.004), radius=3, color=0x333333)

    def to_world(i, local):
        c, s = math.cos(ang[t, i]), math.sin(ang[t, i])
        return xs[t, i] + np.asarray(local) @ np.array([[c, s], [-s, c]])

    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    corners = np.stack([to_world(i, square * h) for i, (_, h, _) in enumerate(bot.boxes)])
    gui.triangles(np.concatenate([corners[:, 0], corners[:, 0]]), np.concatenate([corners[:, 1], corners[:, 2]]),
                  np.concatenate([corners[:, 2], corners[:, 3]]), color=0xB0B8C8)
    gui.lines(corners.reshape(-1, 2), np.roll(corners, -1, axis=1).reshape(-1, 2), radius=1.5, color=0x222222)
    begin, end, colors, joints = [], [], [], []
    for s, (a, b, oa, ob, length, _, _) in enumerate(bot.springs):
        if length is None:
            joints.append(to_world(a, oa))
        else:
            u = float(acts[t, s]) * 0.5
            begin.append(to_world(a, oa))
            end.append(to_world(b, ob))
            colors.append(ti.rgb_to_hex((0.5 + u, 0.5 - abs(u), 0.5 - u)))
    if begin:
        gui.lines(np.array(begin), np.array(end), radius=3, color=np.array(colors, np.uint32))
    if joints:
        gui.circles(np.array(joints), radius=4, color=0x222222)


def render(bot, out: str, tag: str, gif: bool) -> None:
    gui = ti.GUI("rigid_body", res=512, background_color=0xFFFFFF, show_gui=False)
    xs, ang, acts = bot.x.to_numpy(), bot.angle.to_numpy(), bot.act.to_numpy()
    steps = bot.steps
    for t in np.linspace(0, steps - 2, 4).astype(int):
        draw(gui, bot, t, xs, ang, acts)
        gui.show(os.path.join(out, f"{tag}_{t:04d}.png"))
    if gif:  # a smaller canvas and 40 frames: GIF encoding costs ~0.1 s per 512 x 512 frame
        gui = ti.GUI("rigid_body", res=320, background_color=0xFFFFFF, show_gui=False)
        images = []
        for t in range(0, steps - 1, max(1, steps // 40)):
            draw(gui, bot, t, xs, ang, acts)
            images.append(gui.get_image()[..., :3].copy())
        write_gif(ti, images, out, tag)


def train(iters: int, out, robot: int = 0, steps: int = 2048, lr: float = 1.0, clip: float = 0.2, seed: int = 0,
          use_toi: bool = True, frames=True):
    bot = build(robot, steps, use_toi=use_toi)
    bot.setup(seed)
    if out is not None and frames:
        bot.forward()
        render(bot, out, "initial", gif=False)
    losses = []
    t0 = time.time()
    for _ in progress(iters, f"rigid_body {robot}"):
        with ti.ad.Tape(loss=bot.loss):
            bot.forward()
        losses.append(float(bot.loss[None]))
        grads = [p.grad.to_numpy() for p in bot.params]
        norm = math.sqrt(sum(float((g.astype(np.float64) ** 2).sum()) for g in grads))
        scale = lr * min(1.0, clip / (norm + 1e-6))
        for p, g in zip(bot.params, grads):
            p.from_numpy(p.to_numpy() - scale * g)
    seconds = (time.time() - t0) / max(iters, 1)
    if out is not None:
        plot_losses(losses, os.path.join(out, "loss.png"), f"rigid_body robot {robot}: -(distance moved right)")
        if frames:
            bot.forward()
            render(bot, out, "optimized", gif=True)
    return losses, seconds


def main():
    args = parse_args("Optimise the controller of a rigid-body robot to move right", iters=20, steps=2048,
                      robot=0, toi=1)
    ti.init(arch=ti.cpu, default_fp=real)
    out = out_dir(args.out, "rigid_body")
    losses, sec = train(args.iters, out, robot=args.robot, steps=args.steps, use_toi=bool(args.toi))
    print(f"loss {losses[0]:.5f} -> {losses[-1]:.5f} in {len(losses)} iterations ({sec:.3f} s/iteration); "
          f"pictures in {out}")


if __name__ == "__main__":
    main()
