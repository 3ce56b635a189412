"""Reverse-mode autodiff through sparse SNodes (pointer, bitmasked, dynamic), pinned to Taichi 1.7.4's semantics.

* ``place(x, x.grad)`` or ``needs_grad=True`` + ``ti.root.lazy_grad()`` puts the gradient as a sibling of the primal
  under the same dense node: the gradient has exactly the primal's sparsity (the same pointer blocks), and writing
  either one activates the block for both.
* Gradients through struct-fors over active cells (Tape and kernel.grad) are checked against the same computation on
  a dense field (with a mask) and against central finite differences in float64.
* A backward pass that writes the gradient of an inactive cell (the forward read it, so it read 0) stores it: the
  gradient is correct there too (in Taichi the write activates the block, for x.grad and x alike).

TAICHI_WRONG lists tests whose asserted (correct) result Taichi 1.7.4 does not produce; a run under real Taichi
(through a shim module named simgrad) skips them:

* test_grad_loop_bound_from_dynamic_length_at_a_loaded_index: an inner ``for k in range(ti.length(dyn, I))`` in a
  differentiated kernel where I is computed from loaded field values (``int(p[None] // 1)``) fails to compile in
  Taichi 1.7.4 with ``RuntimeError: [statements.inc.h:visit@36] Not supported.`` (taichi-dev/taichi#8682, open:
  "RuntimeError in multi-level loops with sparse data structures and autodiff: IRVisitor unsupported statement").
  The same loop with I = the outer loop variable works (test_grad_loop_bound_from_dynamic_length_at_the_loop_index).
"""

import numpy as np

import simgrad as ti

TAICHI_WRONG = {"test_grad_loop_bound_from_dynamic_length_at_a_loaded_index"}


