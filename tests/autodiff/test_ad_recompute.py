"""Serial loops that store no outer local are recomputed in the adjoint instead of taped (reverse.py).

Each kernel is checked against central finite differences (f64). For the loops that qualify, the adjoint
IR is inspected: the forward replay skips the loop, and its backward loop (attr reversed) pushes nothing
per iteration. Loops that do not qualify (a loop-carried local, a break, a continue) keep the tape.
Also here: the activity analysis that skips adjoints of values no gradient can reach, and a regression
test for a taped loop's local stored after its last load."""

from __future__ import annotations

import math

import numpy as np
from ad_util import f64

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op
from simgrad.testing import check_grads


def _grad_ir(kernel):
    (inst,) = kernel._caches["grad"].values()
    return inst.ir


def _serial_loops(ir):
    return [s for s in walk(ir.body) if s.op is Op.RANGE_FOR and not s.attrs.get("parallel")]


def _pushes_in(stmt) -> int:
    return sum(1 for b in stmt.blocks for x in walk(b) if x.op is Op.TAPE_PUSH)


def _assert_recomputed(kernel, loops: int = 1):
    """Every serial loop of the adjoint is a backward loop; none pushes anything per iteration."""
    ir = _grad_ir(kernel)
    serial = _serial_loops(ir)
    assert len(serial) == loops and all(s.attrs.get("reversed") for s in serial), \
        "the forward replay of a recomputed loop is skipped"
    assert all(_pushes_in(s) == 0 for s in serial), "a recomputed loop pushes nothing"
    assert not any(s.op is Op.WHILE for s in walk(ir.body))
    return ir


def _rng(seed=0):
    return np.random.default_rng(seed)


def _ray_march(inside_if: bool):
    """2-D ray march: per pixel a serial loop of bilinear density gathers at computed indices, summed into
    tau with a field atomic (no loop-carried local), then an opacity image."""
    n, pixels, samples = 8, 6, 24
    dens = ti.field(ti.f64, shape=(n, n), needs_grad=True)
    angle = ti.field(ti.f64, shape=(), needs_grad=True)
    tau = ti.field(ti.f64, shape=pixels, needs_grad=True)
    img = ti.field(ti.f64, shape=pixels, needs_grad=True)

    @ti.func
    def sample(px, py):
        gx = ti.min(ti.max(px * n - 0.5, 0.0), n - 1.001)
        gy = ti.min(ti.max(py * n - 0.5, 0.0), n - 1.001)
        ix = ti.cast(ti.floor(gx), ti.i32)
        iy = ti.cast(ti.floor(gy), ti.i32)
        fx = gx - ix
        fy = gy - iy
        return ((1 - fx) * ((1 - fy) * dens[ix, iy] + fy * dens[ix, iy + 1])
                + fx * ((1 - fy) * dens[ix + 1, iy] + fy * dens[ix + 1, iy + 1]))

    @ti.kernel
    def march():
        for i in range(pixels):
            a = angle[None]
            ox = 0.05
            oy = (i + 0.5) / pixels
            dx = ti.cos(a)
            dy = ti.sin(a) * 0.3
            length = 0.9 / dx
            ds = length / samples
            if ti.static(inside_if):
                if oy > 0.2:  # values from inside the if are then saved once per pixel, not per sample
                    step = ds * (1.0 + 0.1 * oy)
                    for s in range(samples):
                        t = (s + 0.5) * step
                        tau[i] += sample(ox + t * dx, oy + t * dy) * step
            else:
                for s in range(samples):
                    t = (s + 0.5) * ds
                    tau[i] += sample(ox + t * dx, oy + t * dy) * ds

    @ti.kernel
    def shade():
        for i in img:
            img[i] = 1 - ti.exp(-tau[i])

    dens.from_numpy(_rng(1).uniform(0.2, 2.0, (n, n)))
    angle[None] = 0.3

    def forward():
        tau.from_numpy(np.zeros(pixels))
        march()
        shade()

    return march, forward, dens, angle, img


def test_ray_march_matches_finite_differences_and_tapes_nothing():
    f64()
    march, forward, dens, angle, img = _ray_march(inside_if=False)
    check_grads(forward, [dens, angle], [img], rtol=1e-6)
    ir = _assert_recomputed(march)
    assert not ir.uses_tape, "a loop at task level takes its outer values directly: no tape at all"


def test_ray_march_inside_if_saves_outer_values_once_per_pixel():
    f64()
    march, forward, dens, angle, img = _ray_march(inside_if=True)
    check_grads(forward, [dens, angle], [img], rtol=1e-6)
    ir = _assert_recomputed(march)
    # the pushes are the loop's outer values (outside every serial loop): a bound independent of samples
    assert ir.uses_tape and 0 < ir.tape_bound <= 12


