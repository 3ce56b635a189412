"""Asynchronous launches on arch=cuda and Taichi's synchronisation semantics, on the deferred simulated GPU
(SIMGRAD_GPU_SIM=async: HostDriver(deferred=True) queues launches and runs them only at a synchronize, so a
Python-scope access that does not synchronize first reads what the memory held before the kernel ran).

Each test reads or writes through a Python-scope path after a launch that did not wait; without the hook in
front of device memory (lang/program.py sync_for_host) it gets the stale value."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.lang.program import get_program


@pytest.fixture
def dev(monkeypatch):
    from simgrad.runtime import device

    monkeypatch.setattr(device, "cuda_runtime_enabled", lambda: False)  # the deferred simulated GPU, on a GPU too
    monkeypatch.setenv("SIMGRAD_GPU_SIM", "async")
    ti.init(arch=ti.cuda)
    d = get_program().device
    assert ti.lang.impl.current_cfg().arch is ti.cuda and d.deferred and d.asynchronous
    return d


def _writer(x, value=1.0):
    @ti.kernel
    def write(s: ti.f32):
        for i in x:
            x[i] = s * (i + value)

    return write


def test_a_launch_does_not_wait(dev):
    """The kernel is only queued: the field's memory is unchanged until something synchronizes."""
    x = ti.field(ti.f32, shape=8)
    write = _writer(x)
    write(2.0)
    assert dev.pending and x._view is not None and (x._view == 0).all()  # the raw memory, not yet written
    assert x[3] == 8.0  # element read: synchronizes first
    assert not dev.pending


def test_element_write_waits_for_the_queued_kernel(dev):
    """x[i] = v after a launch that writes x: the write lands after the kernel's (as on Taichi's CUDA)."""
    x = ti.field(ti.f32, shape=8)
    y = ti.field(ti.f32, shape=())
    write = _writer(x)

    @ti.kernel
    def read():
        y[None] = x[0]

    write(1.0)
    x[0] = 5.0
    read()
    assert y[None] == 5.0


def test_to_numpy_after_a_kernel(dev):
    x = ti.field(ti.f32, shape=100)
    v = ti.Vector.field(3, ti.f32, shape=10)
    m = ti.Matrix.field(2, 2, ti.i32, shape=(), layout=ti.Layout.SOA)

    @ti.kernel
    def k():
        for i in x:
            x[i] = i
        for i in v:
            v[i] = ti.Vector([i, 2 * i, 3 * i])
        m[None] = ti.Matrix([[1, 2], [3, 4]])

    k()
    assert (x.to_numpy() == np.arange(100)).all()
    assert (v.to_numpy() == np.arange(10)[:, None] * [1, 2, 3]).all()  # the packed view of a vector field
    assert (m.to_numpy() == [[1, 2], [3, 4]]).all()
    k()
    assert list(v[4]) == [4, 8, 12]  # a live element view


def test_fill_and_from_numpy_then_kernel(dev):
    """fill / from_numpy after a queued kernel that writes the field, then a kernel that reads it: the host's
    values are the ones read (they were written after the first kernel ran)."""
    x = ti.field(ti.f32, shape=16)
    s = ti.field(ti.f32, shape=())
    write = _writer(x)

    @ti.kernel
    def total():
        for i in x:
            s[None] += x[i]

    write(1.0)
    x.fill(2.0)
    total()
    assert s[None] == 32.0
    write(1.0)
    x.from_numpy(np.full(16, 0.5, np.float32))
    s[None] = 0.0
    total()
    assert s[None] == 8.0


def test_copy_from_and_torch(dev):
    x = ti.field(ti.f32, shape=4)
    y = ti.field(ti.f32, shape=4)
    write = _writer(x)
    write(1.0)
    y.copy_from(x)
    assert (y.to_numpy() == [1, 2, 3, 4]).all()
    torch = pytest.importorskip("torch")
    write(2.0)
    assert torch.equal(x.to_torch(), torch.tensor([2.0, 4.0, 6.0, 8.0]))


def test_ndarray_access_after_a_kernel(dev):
    a = ti.ndarray(ti.f32, 8)
    b = ti.Vector.ndarray(2, ti.i32, 4)

    @ti.kernel
    def k(a: ti.types.ndarray(), b: ti.types.ndarray()):
        for i in range(8):
            a[i] = a[i] + i
        for i in range(4):
            b[i] = ti.Vector([i, -i])

    k(a, b)
    assert dev.pending
    assert a[5] == 5.0  # element read
    k(a, b)
    assert (a.to_numpy() == 2 * np.arange(8)).all()
    assert (b.to_numpy() == np.stack([np.arange(4), -np.arange(4)], 1)).all()
    k(a, b)
    a.fill(1.0)  # after the queued kernel, not before it
    k(a, b)
    assert (a.to_numpy() == 1 + np.arange(8)).all()
    k(a, b)
    a.from_numpy(np.zeros(8, np.float32))
    k(a, b)
    assert (a.to_numpy() == np.arange(8)).all()
    k(a, b)
    b[1] = [7, 7]
    assert list(b[1]) == [7, 7]


def test_ti_sync(dev):
    x = ti.field(ti.i32, shape=4)

    @ti.kernel
    def k():
        for i in x:
            x[i] += 1

    for _ in range(3):
        k()
    assert dev.pending
    ti.sync()
    assert not dev.pending and (x._view == 3).all()  # the raw memory: the kernels ran at the sync


