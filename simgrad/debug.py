"""The one reader of SIMGRAD_DEBUG (a leaf module: every stage may ask it)."""

from __future__ import annotations

import os


def debug_level() -> int:
    """SIMGRAD_DEBUG: 1 names passes, 2 prints IR after each, 3 the optimised LLVM IR, 4 the assembly.
    Any level > 0 bypasses the kernel cache (compiler/driver.py) so the passes run and print; the object
    cache still serves native code, and 3/4 print on its hits too."""
    try:
        return int(os.environ.get("SIMGRAD_DEBUG", "0"))
    except ValueError:
        return 0
