"""Zeroing large gradients by a compiled kernel, which the lang stage reaches through
lang/ad_hooks.zero_fields (a Tape clears every gradient on entry).

Gradients placed beside their primals (`ti.root.dense(...).place(x, v, C, F)` then `lazy_grad()`) are
interleaved with them: numpy, zeroing one strided component at a time, walks the whole tree once per
component (12 passes over 1.2 GB for DiffTaichi's diffmpm). The kernel visits each cell once, in
parallel, and zeroes every gradient component placed in it."""

from __future__ import annotations

from simgrad.compiler.kernel import kernel
from simgrad.lang import ad_hooks
from simgrad.lang.loops import grouped, static
from simgrad.lang.types import template


@kernel
def _zero(groups: template()):  # type: ignore[valid-type]
    for group in static(groups):
        for I in grouped(group[0]):
            for f in static(group):
                f[I] = 0


def zero_fields(groups: list[tuple]) -> None:
    """Zero each group of scalar fields (the components placed under one SNode, so of one shape) in one
    pass over its cells; compiled once per set of groups, never recorded by a Tape."""
    outer, ad_hooks.recorder = ad_hooks.recorder, None
    try:
        _zero(tuple(tuple(g) for g in groups))
    finally:
        ad_hooks.recorder = outer


ad_hooks.zero_fields = zero_fields
