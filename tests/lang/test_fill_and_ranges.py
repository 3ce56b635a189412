"""field.fill inside kernels, loop counts beyond i32, ti.static of run-time values, Python-scope integer
stores that do not fit."""

import numpy as np
import pytest

import simgrad as ti


def test_fill_in_kernel_runs_at_every_launch():
    x = ti.field(ti.f32, shape=(5, 3))

    @ti.kernel
    def reset():
        x.fill(3.0)

    for _ in range(3):
        x[1, 2] = -1.0
        x[4, 0] = 7.0
        reset()
        assert np.array_equal(x.to_numpy(), np.full((5, 3), 3.0, np.float32))


def test_fill_in_kernel_takes_run_time_values():
    x = ti.field(ti.i32, shape=7)
    s = ti.field(ti.f64, shape=())

    @ti.kernel
    def k(v: ti.i32):
        x.fill(v * 2)

    @ti.kernel
    def from_field():
        x.fill(ti.cast(s[None], ti.i32) + 1)

    k(4)
    assert x.to_numpy().tolist() == [8] * 7
    k(-5)
    assert x.to_numpy().tolist() == [-10] * 7
    s[None] = 41.0
    from_field()
    assert x.to_numpy().tolist() == [42] * 7


def test_fill_in_kernel_vector_and_matrix_fields():
    v = ti.Vector.field(3, ti.f32, shape=(4, 2))
    m = ti.Matrix.field(2, 2, ti.f64, shape=5, offset=(-2,))

    @ti.kernel
    def k(a: ti.f32):
        v.fill(a)  # a scalar goes to every entry
        m.fill(ti.Matrix([[1.0, a], [a * 2, 4.0]]))

    @ti.kernel
    def vec(a: ti.f32):
        v.fill(ti.Vector([a, 2 * a, 3 * a]))

    k(1.5)
    assert np.array_equal(v.to_numpy(), np.full((4, 2, 3), 1.5, np.float32))
    assert np.array_equal(m.to_numpy(), np.broadcast_to([[1.0, 1.5], [3.0, 4.0]], (5, 2, 2)))
    vec(2.0)
    assert np.array_equal(v.to_numpy(), np.broadcast_to(np.array([2.0, 4.0, 6.0], np.float32), (4, 2, 3)))


def test_fill_inside_a_loop_and_before_a_loop():
    """The particle-in-cell pattern: clear the grid, then scatter, every step."""
    grid = ti.field(ti.f32, shape=8)
    hits = ti.field(ti.f32, shape=(3, 8))

    @ti.kernel
    def step(t: ti.i32):
        grid.fill(0)
        for p in range(16):
            grid[(p + t) % 8] += 1.0

    @ti.kernel
    def rows():
        for r in range(3):
            for c in range(8):
                hits[r, c] = 9.0
        for r in range(1):
            hits.fill(r + 0.5)

    for t in range(3):
        step(t)
        assert grid.to_numpy().tolist() == [2.0] * 8
    rows()
    assert np.all(hits.to_numpy() == 0.5)


def test_fill_in_kernel_of_a_scalar_field_with_a_matrix_is_refused():
    x = ti.field(ti.f32, shape=3)

    @ti.kernel
    def k():
        x.fill(ti.Vector([1.0, 2.0]))

    with pytest.raises(SyntaxError, match=r"fill: field x holds scalars") as e:
        k()
    assert "x.fill(ti.Vector([1.0, 2.0]))" in str(e.value)


def test_ndrange_beyond_i32_runs_the_right_count():
    """2**31 + 2**22 iterations: the flat index is i64, the indices stay exact i32 values."""
    count = ti.field(ti.i64, shape=())
    last = ti.field(ti.i32, shape=3)
    a, b, c = 2**11, 2**11, 2**9 + 1

    @ti.kernel
    def k():
        for i, j, l in ti.ndrange(a, b, c):
            count[None] += 1
            if i == a - 1 and j == b - 1 and l == c - 1:
                last[0], last[1], last[2] = i, j, l

    k()
    assert count[None] == a * b * c
    assert last.to_numpy().tolist() == [a - 1, b - 1, c - 1]


def test_run_time_ndrange_beyond_i32_is_refused():
    @ti.kernel
    def k(n: ti.i32, m: ti.i32) -> ti.i32:
        s = 0
        for i, j in ti.ndrange(n, m):
            s += 1 + i * 0 + j * 0
        return s

    assert k(300, 7) == 2100
    with pytest.raises(AssertionError, match=r"iteration count .* exceeds 2\*\*31 - 1") as e:
        k(70000, 70000)
    assert "for i, j in ti.ndrange(n, m):" in str(e.value)


