"""Gradient checking for users and tests: reverse-mode gradients against central finite differences.

`check_grads(forward, inputs, outputs)` runs `forward()` (which must recompute `outputs` from `inputs`
from scratch each time) under a Tape, seeds each output's gradient with random weights w, and compares
the directional derivative along a random direction d of the inputs:

    AD = sum_k <grad_k, d_k>          FD = (L(x + eps d) - L(x - eps d)) / (2 eps),  L = sum <w, outputs>

and requires |AD - FD| <= atol + rtol * |FD| (the inner-product identity: one comparison per direction,
however many inputs there are). Use float64 fields for tight tolerances.
"""

from __future__ import annotations

import numpy as np

from simgrad.lang.tape import Tape


def _loss(outputs, weights) -> float:
    return float(sum(np.sum(o.to_numpy().astype(np.float64) * w) for o, w in zip(outputs, weights)))


def check_grads(forward, inputs, outputs, *, eps: float = 1e-6, rtol: float = 1e-5, atol: float = 1e-9,
                directions: int = 2, seed: int = 0, weights=None):
    """Assert that reverse-mode gradients of `outputs` w.r.t. `inputs` match finite differences.

    Returns the list of (AD, FD) pairs, one per random direction."""
    rng = np.random.default_rng(seed)
    if weights is None:
        weights = [rng.standard_normal(o.to_numpy().shape) if o.shape or hasattr(o, "n") else
                   np.array(rng.standard_normal()) for o in outputs]
    base = [x.to_numpy().astype(np.float64) for x in inputs]

    tape = Tape(loss=None, clear_gradients=True)
    with tape:
        forward()
    for o, w in zip(outputs, weights):
        o.grad.from_numpy(np.asarray(w, dtype=o.dtype.np).reshape(o.grad.to_numpy().shape))
    tape.grad()
    grads = [x.grad.to_numpy().astype(np.float64) for x in inputs]

    results = []
    try:
        for _ in range(directions):
            d = [rng.standard_normal(b.shape) for b in base]
            ad = float(sum(np.sum(g * dk) for g, dk in zip(grads, d)))
            vals = []
            for sign in (1.0, -1.0):
                for x, b, dk in zip(inputs, base, d):
                    x.from_numpy((b + sign * eps * dk).astype(x.dtype.np))
                forward()
                vals.append(_loss(outputs, weights))
            fd = (vals[0] - vals[1]) / (2 * eps)
            results.append((ad, fd))
            if not abs(ad - fd) <= atol + rtol * abs(fd):
                raise AssertionError(f"gradient check failed: AD {ad!r} vs finite differences {fd!r} "
                                     f"(|diff| {abs(ad - fd):.3e} > atol {atol} + rtol {rtol} * |FD|)")
    finally:
        for x, b in zip(inputs, base):
            x.from_numpy(b.astype(x.dtype.np))
    return results
