"""The one hook kernels call on launch so a Tape can record them (None when no tape is recording)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

# `recorder(kernel, args)`; a bound method whose owner also has `insert(fn, args)` (grad_replaced units)
recorder: Callable[[Any, tuple], None] | None = None

# the ti.ad.FwdMode being entered (None outside): kernels launched meanwhile run their forward-mode instance
forward_mode = None

# `zero_fields(groups)`: zeroes groups of scalar fields placed under one SNode each with one compiled kernel
# (compiler/fill.py installs it); clear_all_gradients uses it for large gradients
zero_fields: Callable[[list], None] | None = None