def test_launches_that_return_or_can_fail_wait(dev):
    """A kernel that returns a value, or has error sites (debug bound checks), waits: the value is read and
    the error raised at the call's line."""
    x = ti.field(ti.f32, shape=8)
    write = _writer(x)

    @ti.kernel
    def total() -> ti.f32:
        s = 0.0
        for i in x:
            s += x[i]
        return s

    write(1.0)
    assert total() == 36.0 and not dev.pending
    ti.init(arch=ti.cuda, debug=True)
    y = ti.field(ti.f32, shape=4)

    @ti.kernel
    def oob(i: ti.i32):
        y[i] = 1.0

    with pytest.raises(ti.TaichiAssertionError if hasattr(ti, "TaichiAssertionError") else Exception,
                       match="Out of bound") as e:
        oob(9)
    assert "test_async.py" in str(e.value) and not get_program().device.pending


def test_numpy_arguments_are_copied_in_and_back(dev):
    """A numpy array argument on an asynchronous device (host memory the GPU cannot address) is copied to
    device memory before the launch and back after it, as Taichi does for external arrays on CUDA."""
    @ti.kernel
    def k(a: ti.types.ndarray(), b: ti.types.ndarray()):
        for i in range(a.shape[0]):
            b[i] = a[i] * 2 + b[i]

    a = np.arange(6, dtype=np.float32)
    b = np.ones(6, np.float32)
    k(a, b)
    assert (b == 2 * np.arange(6) + 1).all() and (a == np.arange(6)).all()
    blocks = len(dev._blocks)
    k(a, a)  # one array passed twice: one device copy
    assert (a == 3 * np.arange(6)).all()
    assert len(dev._blocks) == blocks  # the staged copies were freed
    v = np.zeros((3, 2), np.int32)

    @ti.kernel
    def vec(v: ti.types.ndarray(dtype=ti.math.ivec2, ndim=1)):
        for i in range(3):
            v[i] = ti.Vector([i, 10 * i])

    vec(v)
    assert (v == [[0, 0], [1, 10], [2, 20]]).all()


def test_numpy_argument_after_a_queued_kernel_reads_its_results(dev):
    """The copy into device memory is stream-ordered: a kernel queued earlier that writes a field has run before
    the numpy array's kernel reads that field."""
    x = ti.field(ti.f32, shape=4)
    write = _writer(x)

    @ti.kernel
    def into(out: ti.types.ndarray()):
        for i in range(4):
            out[i] = x[i]

    write(3.0)
    out = np.zeros(4, np.float32)
    into(out)
    assert (out == [3, 6, 9, 12]).all()


def test_torch_host_tensor_arguments_are_staged(dev):
    torch = pytest.importorskip("torch")

    @ti.kernel
    def k(t: ti.types.ndarray()):
        for i in range(4):
            t[i] += i

    t = torch.zeros(4)
    k(t)
    assert torch.equal(t, torch.tensor([0.0, 1.0, 2.0, 3.0]))


def test_profiler_times_come_from_device_events(dev):
    """ti.profiler on arch=cuda: events recorded around each launch in stream order (host clocks on the
    simulated GPU, CUDA events on a GPU); a profiled launch still does not wait, the times are read when asked."""
    ti.init(arch=ti.cuda, kernel_profiler=True)
    d = get_program().device
    x = ti.field(ti.f32, shape=100_000)

    @ti.kernel
    def heavy():
        for i in x:
            v = 0.0
            for j in range(200):
                v += ti.sin(v + i * 0.001 + j)
            x[i] = v

    @ti.kernel
    def light():
        x[0] = 1.0

    for _ in range(3):
        heavy()
        light()
    assert d.pending  # profiling did not make the launches wait
    r, q = ti.profiler.query_kernel_profiler_info("heavy"), ti.profiler.query_kernel_profiler_info("light")
    assert not d.pending and r.counter == 3 and q.counter == 3
    assert 0 < r.min <= r.avg <= r.max and q.avg < r.avg  # the queued work's own times, not the launch calls'
    ti.profiler.print_kernel_profiler_info()
    assert ti.profiler.get_kernel_profiler_total_time() > 0
    ti.profiler.clear_kernel_profiler_info()
    assert ti.profiler.query_kernel_profiler_info("heavy").counter == 0


def test_tape_on_the_asynchronous_device(dev):
    """The Tape's gradient path (its snapshot of the tree buffers, the loss read) synchronizes too."""
    n = 16
    w = ti.field(ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def energy():
        for i in w:
            loss[None] += w[i] * w[i] * 0.5

    ws = np.linspace(-1, 1, n)
    w.from_numpy(ws)
    with ti.ad.Tape(loss=loss):
        energy()
    assert loss[None] == pytest.approx(0.5 * (ws ** 2).sum())
    np.testing.assert_allclose(w.grad.to_numpy(), ws)


def test_gui_set_image_of_a_field(dev):
    img = ti.field(ti.f32, shape=(4, 3))

    @ti.kernel
    def paint(v: ti.f32):
        for i, j in img:
            img[i, j] = v

    gui = ti.GUI("async", res=(4, 3), show_gui=False)
    paint(0.5)
    gui.set_image(img)
    np.testing.assert_allclose(gui.get_image()[..., :3], 0.5, atol=1 / 255)


def test_sparse_matrix_builder_on_the_asynchronous_device(dev):
    """A kernel that adds triplets waits (the count is read after its call); build() sees them all."""
    builder = ti.linalg.SparseMatrixBuilder(4, 4, max_num_triplets=16)

    @ti.kernel
    def diag(A: ti.types.sparse_matrix_builder(), v: ti.f32):
        for i in range(4):
            A[i, i] += v

    diag(builder, 2.0)
    diag(builder, 1.0)
    A = builder.build()
    assert [A[i, i] for i in range(4)] == [3.0] * 4 and A[0, 1] == 0.0
