"""Architectures. The CPU backend, and arch=cuda / ti.gpu (issue 22): the GPU when a CUDA driver and a device
exist (and simgrad's GPU runtime is built), else the simulated GPU when SIMGRAD_GPU_SIM=1, else the CPU with
one warning, as Taichi does when a backend is unavailable. TI_ARCH=cuda overrides the arch ti.init asks for.
`current_cfg().arch` is ti.cuda on the GPU and the simulated GPU, the CPU arch after a fallback."""

from __future__ import annotations

import os
import platform
import warnings
from enum import Enum


class Arch:
    def __init__(self, name: str):
        self.name = name

    def __repr__(self):
        return self.name


x64 = Arch("x64")
arm64 = Arch("arm64")
cuda = Arch("cuda")
vulkan = Arch("vulkan")
metal = Arch("metal")
opengl = Arch("opengl")
gles = Arch("gles")
dx11 = Arch("dx11")
dx12 = Arch("dx12")
amdgpu = Arch("amdgpu")
cpu = x64 if platform.machine().lower() in ("x86_64", "amd64") else arm64
gpu = Arch("gpu")

_CPU = {x64.name, arm64.name}


_BY_NAME = {a.name: a for a in (x64, arm64, cuda, vulkan, metal, opengl, gles, dx11, dx12, amdgpu, gpu)}
_BY_NAME["cpu"] = cpu


def requested(arch):
    """The arch to resolve: TI_ARCH (as in Taichi) overrides what ti.init asked for."""
    env = os.environ.get("TI_ARCH", "").strip().lower()
    if env:
        if env not in _BY_NAME:
            raise ValueError(f"TI_ARCH={env!r} is not an arch ({', '.join(sorted(_BY_NAME))})")
        return _BY_NAME[env]
    return arch


def gpu_mode() -> str | None:
    """How arch=cuda can run here: "cuda" (a GPU and the runtime), "sim" (SIMGRAD_GPU_SIM=1) or None."""
    from simgrad.runtime import device

    if device.cuda_runtime_enabled() and device.cuda_available():
        return "cuda"
    if device.sim_requested():
        return "sim"
    return None


def resolve(arch, enable_fallback: bool = True) -> Arch:
    """The arch a program runs on: the CPU, or the (simulated) GPU where available; another arch falls back to the
    CPU with a warning, or is Taichi's RuntimeError with ti.init(enable_fallback=False)."""
    arch = requested(arch)
    if arch is None:
        return cpu
    if isinstance(arch, (list, tuple)):  # the first that is available, in order
        for a in arch:
            if a.name in _CPU:
                return cpu
            if a.name in ("cuda", "gpu") and gpu_mode() is not None:
                return cuda
        arch = arch[0] if arch else cpu
    if arch.name in _CPU:
        return cpu
    if arch.name in ("cuda", "gpu") and gpu_mode() is not None:
        return cuda
    if not enable_fallback:
        from simgrad.errors import SimgradRuntimeError

        raise SimgradRuntimeError(f"Arch={arch.name} is not supported (simgrad runs on the CPU, and on CUDA where "
                                  "enabled), and fallback is disabled")
    warnings.warn(f"arch={arch.name} is not available in this build of simgrad; falling back to the CPU "
                  f"({cpu.name})", stacklevel=4)
    return cpu


class extension(Enum):  # noqa: N801  (Taichi's name: ti.extension.sparse, ...)
    """Optional backend features, as Taichi names them (`require=ti.extension.adstack` in its tests)."""

    sparse = "sparse"
    quant = "quant"
    quant_basic = "quant_basic"
    data64 = "data64"
    adstack = "adstack"
    bls = "bls"
    assertion = "assertion"
    extfunc = "extfunc"
    mesh = "mesh"
    dynamic_index = "dynamic_index"


# what the CPU backend has today (sparse SNodes and quantized types are not built yet)
_SUPPORTED = {extension.data64, extension.adstack, extension.assertion, extension.dynamic_index, extension.bls}


def is_extension_supported(arch, ext: extension) -> bool:
    if arch is cuda or getattr(arch, "name", None) == "gpu":
        return gpu_mode() is not None and ext in _SUPPORTED and ext is not extension.bls
    return resolve(arch) is cpu and ext in _SUPPORTED