def _f64():
    """Re-initialise with f64 defaults (the autouse fixture initialised with f32)."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)


def _eval(kernels, loss):
    loss[None] = 0.0
    for k in kernels:
        k()
    return loss[None]


def _fd(kernels, loss, field, cells, eps=1e-6):
    """Central differences of the loss (a sum computed by `kernels`) w.r.t. field[c] for each index tuple c; the
    perturbed cells must already be active so that perturbing them changes no activity."""
    out = []
    for c in cells:
        v = field[c]
        field[c] = v + eps
        up = _eval(kernels, loss)
        field[c] = v - eps
        down = _eval(kernels, loss)
        field[c] = v
        out.append((up - down) / (2 * eps))
    return np.array(out)


def _visited_1d(f, n):
    mark = ti.field(ti.i32, shape=n)

    @ti.kernel
    def visit(s: ti.template()):
        for i in s:
            mark[i] += 1

    visit(f)
    return np.flatnonzero(mark.to_numpy()).tolist()


def test_grad_field_shares_the_primal_sparsity():
    x = ti.field(ti.f32)
    blk = ti.root.pointer(ti.i, 4)
    blk.dense(ti.i, 8).place(x, x.grad)
    x[3] = 1.0
    assert x.grad.parent(2) == blk and x.grad.parent() == x.parent()
    assert x.grad.shape == (32,)
    assert _visited_1d(x.grad, 32) == list(range(8))
    x.grad[20] = 2.0  # activates block 2, for x as well
    assert _visited_1d(x, 32) == list(range(8)) + list(range(16, 24))
    assert x[20] == 0.0 and x.grad[20] == 2.0
    blk.deactivate_all()
    assert _visited_1d(x.grad, 32) == []
    assert x.grad[20] == 0.0


def test_lazy_grad_places_gradients_under_the_same_pointer():
    y = ti.field(ti.f32, needs_grad=True)
    blk = ti.root.pointer(ti.ij, 2)
    blk.dense(ti.ij, 4).place(y)
    ti.root.lazy_grad()
    y[5, 1] = 3.0
    assert y.grad.parent(2) == blk
    assert y.grad.shape == (8, 8)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)

    @ti.kernel
    def cube():
        for i, j in y:
            loss[None] += y[i, j] ** 3

    with ti.ad.Tape(loss=loss):
        cube()
    want = np.zeros((8, 8), np.float32)
    want[5, 1] = 27.0
    assert np.array_equal(y.grad.to_numpy(), want)
    assert loss[None] == 27.0


def test_tape_through_pointer_struct_for_matches_dense_and_fd():
    _f64()
    n, bs = 16, 4
    x = ti.field(ti.f64)
    ti.root.pointer(ti.ij, n // bs).dense(ti.ij, bs).place(x, x.grad)
    xd = ti.field(ti.f64, shape=(n, n), needs_grad=True)
    mask = ti.field(ti.i32, shape=(n, n))
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    loss_d = ti.field(ti.f64, shape=(), needs_grad=True)

    rng = np.random.default_rng(11)
    ref = np.zeros((n, n))
    for i, j in rng.integers(0, n, size=(5, 2)):
        v = rng.normal()
        x[i, j] = v
        ref[i, j] = v
    active = np.zeros((n, n), bool)
    for i, j in np.argwhere(ref):
        active[i // bs * bs : (i // bs + 1) * bs, j // bs * bs : (j // bs + 1) * bs] = True
    # give every active cell a value, so that cells of an active block that were never written count too
    cells = [tuple(int(v) for v in c) for c in np.argwhere(active)]
    for c in cells:
        v = rng.normal()
        x[c] = v
        ref[c] = v
    xd.from_numpy(ref)
    mask.from_numpy(active.astype(np.int32))

    @ti.kernel
    def sparse_loss():
        for i, j in x:
            loss[None] += ti.sin(x[i, j]) * x[i, j] ** 2 + 0.1 * (i - j) * x[i, j]

    @ti.kernel
    def dense_loss():
        for i, j in xd:
            if mask[i, j]:
                loss_d[None] += ti.sin(xd[i, j]) * xd[i, j] ** 2 + 0.1 * (i - j) * xd[i, j]

    with ti.ad.Tape(loss=loss):
        sparse_loss()
    g = x.grad.to_numpy()  # read before the next Tape clears every gradient
    with ti.ad.Tape(loss=loss_d):
        dense_loss()
    gd = xd.grad.to_numpy()
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    analytic = np.where(active, np.cos(ref) * ref**2 + 2 * np.sin(ref) * ref + 0.1 * (ii - jj), 0.0)
    assert abs(loss[None] - loss_d[None]) < 1e-12
    assert np.allclose(g, gd, rtol=1e-12, atol=1e-14)
    assert np.allclose(g, analytic, rtol=1e-12, atol=1e-14)
    fd = _fd([sparse_loss], loss, x, cells[::7])
    assert np.allclose(np.array([g[c] for c in cells[::7]]), fd, rtol=1e-6, atol=1e-8)


def test_kernel_grad_through_bitmasked_struct_for_fd():
    _f64()
    z = ti.field(ti.f64)
    ti.root.dense(ti.i, 4).bitmasked(ti.j, 8).place(z, z.grad)
    wgt = ti.field(ti.f64, shape=(4, 8))
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    rng = np.random.default_rng(5)
    wgt.from_numpy(rng.normal(size=(4, 8)))
    w = wgt.to_numpy()
    cells = [(0, 1), (1, 3), (3, 7), (2, 2)]
    vals = {}
    for c in cells:
        vals[c] = rng.normal()
        z[c] = vals[c]

    @ti.kernel
    def f():
        for i, j in z:
            loss[None] += ti.exp(z[i, j]) * wgt[i, j]

    loss[None] = 0.0
    f()
    assert abs(loss[None] - sum(np.exp(vals[c]) * w[c] for c in cells)) < 1e-12
    loss.grad[None] = 1.0
    f.grad()
    want = np.zeros((4, 8))
    for c in cells:
        want[c] = np.exp(vals[c]) * w[c]
    assert np.allclose(z.grad.to_numpy(), want, rtol=1e-12, atol=0)
    fd = _fd([f], loss, z, cells)
    assert np.allclose(fd, [want[c] for c in cells], rtol=1e-6, atol=1e-9)


def test_stencil_gradient_reaches_inactive_neighbours():
    """loss = sum over active i of x[i] * x[(i + 1) % n]: a neighbour in an inactive block reads 0 in the forward
    pass, yet d loss / d x[i + 1] = x[i] there. Checked against the dense computation with a mask."""
    _f64()
    n, bs = 32, 4
    x = ti.field(ti.f64)
    ti.root.pointer(ti.i, n // bs).dense(ti.i, bs).place(x, x.grad)
    xd = ti.field(ti.f64, shape=n, needs_grad=True)
    mask = ti.field(ti.i32, shape=n)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    loss_d = ti.field(ti.f64, shape=(), needs_grad=True)
    rng = np.random.default_rng(2)
    blocks = [1, 2, 5]
    ref = np.zeros(n)
    active = np.zeros(n, bool)
    for b in blocks:
        for i in range(b * bs, (b + 1) * bs):
            ref[i] = rng.normal()
            x[i] = ref[i]
            active[i] = True
    xd.from_numpy(ref)
    mask.from_numpy(active.astype(np.int32))

    @ti.kernel
    def sparse_loss():
        for i in x:
            loss[None] += x[i] * x[(i + 1) % n] + 0.5 * x[(i + n - 1) % n] ** 2

    @ti.kernel
    def dense_loss():
        for i in xd:
            if mask[i]:
                loss_d[None] += xd[i] * xd[(i + 1) % n] + 0.5 * xd[(i + n - 1) % n] ** 2

    with ti.ad.Tape(loss=loss):
        sparse_loss()
    g = np.array([x.grad[i] for i in range(n)])  # read before the next Tape clears every gradient
    with ti.ad.Tape(loss=loss_d):
        dense_loss()
    gd = xd.grad.to_numpy()
    want = np.zeros(n)
    for i in np.flatnonzero(active):
        want[i] += ref[(i + 1) % n]
        want[(i + 1) % n] += ref[i]
        want[(i + n - 1) % n] += ref[(i + n - 1) % n]
    assert abs(loss[None] - loss_d[None]) < 1e-12
    assert np.allclose(gd, want, rtol=1e-12, atol=1e-14)
    assert np.allclose(g, want, rtol=1e-12, atol=1e-14)
    assert want[3 * bs] != 0.0 and not active[3 * bs]  # the test does reach an inactive neighbour
    cells = [(int(i),) for i in np.flatnonzero(active)[::3]]
    fd = _fd([sparse_loss], loss, x, cells)
    assert np.allclose(fd, [want[c] for c in cells], rtol=1e-6, atol=1e-8)


def test_grad_of_range_for_reading_inactive_cells():
    _f64()
    x = ti.field(ti.f64)
    ti.root.pointer(ti.i, 4).dense(ti.i, 8).place(x, x.grad)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    x[3] = 1.0

    @ti.kernel
    def weighted():
        for i in range(32):
            loss[None] += x[i] * (i + 1)

    with ti.ad.Tape(loss=loss):
        weighted()
    assert loss[None] == 4.0
    assert [x.grad[i] for i in range(32)] == [float(i + 1) for i in range(32)]
    assert np.array_equal(x.grad.to_numpy(), np.arange(1, 33, dtype=np.float64))


def test_activation_inside_a_differentiated_kernel():
    _f64()
    a = ti.field(ti.f64, shape=16, needs_grad=True)
    s = ti.field(ti.f64)
    ti.root.pointer(ti.i, 4).dense(ti.i, 4).place(s, s.grad)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def scatter():
        for i in a:
            if i % 5 == 0:
                s[i] = a[i] * 2.0

    @ti.kernel
    def sum_sq():
        for i in s:
            loss[None] += s[i] ** 2

    av = np.linspace(-1.0, 2.0, 16)
    a.from_numpy(av)
    with ti.ad.Tape(loss=loss):
        scatter()
        sum_sq()
    sel = np.arange(16) % 5 == 0
    assert abs(loss[None] - np.sum((2 * av[sel]) ** 2)) < 1e-12
    assert np.allclose(a.grad.to_numpy(), np.where(sel, 8 * av, 0.0), rtol=1e-12, atol=0)
    assert _visited_1d(s, 16) == list(range(16))  # indices 0, 5, 10, 15 touch all four blocks
    fd = _fd([scatter, sum_sq], loss, a, [(0,), (5,), (6,), (15,)])
    assert np.allclose(fd, [8 * av[0], 8 * av[5], 0.0, 8 * av[15]], rtol=1e-6, atol=1e-8)


def test_tape_twice_clears_sparse_gradients():
    x = ti.field(ti.f32)
    ti.root.pointer(ti.i, 4).dense(ti.i, 8).place(x, x.grad)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)
    x[3] = 1.5
    x[9] = -2.0

    @ti.kernel
    def f():
        for i in x:
            loss[None] += x[i] ** 2

    for _ in range(2):
        with ti.ad.Tape(loss=loss):
            f()
        want = np.zeros(32, np.float32)
        want[3], want[9] = 3.0, -4.0
        assert np.array_equal(x.grad.to_numpy(), want)
        assert loss[None] == 6.25


def test_grad_through_dynamic_struct_for():
    _f64()
    q = ti.field(ti.f64)
    ti.root.dense(ti.i, 3).dynamic(ti.j, 16, chunk_size=4).place(q, q.grad)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    lengths = [2, 0, 5]
    ref = np.zeros((3, 16))
    rng = np.random.default_rng(9)
    for i, m in enumerate(lengths):
        for j in range(m):
            ref[i, j] = rng.normal()
            q[i, j] = ref[i, j]  # direct writes extend the length (ti.append needs one value per child here)

    @ti.kernel
    def f():
        for i, j in q:
            loss[None] += q[i, j] ** 2 * (i + 1)

    with ti.ad.Tape(loss=loss):
        f()
    want = 2 * ref * (np.arange(3)[:, None] + 1)
    assert abs(loss[None] - np.sum(ref**2 * (np.arange(3)[:, None] + 1))) < 1e-12
    assert np.allclose(q.grad.to_numpy(), want, rtol=1e-12, atol=0)


def _dynamic_lists_and_params():
    d = ti.field(ti.i32)
    ti.root.dense(ti.i, 4).dynamic(ti.j, 8, chunk_size=4).place(d)
    p = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def fill():
        for k in range(10):
            ti.append(d.parent(), k % 4, k)

    fill()
    for i in range(4):
        p[i] = 1.0 + i
    items = [[k for k in range(10) if k % 4 == i] for i in range(4)]
    return d, p, loss, items


def test_grad_loop_bound_from_dynamic_length_at_the_loop_index():
    _f64()
    d, p, loss, items = _dynamic_lists_and_params()

    @ti.kernel
    def f():
        for i in range(4):
            for k in range(ti.length(d.parent(), i)):
                loss[None] += p[i] * p[i] * d[i, k]

    with ti.ad.Tape(loss=loss):
        f()
    pv = np.arange(1.0, 5.0)
    assert loss[None] == sum(pv[i] ** 2 * sum(items[i]) for i in range(4))
    assert p.grad.to_numpy().tolist() == [2 * pv[i] * sum(items[i]) for i in range(4)]


def test_grad_loop_bound_from_dynamic_length_at_a_loaded_index():
    """Taichi 1.7.4 fails to compile the backward kernel (taichi-dev/taichi#8682); see the module docstring."""
    _f64()
    d, p, loss, items = _dynamic_lists_and_params()
    sel = ti.field(ti.f64, shape=(), needs_grad=True)
    sel[None] = 2.7  # list int(2.7) = 2

    @ti.kernel
    def f():
        for _ in range(3):
            i = int(sel[None] // 1)
            for k in range(ti.length(d.parent(), i)):
                loss[None] += p[i] * p[i] * d[i, k]

    with ti.ad.Tape(loss=loss):
        f()
    pv = np.arange(1.0, 5.0)
    assert loss[None] == 3 * pv[2] ** 2 * sum(items[2])
    assert p.grad.to_numpy().tolist() == [0.0, 0.0, 3 * 2 * pv[2] * sum(items[2]), 0.0]
    assert sel.grad[None] == 0.0
