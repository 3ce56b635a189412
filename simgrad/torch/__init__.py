"""simgrad.torch: simgrad kernels inside torch autograd graphs (`@simgrad.torch.function`, bridge.py).

Imported only on use (`simgrad.torch` or `ti.torch` loads it) and only where torch is installed; kernels take
torch tensors as `ti.types.ndarray()` arguments without this module (runtime/tensors.py)."""

try:
    import torch as _torch  # noqa: F401 (the real torch: absolute imports skip this package)
except ImportError as e:  # pragma: no cover - the test extra installs torch
    raise ImportError("simgrad.torch needs PyTorch (pip install torch, or simgrad[torch])") from e

from simgrad.torch.bridge import Function, function

__all__ = ["Function", "function"]
