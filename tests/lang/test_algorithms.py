"""ti.algorithms (parallel_sort, PrefixSumExecutor) against numpy: np.sort and np.argsort(kind="stable") for
the sort (keys of every integer and float dtype, values moved along, fields and ndarrays, offsets, lengths
that are no power of two), np.cumsum in i32 for the scan; and the errors, located at the caller's line.

Taichi 1.7.4's own tests (tests/python/test_sort.py, test_scan.py) run through benchmarks/taichi_tests.py;
its test_scan is CUDA/Vulkan-only there, so its scenario (offset fields of 512..4096 i32) is checked here."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.algorithms import _scan as scan_module
from simgrad.algorithms import _sort as sort_module

DTYPES = {ti.i8: np.int8, ti.i16: np.int16, ti.i32: np.int32, ti.i64: np.int64, ti.u8: np.uint8,
          ti.u16: np.uint16, ti.u32: np.uint32, ti.u64: np.uint64, ti.f16: np.float16, ti.f32: np.float32,
          ti.f64: np.float64}
SIZES = [1, 2, 3, 1000, 4097, 100000]


def _keys(npdt, n: int, seed: int = 0) -> np.ndarray:
    """Keys over the dtype's whole range, a third of them from a few repeated values (stability matters),
    floats with infinities, signed zeros, subnormals and NaNs."""
    rng = np.random.default_rng(seed)
    if np.issubdtype(npdt, np.integer):
        info = np.iinfo(npdt)
        a = rng.integers(info.min, info.max, n, dtype=npdt, endpoint=True)
        rep = np.array([info.min, info.max, 0, 1, 7], dtype=npdt)
    else:
        a = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n)).astype(npdt)
        tiny = np.finfo(npdt).smallest_subnormal
        rep = np.array([np.inf, -np.inf, 0.0, -0.0, np.nan, -np.nan, tiny, -tiny, 1.5], dtype=npdt)
    pick = rng.random(n) < 1 / 3
    a[pick] = rep[rng.integers(0, len(rep), int(pick.sum()))]
    return a


def _container(kind: str, dtype, n: int, offset: int = 0):
    if kind == "field":
        return ti.field(dtype, n, offset=offset or None)
    return ti.ndarray(dtype, n)


def _check(keys_out, values_out, keys_in):
    expect = np.sort(keys_in, kind="stable")
    np.testing.assert_array_equal(keys_out, expect)  # NaNs last, as numpy puts them
    if values_out is not None:
        np.testing.assert_array_equal(values_out, np.argsort(keys_in, kind="stable"))


@pytest.mark.parametrize("dtype", list(DTYPES), ids=str)
@pytest.mark.parametrize("kind", ["field", "ndarray"])
def test_sort_keys_and_values_like_numpy(dtype, kind):
    for n in SIZES:
        a = _keys(DTYPES[dtype], n, seed=n)
        keys, values = _container(kind, dtype, n), _container(kind, ti.i32, n)
        keys.from_numpy(a)
        values.from_numpy(np.arange(n, dtype=np.int32))
        ti.algorithms.parallel_sort(keys, values)
        _check(keys.to_numpy(), values.to_numpy(), a)


@pytest.mark.parametrize("dtype", [ti.i8, ti.i32, ti.u64, ti.f16, ti.f32, ti.f64], ids=str)
@pytest.mark.parametrize("kind", ["field", "ndarray"])
def test_sort_keys_only(dtype, kind):
    for n in (3, 4097):
        a = _keys(DTYPES[dtype], n, seed=7)
        keys = _container(kind, dtype, n)
        keys.from_numpy(a)
        ti.algorithms.parallel_sort(keys)
        _check(keys.to_numpy(), None, a)


def test_sort_keeps_the_bits_of_every_key():
    """Keys are moved, not rebuilt from their order bits: -0.0 stays -0.0 (ordered as 0.0, stably) and a
    NaN keeps its payload."""
    a = np.array([0.0, 1.0, -0.0, np.nan, -1.0, 0.0, -0.0], dtype=np.float32)
    bits = a.view(np.uint32).copy()
    bits[3] = 0x7FC00123  # a quiet NaN with a payload
    a = bits.view(np.float32)
    keys = ti.field(ti.f32, len(a))
    keys.from_numpy(a)
    ti.algorithms.parallel_sort(keys)
    got = keys.to_numpy().view(np.uint32)
    expect = a[np.argsort(a, kind="stable")].view(np.uint32)
    assert got.tolist() == expect.tolist()
    assert got[-1] == 0x7FC00123 and [np.signbit(x) for x in keys.to_numpy()[1:5]] == [False, True, False, True]


@pytest.mark.parametrize("n", [0, 1])
def test_sort_of_nothing_and_of_one_element(n):
    keys, values = ti.field(ti.f32, n), ti.field(ti.i32, n)
    if n:
        keys[0], values[0] = 2.5, 9
    ti.algorithms.parallel_sort(keys, values)
    assert keys.to_numpy().tolist() == [2.5] * n and values.to_numpy().tolist() == [9] * n


@pytest.mark.parametrize("offset", [-23333, -1, 128])
@pytest.mark.parametrize("dtype", [ti.i8, ti.i32], ids=str)  # one pass (the result lands in the scratch), four
def test_sort_offset_fields_and_mixed_containers(offset, dtype):
    """Taichi's test_sort_with_offset: keys and values fields with an index offset; also keys in a field with
    values in an ndarray and the reverse, and values longer than keys (only the first n move)."""
    n = 1001
    a = _keys(DTYPES[dtype], n, seed=3)
    keys, values = ti.field(dtype, n, offset=offset), ti.field(ti.i32, n, offset=offset)
    keys.from_numpy(a)
    values.from_numpy(np.arange(n, dtype=np.int32))
    ti.algorithms.parallel_sort(keys, values)
    _check(keys.to_numpy(), values.to_numpy(), a)

    keys, values = ti.field(dtype, n, offset=offset), ti.ndarray(ti.i32, n + 5)
    keys.from_numpy(a)
    values.from_numpy(np.arange(n + 5, dtype=np.int32))
    ti.algorithms.parallel_sort(keys, values)
    _check(keys.to_numpy(), values.to_numpy()[:n], a)
    assert values.to_numpy()[n:].tolist() == list(range(n, n + 5))

    keys, values = ti.ndarray(dtype, n), ti.field(ti.i32, n, offset=offset)
    keys.from_numpy(a)
    values.from_numpy(np.arange(n, dtype=np.int32))
    ti.algorithms.parallel_sort(keys, values)
    _check(keys.to_numpy(), values.to_numpy(), a)


@pytest.mark.parametrize("kind", ["field", "ndarray"])
def test_sort_moves_vector_and_matrix_values(kind):
    n = 513
    a = _keys(np.float32, n, seed=5)
    order = np.argsort(a, kind="stable")
    vec = np.random.default_rng(1).standard_normal((n, 3)).astype(np.float32)
    mat = np.random.default_rng(2).standard_normal((n, 2, 2))
    for values, data in ((ti.Vector.field(3, ti.f32, n) if kind == "field" else ti.Vector.ndarray(3, ti.f32, n),
                          vec),
                         (ti.Matrix.field(2, 2, ti.f64, n) if kind == "field" else ti.Matrix.ndarray(2, 2, ti.f64, n),
                          mat)):
        keys = _container(kind, ti.f32, n)
        keys.from_numpy(a)
        values.from_numpy(data)
        ti.algorithms.parallel_sort(keys, values)
        np.testing.assert_array_equal(keys.to_numpy(), a[order])
        np.testing.assert_array_equal(values.to_numpy(), data[order])


def test_sort_fields_placed_together_with_an_offset():
    """Keys and vector values interleaved in one dense SNode with an index offset (a matrix field's offset is
    its components')."""
    n = 1000
    keys, values = ti.field(ti.f32), ti.Vector.field(2, ti.i32)
    ti.root.dense(ti.i, n).place(keys, values, offset=(-7,))
    a = _keys(np.float32, n, seed=9)
    keys.from_numpy(a)
    values.from_numpy(np.stack([np.arange(n), -np.arange(n)], 1).astype(np.int32))
    ti.algorithms.parallel_sort(keys, values)
    order = np.argsort(a, kind="stable")
    np.testing.assert_array_equal(keys.to_numpy(), a[order])
    np.testing.assert_array_equal(values.to_numpy(), np.stack([order, -order], 1))


def test_sort_is_stable_across_blocks_and_at_the_block_cap(monkeypatch):
    """Few distinct keys over many blocks: stability is the digit-major order of the block counts. With tiny
    blocks the count of blocks reaches its cap and blocks grow instead."""
    monkeypatch.setattr(sort_module, "_BLOCK", 3)
    for n in (700, 4097):
        a = np.random.default_rng(n).integers(-3, 3, n).astype(np.int64)
        keys, values = ti.ndarray(ti.i64, n), ti.ndarray(ti.i32, n)
        keys.from_numpy(a)
        values.from_numpy(np.arange(n, dtype=np.int32))
        ti.algorithms.parallel_sort(keys, values)
        _check(keys.to_numpy(), values.to_numpy(), a)


def test_sort_sorts_the_taichi_test_program():
    """The program of Taichi's test_sort: keys from ti.random() * N in a kernel, values equal to the keys."""
    for dtype in (ti.i32, ti.f32):
        n = 100001
        keys, values = ti.field(dtype, n), ti.field(dtype, n)

        @ti.kernel
        def fill():
            for i in keys:
                keys[i] = ti.random() * n
                values[i] = keys[i]

        fill()
        before = keys.to_numpy()
        ti.algorithms.parallel_sort(keys, values)
        k = keys.to_numpy()
        assert (k[:-1] <= k[1:]).all() and (k == values.to_numpy()).all() and (k == np.sort(before)).all()


def test_sort_errors_are_located():
    here = __file__.split("/")[-1]
    grid = ti.field(ti.f32, (4, 4))
    with pytest.raises(ti.TaichiTypeError, match=f"(?s){here}.*keys must be one-dimensional, got shape \\(4, 4\\)"):
        ti.algorithms.parallel_sort(grid)
    with pytest.raises(ti.TaichiTypeError, match="keys must be integers or floats"):
        ti.algorithms.parallel_sort(ti.Vector.field(2, ti.f32, 8))
    with pytest.raises(ti.TaichiTypeError, match="keys must be integers or floats.*got u1"):
        ti.algorithms.parallel_sort(ti.field(ti.u1, 8))
    with pytest.raises(ti.TaichiTypeError, match="keys must be a field or an ndarray"):
        ti.algorithms.parallel_sort(np.zeros(8, np.float32))
    with pytest.raises(ValueError, match="values have 4 elements, fewer than the 8 keys"):
        ti.algorithms.parallel_sort(ti.field(ti.i32, 8), ti.field(ti.i32, 4))
    with pytest.raises(ti.TaichiTypeError, match="values must be a field or an ndarray"):
        ti.algorithms.parallel_sort(ti.field(ti.i32, 8), ti.Struct.field({"a": ti.i32}, shape=8))


def test_inside_a_kernel_is_a_located_error():
    """Called from a kernel, the helpers would launch kernels while it compiles (Taichi refuses as well)."""
    x = ti.field(ti.i32, 8)

    @ti.kernel
    def sorts():
        ti.algorithms.parallel_sort(x)

    @ti.kernel
    def scans():
        ti.algorithms.PrefixSumExecutor(8).run(x)

    here = __file__.split("/")[-1]
    with pytest.raises(ti.TaichiSyntaxError, match=f"(?s){here}.*parallel_sort\\(x\\).*call it in Python scope"):
        sorts()
    with pytest.raises(ti.TaichiSyntaxError, match="PrefixSumExecutor.run launches kernels"):
        scans()


def test_on_a_tape_only_without_gradients():
    """On a Tape, sorting indices by integer keys is fine (the gradient through the gather, checked against
    central differences in f64); permuting or scanning a container with a gradient is refused (its adjoint
    zeroed the gradient: silently wrong)."""
    n = 50
    rng = np.random.default_rng(4)
    xv, kv = rng.standard_normal(n), rng.integers(0, 10, n).astype(np.int32)
    x = ti.field(ti.f64, n, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    idx, key = ti.field(ti.i32, n), ti.ndarray(ti.i32, n)

    @ti.kernel
    def energy():
        for i in x:
            loss[None] += ti.sin(x[idx[i]]) * (i + 1)

    def numpy_loss(v):
        return float((np.sin(v[np.argsort(kv, kind="stable")]) * np.arange(1, n + 1)).sum())

    x.from_numpy(xv)
    key.from_numpy(kv)
    idx.from_numpy(np.arange(n, dtype=np.int32))
    with ti.ad.Tape(loss):
        ti.algorithms.parallel_sort(key, idx)
        energy()
    h = 1e-6
    fd = [(numpy_loss(xv + h * e) - numpy_loss(xv - h * e)) / (2 * h) for e in np.eye(n)]
    np.testing.assert_allclose(x.grad.to_numpy(), fd, rtol=1e-7, atol=1e-7)
    assert loss[None] == pytest.approx(numpy_loss(xv), rel=1e-12)

    here = __file__.split("/")[-1]
    with pytest.raises(ti.SimgradNotSupportedError, match=f"(?s){here}.*parallel_sort on a ti.ad.Tape.*field x has a"):
        with ti.ad.Tape(loss):
            ti.algorithms.parallel_sort(x)
    values = ti.ndarray(ti.f32, n, needs_grad=True)
    with pytest.raises(ti.SimgradNotSupportedError, match="an ndarray has a gradient"):
        with ti.ad.Tape(loss):
            ti.algorithms.parallel_sort(key, values)
    s = ti.field(ti.i32, n)
    with ti.ad.Tape(loss):
        ti.algorithms.PrefixSumExecutor(n).run(s)  # no gradient: fine


@pytest.mark.parametrize("kind", ["field", "ndarray"])
def test_prefix_sum_like_numpy(kind):
    for n in SIZES:
        a = np.random.default_rng(n).integers(-1000, 1000, n, dtype=np.int32)
        arr = _container(kind, ti.i32, n)
        arr.from_numpy(a)
        ti.algorithms.PrefixSumExecutor(n).run(arr)
        np.testing.assert_array_equal(arr.to_numpy(), np.cumsum(a, dtype=np.int32))


@pytest.mark.parametrize("offset", [0, -1, 1, 256, -256, -23333, 23333])
def test_prefix_sum_of_the_taichi_test_program(offset):
    """Taichi's test_scan_with_offset (run there on CUDA/Vulkan only): ti.random() * N in an offset field,
    one executor reused."""
    for n in (512, 1024, 4096):
        arr, aux = ti.field(ti.i32, n, offset=offset), ti.field(ti.i32, n, offset=offset)

        @ti.kernel
        def fill():
            for i in arr:
                arr[i] = ti.random() * n
                aux[i] = arr[i]

        fill()
        executor = ti.algorithms.PrefixSumExecutor(n)
        executor.run(arr)
        np.testing.assert_array_equal(arr.to_numpy(), np.cumsum(aux.to_numpy(), dtype=np.int32))
        fill()
        executor.run(arr)
        np.testing.assert_array_equal(arr.to_numpy(), np.cumsum(aux.to_numpy(), dtype=np.int32))


def test_prefix_sum_scans_the_executor_length_and_wraps_as_i32(monkeypatch):
    monkeypatch.setattr(scan_module, "_BLOCK", 3)  # many blocks, then the cap of blocks
    for n in (10, 1000, 4097):
        a = np.random.default_rng(n).integers(2**30, 2**31 - 1, n + 7, dtype=np.int32)
        arr = ti.ndarray(ti.i32, n + 7)
        arr.from_numpy(a)
        ti.algorithms.PrefixSumExecutor(n).run(arr)
        expect = np.concatenate([np.cumsum(a[:n], dtype=np.int32), a[n:]])
        np.testing.assert_array_equal(arr.to_numpy(), expect)
    empty = ti.field(ti.i32, 0)
    ti.algorithms.PrefixSumExecutor(0).run(empty)


def test_prefix_sum_errors_are_taichis():
    here = __file__.split("/")[-1]
    with pytest.raises(RuntimeError, match=f"(?s){here}.*Only ti.i32 type is supported for prefix sum."):
        ti.algorithms.PrefixSumExecutor(8).run(ti.field(ti.f32, 8))
    with pytest.raises(ti.TaichiRuntimeError, match="Only ti.i32 type is supported for prefix sum."):
        ti.algorithms.PrefixSumExecutor(8).run(ti.ndarray(ti.i64, 8))
    with pytest.raises(ValueError, match=r"PrefixSumExecutor\(9\).run: the array has only 8 elements"):
        ti.algorithms.PrefixSumExecutor(9).run(ti.field(ti.i32, 8))
    with pytest.raises(ti.TaichiTypeError, match="one-dimensional"):
        ti.algorithms.PrefixSumExecutor(8).run(ti.field(ti.i32, (8, 2)))
    with pytest.raises(ti.TaichiTypeError, match="takes scalars"):
        ti.algorithms.PrefixSumExecutor(8).run(ti.Vector.field(2, ti.i32, 8))
    with pytest.raises(ValueError, match="non-negative integer"):
        ti.algorithms.PrefixSumExecutor(-1)


def test_algorithms_has_taichis_public_names():
    """Taichi 1.7.4's dir(taichi.algorithms) shows exactly these two public names (its test_api checks it)."""
    assert [s for s in dir(ti.algorithms) if not s.startswith("_")] == ["PrefixSumExecutor", "parallel_sort"]
    assert ti.algorithms.__all__ == ["parallel_sort", "PrefixSumExecutor"]
    assert callable(ti.algorithms.parallel_sort) and isinstance(ti.algorithms.PrefixSumExecutor, type)


def test_on_the_simulated_gpu_and_through_ptxas(monkeypatch):
    """arch=cuda (SIMGRAD_GPU_SIM=1): the kernels as grid-stride GPU kernels (a block's serial loops in one
    thread), every one also assembled by ptxas for sm_80/sm_90 when ptxas is here (SIMGRAD_PTX_CHECK=1)."""
    from simgrad.codegen import nvptx

    monkeypatch.setenv("SIMGRAD_GPU_SIM", "1")
    if nvptx.ptxas_path() is not None:
        monkeypatch.setenv("SIMGRAD_PTX_CHECK", "1")
    ti.init(arch=ti.cuda)
    assert ti.lang.impl.current_cfg().arch is ti.cuda
    n = 40000
    a = _keys(np.float32, n, seed=11)
    keys, values = ti.field(ti.f32, n, offset=-5), ti.ndarray(ti.i32, n)
    keys.from_numpy(a)
    values.from_numpy(np.arange(n, dtype=np.int32))
    ti.algorithms.parallel_sort(keys, values)
    _check(keys.to_numpy(), values.to_numpy(), a)
    b = np.random.default_rng(2).integers(-9, 9, 70000, dtype=np.int32)
    arr = ti.ndarray(ti.i32, 70000)
    arr.from_numpy(b)
    ti.algorithms.PrefixSumExecutor(70000).run(arr)
    np.testing.assert_array_equal(arr.to_numpy(), np.cumsum(b, dtype=np.int32))


def test_the_algorithms_are_kernels_not_numpy():
    """The package imports no numpy: sorting and scanning happen in simgrad kernels (the brief of issue 23)."""
    import ast
    import pathlib

    pkg = pathlib.Path(sort_module.__file__).parent
    for path in pkg.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            assert not any(n.split(".")[0] == "numpy" for n in names), f"{path.name} imports numpy"


def test_debug_mode_index_checks_stay_quiet():
    """ti.init(debug=True) checks every index the kernels use: none is out of bounds (offsets, values longer
    than the keys, one pass ending in the scratch buffer)."""
    ti.init(arch=ti.cpu, debug=True)
    n = 3001
    a = _keys(np.int8, n, seed=12)
    keys, values = ti.field(ti.i8, n, offset=-50), ti.Vector.ndarray(2, ti.f32, n + 3)
    vals = np.random.default_rng(0).standard_normal((n + 3, 2)).astype(np.float32)
    keys.from_numpy(a)
    values.from_numpy(vals)
    ti.algorithms.parallel_sort(keys, values)
    order = np.argsort(a, kind="stable")
    np.testing.assert_array_equal(keys.to_numpy(), a[order])
    np.testing.assert_array_equal(values.to_numpy()[:n], vals[order])
    x = ti.field(ti.i32, 5000, offset=7)
    b = np.random.default_rng(1).integers(-9, 9, 5000, dtype=np.int32)
    x.from_numpy(b)
    ti.algorithms.PrefixSumExecutor(4000).run(x)
    np.testing.assert_array_equal(x.to_numpy(), np.r_[np.cumsum(b[:4000], dtype=np.int32), b[4000:]])
