"""Architectures. Only the CPU backend exists today: asking for another falls back with a warning, as
Taichi does when a backend is unavailable."""

from __future__ import annotations

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


def resolve(arch) -> Arch:
    if arch is None:
        return cpu
    if isinstance(arch, (list, tuple)):
        for a in arch:
            if a.name in _CPU:
                return cpu
        arch = arch[0] if arch else cpu
    if arch.name in _CPU:
        return cpu
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
    return resolve(arch) is cpu and ext in _SUPPORTED
