"""ti.ad.FwdMode: forward-mode differentiation (Jacobian-vector products), as Taichi spells it.

Inside `with ti.ad.FwdMode(loss=y, param=x, seed=[...])` every kernel launch runs its forward-mode instance
(autodiff/forward.py), which computes the fields' duals beside their values: afterwards `y.dual` holds
J(x) . seed for every loss field `y`. The seed is written into `x.dual` on entry and cleared on exit.
"""

from __future__ import annotations

import numpy as np

from simgrad.errors import SimgradError, caller_loc
from simgrad.lang import ad_hooks
from simgrad.lang.field import ScalarField
from simgrad.lang.tape import SNodeGradType, clear_all_gradients


class FwdMode:
    def __init__(self, loss, param, seed=None, clear_gradients: bool = True):
        self.loss = loss if isinstance(loss, list) else [loss]
        self.param = param
        self.seed = None if seed is None else [float(v) for v in seed]
        self.clear_gradients = clear_gradients
        self.entered = False
        self._outer = None

    def __enter__(self):
        if self.entered:
            raise SimgradError("a FwdMode can be entered only once", caller_loc())
        self.entered = True
        for f in self.loss + [self.param]:
            if not isinstance(f, ScalarField):
                raise SimgradError(f"FwdMode takes scalar fields for loss and param, got {type(f).__name__} "
                                   "(as Taichi: one N-d scalar field of parameters)", caller_loc())
            if f.dual is None or f.dual.snode is None:
                raise SimgradError(f"field {f.name} has no dual: create it with needs_dual=True or call "
                                   "ti.root.lazy_dual() after placing it", caller_loc())
        size = int(np.prod(self.param.shape)) if self.param.shape else 1
        if self.seed is None:
            if size != 1:
                raise SimgradError(f"FwdMode needs a seed of {size} values for the parameter field "
                                   f"{self.param.name} of shape {self.param.shape} (which direction to "
                                   "differentiate along)", caller_loc())
            self.seed = [1.0]
        elif len(self.seed) != size:
            raise SimgradError(f"the seed has {len(self.seed)} values, the parameter field {self.param.name} "
                               f"{size}", caller_loc())
        if self.clear_gradients:
            clear_all_gradients(SNodeGradType.DUAL)
        self._write_seed(self.seed)
        self._outer, ad_hooks.forward_mode = ad_hooks.forward_mode, self
        return self

    def _write_seed(self, values: list) -> None:
        dual = self.param.dual
        dual.from_numpy(np.asarray(values, dtype=dual.dtype.np).reshape(self.param.shape))

    def __exit__(self, exc_type, exc, tb):
        ad_hooks.forward_mode = self._outer
        self._write_seed([0.0] * len(self.seed or []))
        return False