def test_nested_ifs_inside_recomputed_loop():
    """Values inside the loop's nested ifs use the tape within one iteration: pushed by its recompute,
    popped by its backward, so the tape bound does not grow with the trip count."""
    f64()
    n, m = 5, 40
    x = ti.field(ti.f64, shape=(n, m), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            for k in range(m):
                v = x[i, k]
                if v > 0.0:
                    w = ti.sin(v) * v
                    if w > 0.2:
                        y[i] += ti.exp(w * 0.5)
                    else:
                        y[i] += w * w
                else:
                    y[i] += ti.cos(v) * v

    x.from_numpy(_rng(2).uniform(-1.5, 1.5, (n, m)))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x], [y])
    ir = _grad_ir(f)
    (loop,) = _serial_loops(ir)
    assert loop.attrs.get("reversed")
    assert ir.tape_bound is not None and ir.tape_bound < m, "one iteration's entries, not m times them"


def test_nested_recomputed_loops():
    """Both loops qualify; the inner one reads a local of the outer body and an outer SSA value."""
    f64()
    n = 4
    x = ti.field(ti.f64, shape=(n, 3), needs_grad=True)
    w = ti.field(ti.f64, shape=5, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            scale = x[i, 0] * 0.5
            for a in range(3):
                u = x[i, a] * scale
                for b in range(5):
                    y[i] += ti.sin(u * w[b] + a)

    x.from_numpy(_rng(3).uniform(-1, 1, (n, 3)))
    w.from_numpy(_rng(4).uniform(-1, 1, 5))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x, w], [y])
    _assert_recomputed(f, loops=2)
    assert not _grad_ir(f).uses_tape


def test_loop_carried_inner_loop_inside_recomputed_loop():
    """The outer loop qualifies (its accumulator is its own local); the inner one carries `acc`, so it is
    replayed with the tape inside each recomputed outer iteration."""
    f64()
    n, outer, inner = 3, 50, 4
    x = ti.field(ti.f64, shape=(n, outer), needs_grad=True)
    c = ti.field(ti.f64, shape=inner, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            for a in range(outer):
                acc = x[i, a]
                for b in range(inner):
                    acc = ti.sin(acc) * c[b] + 0.1
                y[i] += acc * acc

    x.from_numpy(_rng(5).uniform(-1, 1, (n, outer)))
    c.from_numpy(_rng(6).uniform(0.5, 1.5, inner))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x, c], [y])
    ir = _grad_ir(f)
    loops = _serial_loops(ir)
    backward_outer = [s for s in loops if s.attrs.get("reversed") and _pushes_in(s)]
    assert len(backward_outer) == 1, "the inner loop's replay (with pushes) lives in the outer backward loop"
    assert ir.tape_bound is not None and ir.tape_bound < outer, "balanced per outer iteration"


def test_bound_is_kernel_argument_or_field_value():
    f64()
    n = 4
    x = ti.field(ti.f64, shape=(n, 12), needs_grad=True)
    count = ti.field(ti.i32, shape=n)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    z = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def by_arg(m: ti.i32, k: ti.f64):
        for i in range(n):
            for s in range(1, m):
                y[i] += ti.tanh(x[i, s] * k + s)

    @ti.kernel
    def by_field():
        for i in range(n):
            base = x[i, 0]
            if base > -2.0:  # the bound is a field value read inside an if: taped once per pixel
                for s in range(count[i]):
                    z[i] += ti.sin(x[i, s] * base)

    x.from_numpy(_rng(7).uniform(-1, 1, (n, 12)))
    count.from_numpy(np.array([0, 3, 12, 7], dtype=np.int32))

    def forward():
        y.from_numpy(np.zeros(n))
        z.from_numpy(np.zeros(n))
        by_arg(9, 0.7)
        by_field()

    check_grads(forward, [x], [y, z])
    _assert_recomputed(by_arg)
    _assert_recomputed(by_field)


def test_loop_carried_local_is_not_recomputed():
    f64()
    n = 4
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            s = x[i]
            for _k in range(6):
                s = ti.sin(s) * 0.9 + x[i] * 0.1
            y[i] = s

    x.from_numpy(_rng(8).uniform(-1, 1, n))
    check_grads(f, [x], [y])
    ir = _grad_ir(f)
    replay = [s for s in _serial_loops(ir) if not s.attrs.get("reversed")]
    assert len(replay) == 1 and _pushes_in(replay[0]) > 0, "taped: replayed with pushes"


