"""Zen's scatters (runtime/jit.py tuned_features): a loop over an interleaved 3-D grid that stores a vector
component per cell was vectorised with AVX-512 scatters, and on Zen 5 each gather after them waited for them
(diffmpm3d's grid_op 4.0 -> 0.67 ms with the stores scalarised). The IR checks run LLVM for znver5 whatever the
host is; the results are checked against numpy and finite differences on the host, at 1 and 2 threads."""

import re
import types

import llvmlite.binding as llvm
import numpy as np
import pytest

import simgrad as ti
from simgrad.runtime.jit import Jit, get_jit, tuned_features

N = 16  # grid cells per axis
BOUND = 3


def test_tuned_features():
    assert tuned_features("znver5", "+avx512f,+avx2") == "+avx512f,+avx2,+prefer-no-scatter"
    assert tuned_features("znver4", "") == "+prefer-no-scatter"
    assert tuned_features("znver5", "+avx512f,+prefer-no-scatter") == "+avx512f,+prefer-no-scatter"
    assert tuned_features("skylake-avx512", "+avx512f") == "+avx512f"
    jit = get_jit()
    assert ("+prefer-no-scatter" in jit.features.split(",")) == jit.cpu.startswith("znver")


def _grid(dtype=ti.f32, grad=False):
    """diffmpm3d's grid: three fields interleaved in one cell (and their gradients), a grid_op-like update."""
    v_in = ti.Vector.field(3, dtype)
    m_in = ti.field(dtype)
    v_out = ti.Vector.field(3, dtype)
    ti.root.dense(ti.ijk, N).place(v_in, m_in, v_out)
    if grad:
        ti.root.lazy_grad()

    @ti.kernel
    def grid_op():
        for i, j, k in m_in:
            inv_m = 1 / (m_in[i, j, k] + 1e-10)
            v = inv_m * v_in[i, j, k]
            v[1] -= 0.02
            if i < BOUND and v[0] < 0:
                v = ti.Vector([0.0, 0.0, 0.0])
            if k > N - BOUND and v[2] > 0:
                v = ti.Vector([0.0, 0.0, 0.0])
            v_out[i, j, k] = v

    return grid_op, v_in, m_in, v_out


def _reference(m, v):
    one = m.dtype.type(1)
    out = (one / (m + m.dtype.type(1e-10)))[..., None] * v
    out[..., 1] -= out.dtype.type(0.02)
    i = np.arange(N)[:, None, None]
    k = np.arange(N)[None, None, :]
    zero = ((i < BOUND) & (out[..., 0] < 0)) | ((k > N - BOUND) & (out[..., 2] > 0))
    out[zero] = 0
    return out


def _optimized_for(cpu: str, features: str, text: str) -> str:
    target = llvm.Target.from_triple(get_jit().triple)
    machine = target.create_target_machine(cpu=cpu, features=features, opt=3, reloc="default", codemodel="jitdefault")
    module = llvm.parse_assembly(text)
    module.triple = get_jit().triple
    module.data_layout = str(machine.target_data)
    Jit._optimize(types.SimpleNamespace(target_machine=machine), module)  # type: ignore[arg-type]
    return str(module).split("define internal void @sg_kernel_task1")[1].split("\n}")[0]


def test_znver_grid_loop_stores_are_not_scattered():
    if not get_jit().triple.startswith("x86_64"):
        pytest.skip("an x86 tuning")
    ti.init(arch=ti.cpu, offline_cache=False)
    grid_op = _grid()[0]
    text = grid_op._instance_for((), "").llvm_text
    tuned = _optimized_for("znver5", tuned_features("znver5", ""), text)
    assert re.search(r"<(8|16) x float>", tuned) and "masked.scatter" not in tuned  # vectorised, stores scalar
    assert "masked.scatter" in _optimized_for("znver5", "", text)  # what LLVM's own model of Zen 5 does


@pytest.mark.parametrize("threads", [1, 2])
def test_grid_op_values(threads):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, offline_cache=False)
    grid_op, v_in, m_in, v_out = _grid()
    rng = np.random.default_rng(1)
    m = (rng.random((N, N, N)) * (rng.random((N, N, N)) < 0.5)).astype(np.float32)
    v = rng.standard_normal((N, N, N, 3)).astype(np.float32)
    m_in.from_numpy(m)
    v_in.from_numpy(v)
    grid_op()
    np.testing.assert_allclose(v_out.to_numpy(), _reference(m, v), rtol=1e-6)
    assert np.all(m_in.to_numpy() == m) and np.all(v_in.to_numpy() == v)  # neighbours in the cell untouched


@pytest.mark.parametrize("threads", [1, 2])
def test_grid_op_gradient_f64(threads):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, default_fp=ti.f64, offline_cache=False)
    grid_op, v_in, m_in, v_out = _grid(ti.f64, grad=True)
    rng = np.random.default_rng(2)
    m = rng.random((N, N, N)) + 0.5
    v = rng.standard_normal((N, N, N, 3))
    w = rng.standard_normal((N, N, N, 3))
    m_in.from_numpy(m)
    v_in.from_numpy(v)
    v_out.grad.from_numpy(w)
    grid_op.grad()
    dm, dv = m_in.grad.to_numpy(), v_in.grad.to_numpy()

    def loss(m_, v_):
        return float(np.sum(_reference(m_, v_) * w))

    du_m, du_v = rng.standard_normal(m.shape), rng.standard_normal(v.shape)
    eps = 1e-6
    fd = (loss(m + eps * du_m, v + eps * du_v) - loss(m - eps * du_m, v - eps * du_v)) / (2 * eps)
    assert np.sum(dm * du_m) + np.sum(dv * du_v) == pytest.approx(fd, rel=1e-6)
