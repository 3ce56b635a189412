"""The `ti.ad` namespace."""

from simgrad.autodiff.tape import Tape, clear_all_gradients, grad_for, grad_replaced, no_grad

__all__ = ["Tape", "clear_all_gradients", "grad_for", "grad_replaced", "no_grad"]