def test_static_of_a_run_time_value_is_refused():
    @ti.kernel
    def unroll(n: ti.i32) -> ti.i32:
        s = 0
        for i in ti.static(range(n)):
            s += i
        return s

    @ti.kernel
    def branch(n: ti.i32) -> ti.i32:
        r = 0
        if ti.static(n > 2):
            r = 1
        return r

    for k, line in ((unroll, "for i in ti.static(range(n)):"), (branch, "if ti.static(n > 2):")):
        with pytest.raises(SyntaxError, match=r"ti.static\(\) arguments must be compile-time constants") as e:
            k(3)
        assert line in str(e.value) and "test_fill_and_ranges.py" in str(e.value)


@pytest.mark.parametrize("value", [2**40, 2**31, np.int64(2**40), -(2**31) - 1])
def test_python_scope_store_that_does_not_fit_is_refused(value):
    x = ti.field(ti.i32, shape=2)
    v = ti.Vector.field(2, ti.i32, shape=2)
    with pytest.raises(OverflowError, match=r"does not fit field x of type i32") as e:
        x[0] = value
    assert "x[0] = value" in str(e.value)
    with pytest.raises(OverflowError, match=r"does not fit field x of type i32"):
        x.fill(value)
    with pytest.raises(OverflowError, match=r"does not fit field v of type i32"):
        v[1] = [1, value]
    assert x.to_numpy().tolist() == [0, 0] and v.to_numpy().sum() == 0
    x[0] = -(2**31)
    x[1] = 2**31 - 1
    assert x.to_numpy().tolist() == [-(2**31), 2**31 - 1]


def test_kernel_with_fill_is_taken_from_the_kernel_cache(tmp_path):
    """fill emits IR from the field's layout, which is part of the key: no compile-time user call."""
    import json
    import os
    import subprocess
    import sys

    script = tmp_path / "prog.py"
    script.write_text(
        "import json, simgrad as ti\n"
        "from simgrad.runtime.jit import get_jit\n"
        f"ti.init(arch=ti.cpu, offline_cache_file_path=r'{tmp_path / 'cache'}')\n"
        "v = ti.Vector.field(2, ti.f32, shape=5)\n"
        "@ti.kernel\n"
        "def k(a: ti.f32):\n"
        "    v.fill(a)\n"
        "k(2.5)\n"
        "print('RESULT ' + json.dumps([v.to_numpy().tolist(), get_jit().stats['kernel_hits']]))\n")
    outs = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=dict(os.environ),
                              timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        outs.append(json.loads(next(s for s in proc.stdout.splitlines() if s.startswith("RESULT "))[7:]))
    assert outs[0] == [[[2.5, 2.5]] * 5, 0]
    assert outs[1] == [[[2.5, 2.5]] * 5, 1]


@pytest.mark.parametrize("value", [[1.0, 1.0, 1.0], [0.0, -0.0, 0.0], [1.0, 2.0, 3.0], 7.5])
@pytest.mark.parametrize("layout", ["alone", "shared_cells", "soa"])
def test_python_scope_fill_of_vector_fields(value, layout):
    """Python-scope fill of a vector field: one value for every component (written in one pass where the cells
    hold nothing else), different ones, 0.0 next to -0.0 (different bits); neighbours in the same cells (a scalar
    field placed beside it) and a struct-of-arrays layout keep their values. Compared with numpy, bit for bit."""
    ti.init(arch=ti.cpu)
    v = ti.Vector.field(3, ti.f32, shape=(7, 5), layout=ti.Layout.SOA) if layout == "soa" else \
        ti.Vector.field(3, ti.f32)
    other = ti.field(ti.f32)
    if layout == "alone":
        ti.root.dense(ti.ij, (7, 5)).place(v)
        ti.root.dense(ti.i, 4).place(other)
    elif layout == "shared_cells":
        ti.root.dense(ti.ij, (7, 5)).place(v, other)
    else:
        ti.root.dense(ti.ij, (7, 5)).place(other)
    other.fill(-4.0)
    v.fill(value)
    want = np.broadcast_to(np.asarray(value, np.float32), (7, 5, 3))
    np.testing.assert_array_equal(v.to_numpy().view(np.uint32), want.view(np.uint32))
    assert (other.to_numpy() == -4.0).all()
