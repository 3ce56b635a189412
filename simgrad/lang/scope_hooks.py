"""Python-scope services that need compiled kernels, installed by the compiler stage (lang may not import
it): `sparse` is compiler/sparse_scope.py's SparseScope (element access, to/from numpy, fill and
deactivate_all for fields and nodes under sparse SNodes)."""

from __future__ import annotations

from typing import Any

sparse: Any = None
