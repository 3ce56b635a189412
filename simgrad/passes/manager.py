"""The pass pipeline: one readable function, one line per pass."""

from __future__ import annotations

import os

from simgrad.ir.nodes import Kernel
from simgrad.ir.printer import print_kernel


def _debug() -> int:
    try:
        return int(os.environ.get("SIMGRAD_DEBUG", "0"))
    except ValueError:
        return 0


def run_pipeline(kernel: Kernel, transform=None) -> None:
    from simgrad.passes import simplify, verify

    level = _debug()
    steps = [
        ("verify", verify.verify),  # structural and type invariants of the frontend's output
        ("simplify", simplify.simplify),  # constant folding, algebraic identities, CSE, DCE
    ]
    if transform is not None:
        steps += [(getattr(transform, "__name__", "transform"), transform), ("verify", verify.verify),
                  ("simplify", simplify.simplify)]
    steps.append(("verify", verify.verify))
    for name, fn in steps:
        if level >= 1:
            print(f"[simgrad] {kernel.name}: {name}")
        fn(kernel)
        if level >= 2:
            print(print_kernel(kernel))
