"""Dynamic SNodes grow chunk by chunk, as Taichi's: a list is a chain of `chunk_size`-cell chunks from the node's
pool, allocated as appends and writes reach them. Memory (the pool's statistics), element access at any index,
appends from many threads to few lists, emptying and refilling within a kernel, and gradients through chunked
lists. Run also on the simulated GPU (SIMGRAD_GPU_SIM=1 TI_ARCH=cuda), whose allocator takes one block at a time.
Small lists are one chunk (lang/snode.py WHOLE_LIST_BYTES): these tests set that size to 0 so every list here is
a chain, and the last test checks the small-list rule itself."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.lang import snode


@pytest.fixture(autouse=True)
def chains_even_for_small_lists(monkeypatch, request):
    if "whole_list" not in request.node.name:
        monkeypatch.setattr(snode, "WHOLE_LIST_BYTES", 0)


def test_a_list_takes_memory_chunk_by_chunk():
    """1000 lists of at most 1024 * 1024 i32 in chunks of 4096, 10 elements each: one chunk per list (8 bytes
    of link and 4096 cells, as Taichi's node size), not the whole list (4 MiB each)."""
    x = ti.field(ti.i32)
    lists = ti.root.dense(ti.i, 1000).dynamic(ti.j, 1024 * 1024, chunk_size=4096)
    lists.place(x)

    @ti.kernel
    def fill(n: ti.i32):
        for i in range(1000):
            for k in range(n):
                ti.append(x.parent(), i, i * 100 + k)

    fill(10)
    use = lists.memory_usage()
    assert use["block_bytes"] == 8 + 4 * 4096
    assert use["live_blocks"] == use["touched_blocks"] == 1000
    assert use["touched_bytes"] == 1000 * (8 + 4 * 4096)

    @ti.kernel
    def grow():
        ti.loop_config(serialize=True)  # in order, so element k holds -(k - 10)
        for k in range(10000 - 10):  # list 7 to 10000 elements: 3 chunks
            ti.append(x.parent(), 7, -k)

    grow()
    assert lists.memory_usage()["touched_blocks"] == 1002
    assert [x[7, k] for k in (0, 9, 10, 4095, 4096, 8192, 9999, 10000)] == [700, 709, 0, -4085, -4086, -8182,
                                                                            -9989, 0]
    lists.deactivate_all()  # the chunks go back to the pool, which starts over on them
    fill(3)
    use = lists.memory_usage()
    assert use["live_blocks"] == 1000 and use["touched_blocks"] == 1002
    assert x[999, 2] == 99902 and x[999, 3] == 0 and x[7, 3] == 0


def test_elements_at_any_index_match_a_model():
    """Writes at scattered indices (kernel and Python scope) allocate the chunks up to theirs and extend the
    length; reads anywhere see the value or 0; a struct-for visits every index below the length."""
    n, chunk = 200, 8
    x = ti.field(ti.f32)
    node = ti.root.dense(ti.i, 3).dynamic(ti.j, n, chunk_size=chunk)
    node.place(x)
    rng = np.random.default_rng(3)
    model = np.zeros((3, n), np.float32)
    length = np.zeros(3, np.int64)
    cells = rng.integers(0, n, (40, 2))
    cells[:, 0] %= 3

    @ti.kernel
    def put(i: ti.i32, j: ti.i32, v: ti.f32):
        x[i, j] = v

    for t, (i, j) in enumerate(cells):
        v = float(t + 1)
        if t % 2:
            put(int(i), int(j), v)
        else:
            x[int(i), int(j)] = v
        model[i, j] = v
        length[i] = max(length[i], j + 1)

    @ti.kernel
    def lengths(out: ti.types.ndarray()):
        for i in range(3):
            out[i] = ti.length(node, i)

    got = np.zeros(3, np.int32)
    lengths(got)
    np.testing.assert_array_equal(got, length)
    np.testing.assert_array_equal(x.to_numpy(), model)

    @ti.kernel
    def visit(out: ti.types.ndarray()):
        for i, j in x:
            out[i, j] += 1.0 + x[i, j]

    seen = np.zeros((3, n), np.float32)
    visit(seen)
    want = np.where(np.arange(n)[None, :] < length[:, None], 1.0 + model, 0.0)
    np.testing.assert_array_equal(seen, want)
    want_chunks = sum(len(set(j // chunk for j in range(int(length[i])))) for i in range(3))
    assert node.memory_usage()["live_blocks"] == want_chunks


def test_parallel_appends_to_few_lists_lose_nothing_and_allocate_each_chunk_once():
    """200000 appends from a parallel loop into 4 lists of 16-cell chunks: every value lands exactly once and each
    list holds ceil(length / 16) chunks (chunks are installed under the list's lock: none twice, none lost)."""
    m, lists_n, chunk = 200000, 4, 16
    x = ti.field(ti.i32)
    node = ti.root.dense(ti.i, lists_n).dynamic(ti.j, 1 << 17, chunk_size=chunk)
    node.place(x)

    @ti.kernel
    def spread():
        for k in range(m):
            ti.append(x.parent(), k % lists_n, k)

    @ti.kernel
    def lengths(out: ti.types.ndarray()):
        for i in range(lists_n):
            out[i] = ti.length(node, i)

    spread()
    values = x.to_numpy()
    per_list = m // lists_n
    got = np.zeros(lists_n, np.int32)
    lengths(got)
    assert (got == per_list).all()
    for i in range(lists_n):
        np.testing.assert_array_equal(np.sort(values[i, :per_list]), np.arange(i, m, lists_n))
        assert not values[i, per_list:].any()
    use = node.memory_usage()
    assert use["live_blocks"] == use["touched_blocks"] == lists_n * -(-per_list // chunk)


def test_a_kernel_empties_and_refills_a_list_it_reads():
    """Within one kernel: fill a list across chunks, read it back, empty it and refill it with other values;
    reads after the refill must see the new chunks (the walk's cursor forgets freed chunks)."""
    x = ti.field(ti.i32)
    node = ti.root.dynamic(ti.i, 4096, chunk_size=4)
    node.place(x)

    @ti.kernel
    def churn() -> ti.i32:
        bad = 0
        ti.loop_config(serialize=True)
        for r in range(5):
            for j in range(37 + r * 5):
                ti.append(node, [], r * 1000 + j)
            for j in range(37 + r * 5):
                if x[j] != r * 1000 + j:
                    bad += 1
            if x[37 + r * 5] != 0:
                bad += 1
            if r < 4:
                ti.deactivate(node, [])
        return bad

    assert churn() == 0
    np.testing.assert_array_equal(x.to_numpy()[:60], np.r_[4000 + np.arange(57), [0, 0, 0]])
    assert node.memory_usage()["live_blocks"] == -(-57 // 4)

    @ti.kernel
    def jump():
        ti.loop_config(serialize=True)
        for r in range(3):  # each write is further down the list than the last chunk the kernel found
            ti.deactivate(node, [])
            x[4 * r + 30] = r + 1

    jump()
    want = np.zeros(4096, np.int32)
    want[38] = 3
    np.testing.assert_array_equal(x.to_numpy(), want)
    assert node.memory_usage()["live_blocks"] == 10


def test_a_write_past_the_size_allocates_no_chunk_beyond_the_list():
    """An index past the node's size (not checked outside debug mode, as in Taichi) writes the discard block
    and reads the zero block; it never walks, and allocates, past the list's last chunk."""
    x = ti.field(ti.i32)
    node = ti.root.dynamic(ti.i, 64, chunk_size=8)
    node.place(x)

    @ti.kernel
    def wild(j: ti.i32) -> ti.i32:
        x[j] = 5
        return x[j]

    assert wild(10 ** 6) == 0
    assert node.memory_usage()["touched_blocks"] <= 1
    assert wild(63) == 5


def test_chunk_size_must_be_positive():
    with pytest.raises(ti.SimgradError, match="chunk_size must be a positive 32-bit integer") as e:
        ti.root.dynamic(ti.i, 16, chunk_size=0)
    assert "test_dynamic_chunks.py" in str(e.value)


def test_gradients_through_chunked_lists_match_finite_differences():
    """loss = sum over each list of w_j * x_j^3, the lists in 3-cell chunks (f64): x.grad against central
    differences."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x, w = ti.field(ti.f64, needs_grad=True), ti.field(ti.f64)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    node = ti.root.dense(ti.i, 2).dynamic(ti.j, 32, chunk_size=3)
    node.place(x, w, x.grad)
    rng = np.random.default_rng(1)
    xs, ws = rng.standard_normal((2, 11)), rng.standard_normal((2, 11))
    for i in range(2):
        for j in range(11):
            x[i, j], w[i, j] = xs[i, j], ws[i, j]

    @ti.kernel
    def compute():
        for i, j in x:
            loss[None] += w[i, j] * x[i, j] ** 3

    def value(v):
        for i in range(2):
            for j in range(11):
                x[i, j] = v[i, j]
        loss[None] = 0.0
        compute()
        return loss[None]

    value(xs)
    loss.grad[None] = 1.0
    compute.grad()
    got = np.array([[x.grad[i, j] for j in range(11)] for i in range(2)])
    eps = 1e-6
    fd = np.zeros_like(xs)
    for i in range(2):
        for j in range(11):
            p, m = xs.copy(), xs.copy()
            p[i, j] += eps
            m[i, j] -= eps
            fd[i, j] = (value(p) - value(m)) / (2 * eps)
    np.testing.assert_allclose(got, fd, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(got, 3 * ws * xs ** 2, rtol=1e-12)


def test_running_out_of_chunks_is_a_located_error_and_the_program_goes_on():
    ti.init(arch=ti.cpu, device_memory_GB=2**-16)  # 16 KiB per pool: 62 chunks of 8 + 64 * 4 bytes
    x = ti.field(ti.i32)
    node = ti.root.dynamic(ti.i, 1 << 16, chunk_size=64)
    node.place(x)

    @ti.kernel
    def push(n: ti.i32):
        ti.loop_config(serialize=True)
        for k in range(n):
            ti.append(node, [], k)

    with pytest.raises(ti.SimgradRuntimeError, match="out of memory for dynamic SNode blocks") as e:
        push(64 * 100)
    assert "test_dynamic_chunks.py" in str(e.value)
    node.deactivate_all()
    push(64 * 30)
    np.testing.assert_array_equal(x.to_numpy()[:64 * 31], np.r_[np.arange(64 * 30), np.zeros(64)])


def test_a_small_list_is_one_whole_list_chunk_with_the_same_values():
    """A list of at most WHOLE_LIST_BYTES takes one block at its first append (no chain to walk when read), and
    computes what a chain of small chunks computes."""
    def run():
        ti.init(arch=ti.cpu)
        x = ti.field(ti.f32)
        node = ti.root.dense(ti.i, 4).dynamic(ti.j, 1024, chunk_size=32)
        node.place(x)
        out = ti.field(ti.f32, shape=4)

        @ti.kernel
        def fill():
            for i in range(4):
                for j in range(100 * (i + 1)):
                    ti.append(x.parent(), i, j * 0.5 + i)

        @ti.kernel
        def total():
            for i in range(4):
                s = 0.0
                for j in range(ti.length(x.parent(), i)):
                    s += x[i, j] * (j % 7)
                out[i] = s

        fill()
        total()
        return node.chunk, out.to_numpy()

    chunk, whole = run()
    assert chunk == 1024  # 1024 f32 = 4 KiB: one chunk
    snode.WHOLE_LIST_BYTES, saved = 0, snode.WHOLE_LIST_BYTES
    try:
        chunk, chained = run()
    finally:
        snode.WHOLE_LIST_BYTES = saved
    assert chunk == 32
    j = np.arange(400)
    want = [((j[:100 * (i + 1)] * 0.5 + i) * (j[:100 * (i + 1)] % 7)).sum() for i in range(4)]
    np.testing.assert_allclose(whole, want, rtol=1e-5)
    np.testing.assert_allclose(chained, want, rtol=1e-5)
