"""simgrad on Ray: many simulations and gradients across processes and machines (issue 26).

A simgrad program cannot be sent to another process (its fields and kernels are native state of this one),
so a worker builds it itself: `build()` runs once in each worker and returns the function
`f(params: dict[str, np.ndarray]) -> (loss: float, grads: dict[str, np.ndarray])`. Only numpy arrays and
plain values cross processes. Ray (the `ray` extra) is imported here and nowhere in simgrad's core.

    from simgrad.distributed import map_value_and_grad
    results = map_value_and_grad(build, params_list)   # [(loss, grads), ...] in the order of params_list
"""

from __future__ import annotations

try:
    import ray  # noqa: F401
except ImportError as e:  # pragma: no cover - exercised by a test that hides ray
    raise ImportError("simgrad.distributed needs Ray: install it with `pip install simgrad[ray]` "
                      "(or `pip install ray`)") from e

from simgrad.distributed.pool import WorkerPool, imap_value_and_grad, map_value_and_grad
from simgrad.distributed.worker import Served, Worker, from_fields

__all__ = ["Served", "Worker", "WorkerPool", "from_fields", "imap_value_and_grad", "map_value_and_grad"]
