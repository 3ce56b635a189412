"""``ti.experimental``: what Taichi 1.7.4 still has there, ``real_func``, deprecated (it is ``ti.real_func`` now)."""

import warnings

from simgrad.lang.functions import real_func as _real_func

__all__ = ["real_func"]


def real_func(fn):
    """``ti.real_func`` with Taichi's DeprecationWarning."""
    warnings.warn("ti.experimental.real_func is deprecated because it is no longer experimental. Use ti.real_func "
                  "instead.", DeprecationWarning, stacklevel=2)
    return _real_func(fn)
