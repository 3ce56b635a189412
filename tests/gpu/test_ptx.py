"""SIMGRAD_PTX_CHECK=1: every kernel the representative set compiles is also lowered to PTX and assembled with
ptxas for sm_80 and sm_90 (issue 22, 4a)."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.codegen import nvptx
from tests.gpu.kernels import CASES

pytestmark = pytest.mark.skipif(nvptx.ptxas_path() is None, reason="ptxas not found (CUDA toolkit or the "
                                "nvidia-cuda-nvcc wheel provides it): the PTX check cannot run here")


@pytest.fixture
def ptx_check(monkeypatch):
    monkeypatch.setenv("SIMGRAD_PTX_CHECK", "1")
    calls = []
    real = nvptx.ptxas_check

    def counting(ptx, archs=("sm_80", "sm_90")):
        calls.append(ptx)
        real(ptx, archs)

    monkeypatch.setattr(nvptx, "ptxas_check", counting)
    yield calls


@pytest.mark.parametrize("case", CASES, ids=[c.__name__ for c in CASES])
def test_kernels_assemble_for_sm80_and_sm90(ptx_check, case):
    for got, ref, tol in case():  # the CPU still computes the answers
        np.testing.assert_allclose(np.asarray(got, np.float64), np.asarray(ref, np.float64), rtol=tol, atol=tol)
    assert ptx_check, "no kernel went through ptxas"
    for ptx in ptx_check:
        assert ".entry" in ptx and ".extern .func __nv_" not in ptx  # libdevice linked in, not left external


def test_ptx_shape(ptx_check):
    x = ti.field(ti.f32, shape=1000)

    @ti.kernel
    def k():
        for i in x:
            x[i] = ti.sin(i * 0.5)

    k()
    (ptx,) = ptx_check
    assert "%ctaid.x" in ptx and "%ntid.x" in ptx and "%nctaid.x" in ptx and "%tid.x" in ptx
    assert "sinf" not in ptx.split(".entry")[0] or "__nv_sinf" not in ptx  # inlined from libdevice


def test_print_is_vprintf_with_its_argument_buffer(ptx_check):
    x = ti.field(ti.f32, shape=4)

    @ti.kernel
    def k(a: ti.i64):
        for i in range(4):
            print("i =", i, x[i], a, ti.cast(i, ti.i8))

    k(7)
    (ptx,) = ptx_check
    assert ".extern .func  (.param .b32 func_retval0) vprintf" in ptx and "call.uni (retval0), vprintf" in ptx
    # the buffer holds i32, double (the promoted f32) and i64, each at its natural alignment, then an i32
    assert ".local .align 8 .b8" in ptx


def test_ptxas_error_raises():
    with pytest.raises(RuntimeError, match="ptxas -arch=sm_80 rejected"):
        nvptx.ptxas_check(".version 7.0\n.target sm_80\n.address_size 64\n.visible .entry k() { bogus; }\n")


@pytest.mark.parametrize("flush", [True, False])
def test_flush_to_zero_is_the_ftz_forms_for_f32_only(ptx_check, flush):
    """ti.init(flush_denormals=...) on the GPU (runtime/fpenv.py): f32 arithmetic in PTX's .ftz forms and
    libdevice's FTZ paths (nvvm-reflect-ftz), as Taichi's CUDA backend; f64 has no .ftz form and stays IEEE."""
    ti.init(arch=ti.cpu, flush_denormals=flush)
    x = ti.field(ti.f32, shape=64)
    y = ti.field(ti.f64, shape=64)

    @ti.kernel
    def k(u: ti.f32, v: ti.f64):
        for i in x:
            x[i] = u * i / (u + 1.0) + ti.exp(u * i)
            y[i] = v * i / (v + 1.0)

    k(0.5, 0.25)
    (ptx,) = ptx_check
    f32_ops = [ln for ln in ptx.splitlines() if ln.strip().startswith(("mul.", "div.", "add.", "fma."))
               and ".f32" in ln]
    f64_ops = [ln for ln in ptx.splitlines() if ".f64" in ln and ln.strip().startswith(("mul.", "div.", "add."))]
    assert f32_ops and f64_ops
    assert all(".ftz" in ln for ln in f32_ops) == flush and any(".ftz" in ln for ln in f32_ops) == flush
    assert not any(".ftz" in ln for ln in f64_ops)
