"""``ti._lib.core``: Taichi programs choose a backend with ``ti._lib.core.with_vulkan()`` and friends; simgrad
compiles for the CPU only, so every GPU probe answers False (and such programs fall back to ``ti.cuda``,
which ``ti.init`` maps to the CPU).  GGUI is available: ``ti.ui`` renders on the CPU."""

from simgrad.errors import TaichiRuntimeError  # noqa: F401  (Taichi's core module exports its error class)

GGUI_AVAILABLE = True


def with_vulkan() -> bool:
    return False


def with_cuda() -> bool:
    return False


def with_metal() -> bool:
    return False


def with_opengl() -> bool:
    return False


def with_dx11() -> bool:
    return False


def with_dx12() -> bool:
    return False


def with_amdgpu() -> bool:
    return False


def get_max_num_indices() -> int:
    """Taichi's cap on a field's dimensionality (12; ti.field(shape=(1,) * 13) is its RuntimeError). simgrad has
    no cap, so every program written within Taichi's runs here."""
    return 12


TAICHI_VERSION = (1, 7, 4)  # the Taichi release whose language and API simgrad follows


def get_version_major() -> int:
    return TAICHI_VERSION[0]


def get_version_minor() -> int:
    return TAICHI_VERSION[1]


def get_version_patch() -> int:
    return TAICHI_VERSION[2]
