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