def test_loop_reading_a_local_stored_after_it():
    """The loop reads `c`, which is changed after it: the replay snapshots `c` where the loop stood, so
    the recompute sees the value the loop saw (and qualifies). Inside a loop-carried (taped) outer loop
    the snapshot goes on the tape once per outer iteration."""
    f64()
    n = 3
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    w = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    z = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def flat():
        for i in range(n):
            c = x[i] * 2.0
            for k in range(4):
                y[i] += ti.sin(c * w[k])
            c = c * c + 1.0
            y[i] += c

    @ti.kernel
    def in_carried_loop():
        for i in range(n):
            c = x[i]
            for _j in range(3):
                for k in range(4):
                    z[i] += ti.sin(c * w[k])
                c = ti.cos(c) + c * 0.5

    x.from_numpy(_rng(9).uniform(-1, 1, n))
    w.from_numpy(_rng(10).uniform(-1, 1, 4))

    def forward():
        y.from_numpy(np.zeros(n))
        z.from_numpy(np.zeros(n))
        flat()
        in_carried_loop()

    check_grads(forward, [x, w], [y, z])
    _assert_recomputed(flat)
    loops = _serial_loops(_grad_ir(in_carried_loop))
    assert sum(1 for s in loops if not s.attrs.get("reversed")) == 1, "only the outer loop is replayed"
    assert sum(1 for s in loops if s.attrs.get("reversed")) == 2


def test_break_inside_loop_keeps_the_tape():
    f64()
    n = 4
    x = ti.field(ti.f64, shape=(n, 10), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            for k in range(10):
                if x[i, k] > 0.7:
                    break
                y[i] += ti.sin(x[i, k]) * x[i, k]

    x.from_numpy(_rng(11).uniform(-1, 1, (n, 10)))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x], [y])
    ir = _grad_ir(f)
    assert any(s.op is Op.WHILE for s in walk(ir.body)), "a loop that breaks becomes a taped while loop"


def test_continue_inside_loop_keeps_the_tape():
    """continue sets a flag declared outside the loop, so the loop stores an outer local: taped."""
    f64()
    n = 4
    x = ti.field(ti.f64, shape=(n, 8), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            for k in range(8):
                if x[i, k] < -0.3:
                    continue
                y[i] += ti.exp(x[i, k]) * x[i, k]

    x.from_numpy(_rng(12).uniform(-1, 1, (n, 8)))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x], [y])
    assert any(not s.attrs.get("reversed") for s in _serial_loops(_grad_ir(f)))


def test_while_inside_recomputed_loop():
    f64()
    n = 3
    x = ti.field(ti.f64, shape=(n, 5), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            for k in range(5):
                v = x[i, k]
                j = 0
                while j < k:
                    v = ti.sin(v) + 0.3
                    j += 1
                y[i] += v * v

    x.from_numpy(_rng(13).uniform(-1, 1, (n, 5)))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x], [y])
    loops = _serial_loops(_grad_ir(f))  # the recomputed loop, and the while's backward loop inside it
    assert len(loops) == 2 and all(s.attrs.get("reversed") for s in loops)


def test_recompute_matches_closed_form():
    """y[i] = sum_k sin(x[i] * (k + 1)) in a recomputed loop: exact derivative."""
    f64()
    n, m = 5, 30
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            for k in range(m):
                y[i] += ti.sin(x[i] * (k + 1))

    xs = np.linspace(-1, 1, n)
    x.from_numpy(xs)
    f()
    y.grad.fill(1.0)
    f.grad()
    expect = [sum((k + 1) * math.cos(v * (k + 1)) for k in range(m)) for v in xs]
    np.testing.assert_allclose(x.grad.to_numpy(), expect, rtol=1e-12, atol=1e-12)
    _assert_recomputed(f)


