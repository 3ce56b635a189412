"""Arch selection (issue 22): ti.cuda / ti.gpu / TI_ARCH=cuda, the simulated GPU, the CPU fallback."""

import warnings

import pytest

import simgrad as ti
from simgrad.runtime import device


@pytest.fixture
def no_gpu(monkeypatch):
    monkeypatch.delenv("SIMGRAD_GPU_SIM", raising=False)
    monkeypatch.delenv("TI_ARCH", raising=False)
    monkeypatch.setattr(device, "cuda_available", lambda: False)


@pytest.mark.parametrize("arch", ["cuda", "gpu"])
def test_fallback_warns_once(no_gpu, arch):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        ti.init(arch=getattr(ti, arch))
    assert len([x for x in w if "falling back to the CPU" in str(x.message)]) == 1
    assert ti.lang.impl.current_cfg().arch is ti.cpu


@pytest.mark.parametrize("arch", ["cuda", "gpu"])
def test_simulated_gpu(no_gpu, monkeypatch, arch):
    monkeypatch.setenv("SIMGRAD_GPU_SIM", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ti.init(arch=getattr(ti, arch))
    assert ti.lang.impl.current_cfg().arch is ti.cuda


def test_ti_arch_overrides(no_gpu, monkeypatch):
    monkeypatch.setenv("SIMGRAD_GPU_SIM", "1")
    monkeypatch.setenv("TI_ARCH", "cuda")
    ti.init(arch=ti.cpu)
    assert ti.lang.impl.current_cfg().arch is ti.cuda
    monkeypatch.delenv("SIMGRAD_GPU_SIM")
    with pytest.warns(UserWarning, match="falling back"):
        ti.init(arch=ti.cpu)
    assert ti.lang.impl.current_cfg().arch is ti.cpu


def test_real_gpu_waits_for_the_runtime(no_gpu, monkeypatch):
    """A present GPU is used only once the CUDA launcher exists (device.CUDA_RUNTIME_READY)."""
    monkeypatch.setattr(device, "cuda_available", lambda: True)
    monkeypatch.setattr(device, "CUDA_RUNTIME_READY", False)
    with pytest.warns(UserWarning, match="falling back"):
        ti.init(arch=ti.cuda)
    monkeypatch.setenv("SIMGRAD_CUDA_RUNTIME", "1")  # the device check's switch
    assert ti.lang.archs.gpu_mode() == "cuda"
    monkeypatch.delenv("SIMGRAD_CUDA_RUNTIME")
    monkeypatch.setattr(device, "CUDA_RUNTIME_READY", True)
    assert ti.lang.archs.gpu_mode() == "cuda"


def test_arch_list_takes_the_first_available(no_gpu, monkeypatch):
    ti.init(arch=[ti.cpu, ti.cuda])
    assert ti.lang.impl.current_cfg().arch is ti.cpu
    monkeypatch.setenv("SIMGRAD_GPU_SIM", "1")
    ti.init(arch=[ti.cuda, ti.cpu])
    assert ti.lang.impl.current_cfg().arch is ti.cuda
    ti.init(arch=[ti.vulkan, ti.cpu])
    assert ti.lang.impl.current_cfg().arch is ti.cpu
