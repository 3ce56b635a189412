"""scipy, imported when a sparse matrix is first needed: simgrad itself does not depend on it."""

from __future__ import annotations

from typing import Any


def sparse() -> Any:
    """The scipy.sparse module, or a clear ImportError naming the extra that installs it."""
    try:
        import scipy.sparse
    except ImportError as e:
        raise ImportError("ti.linalg's sparse matrices and solvers need scipy, which is not installed: "
                          "pip install simgrad[linalg] (or pip install scipy)") from e
    return scipy.sparse


def sparse_linalg() -> Any:
    sparse()
    import scipy.sparse.linalg

    return scipy.sparse.linalg


def dense_linalg() -> Any:
    sparse()
    import scipy.linalg

    return scipy.linalg