def test_taped_loop_local_stored_after_its_last_load():
    """Regression: in a taped loop, `c = cos(c)` is walked backwards before the loads of c in the inner
    loop that created its adjoint; the store's adjoint must still run (c feeds the next iteration)."""
    f64()
    x = ti.field(ti.f64, shape=1, needs_grad=True)
    z = ti.field(ti.f64, shape=1, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(1):
            c = x[i]
            for _j in range(4):
                for _k in range(3):
                    z[i] += ti.sin(c)
                c = ti.cos(c)

    def expected(v):
        d, c = 0.0, v  # d = dc/dv along the iteration
        dc = 1.0
        for _ in range(4):
            d += 3 * math.cos(c) * dc
            dc *= -math.sin(c)
            c = math.cos(c)
        return d

    x[0] = 0.3
    f()
    z.grad[0] = 1.0
    f.grad()
    assert abs(x.grad[0] - expected(0.3)) < 1e-12


def test_recomputed_loop_inside_taped_while_loop():
    """The while loop carries `c` (taped, its trip count recorded); the inner loop reads `c` and qualifies:
    its snapshot of `c` is pushed once per while iteration and popped by that iteration's backward."""
    f64()
    n = 3
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    w = ti.field(ti.f64, shape=6, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            c = x[i]
            j = 0
            while j < i + 2:
                for k in range(6):
                    y[i] += ti.sin(c * w[k]) * (k + 1)
                c = c * 0.8 + ti.cos(c)
                j += 1

    x.from_numpy(_rng(14).uniform(-1, 1, n))
    w.from_numpy(_rng(15).uniform(-1, 1, 6))

    def forward():
        y.from_numpy(np.zeros(n))
        f()

    check_grads(forward, [x, w], [y])
    ir = _grad_ir(f)
    assert any(s.op is Op.WHILE for s in walk(ir.body))
    recomputed = [s for s in _serial_loops(ir) if s.attrs.get("reversed") and s.operands[1].op is Op.CONST]
    assert recomputed and all(_pushes_in(s) == 0 for s in recomputed)


def test_inactive_values_get_no_adjoint():
    """Values that depend on no field with a gradient (here a weight from the loop index and an argument)
    never accumulate an adjoint: the adjoint holds no derivative of their sin (no cos)."""
    f64()
    n, m = 4, 16
    x = ti.field(ti.f64, shape=(n, m), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f(phase: ti.f64):
        for i in range(n):
            for k in range(m):
                y[i] += ti.sin(k * 0.1 + phase) * x[i, k]

    x.from_numpy(_rng(16).uniform(-1, 1, (n, m)))
    f(0.3)
    y.grad.fill(1.0)
    f.grad(0.3)
    expect = np.tile(np.sin(np.arange(m) * 0.1 + 0.3), (n, 1))
    np.testing.assert_allclose(x.grad.to_numpy(), expect, rtol=1e-13, atol=1e-13)
    ir = _assert_recomputed(f)
    assert not any(s.op is Op.COS for s in walk(ir.body))


def test_activity_reaches_a_local_through_the_loop_back_edge():
    """`a = b * 2` reads b before b is first made to depend on x (later in the body): a depends on x only
    through the previous iteration; the activity fixpoint must still see it."""
    f64()
    x = ti.field(ti.f64, shape=3, needs_grad=True)
    y = ti.field(ti.f64, shape=3, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            a = 0.0
            b = 0.0
            for _k in range(3):
                a = b * 2.0
                b = x[i] * x[i] + a
            y[i] = a

    xs = np.array([0.5, -1.0, 2.0])
    x.from_numpy(xs)
    f()
    y.grad.fill(1.0)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), 6 * 2 * xs, rtol=1e-14)  # y = 6 x^2


def test_dynamic_for_inside_while_reads_an_element_pointer_shared_with_its_bound():
    """Issue 21: CSE made `p[i]` of the loop bound and of the body one element pointer, defined in the while
    body outside the recomputed for: the adjoint pushed that pointer on the i32 tape (LLVM: 'defined with
    type ptr but expected i32'). The pointer is rebuilt from its indices; both forms of the choice."""
    f64()
    n = 4
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    p = ti.field(ti.i32, shape=n)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    x.from_numpy(np.array([0.5, -0.25, 1.5, 2.0]))
    p.from_numpy(np.array([3, 1, 4, 2], dtype=np.int32))

    @ti.kernel
    def a():
        for i in range(n):
            w = 0
            while w < 2:
                w += 1
                for _k in range(p[i]):
                    loss[None] += x[i] * x[i] if p[i] > 1 else 0.0

    @ti.kernel
    def b():
        for i in range(n):
            w = 0
            while w < 1:
                w += 1
                for k in range(p[i] + w):
                    loss[None] += ti.select(p[i] > 2, ti.sin(x[i]) * k, 0.0)

    def run(kernel):
        loss[None] = 0.0
        kernel()

    check_grads(lambda: run(a), [x], [loss])
    check_grads(lambda: run(b), [x], [loss])
    loss[None] = 0.0
    with ti.ad.Tape(loss=loss):
        a()
    xs, ps = x.to_numpy(), p.to_numpy()
    np.testing.assert_allclose(x.grad.to_numpy(), np.where(ps > 1, 2 * ps * 2 * xs, 0.0), rtol=1e-12)
