"""Shared helpers of the reverse-mode tests (imported by the test modules of this folder)."""

from __future__ import annotations

import numpy as np

import simgrad as ti


def f64():
    """Re-initialise with f64 defaults (the autouse fixture initialised with f32)."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)


def rel_err(a, b, floor: float = 1e-12) -> float:
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), floor)))


def fd_grad(loss, field, eps: float = 1e-6):
    """Central finite differences of the Python callable `loss()` w.r.t. every entry of `field`."""
    base = field.to_numpy().astype(np.float64)
    g = np.zeros_like(base)
    flat = g.reshape(-1)
    for k in range(base.size):
        for sign in (1.0, -1.0):
            p = base.copy().reshape(-1)
            p[k] += sign * eps
            field.from_numpy(p.reshape(base.shape).astype(field.dtype.np))
            flat[k] += sign * loss() / (2 * eps)
    field.from_numpy(base.astype(field.dtype.np))
    return g


def assert_finite(*arrays):
    for a in arrays:
        a = np.asarray(a)
        assert np.all(np.isfinite(a)), f"non-finite gradient entries: {a}"
