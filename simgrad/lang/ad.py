"""The `ti.ad` namespace."""

from simgrad.lang.tape import Tape, clear_all_gradients, grad_for, grad_replaced, no_grad

__all__ = ["Tape", "clear_all_gradients", "grad_for", "grad_replaced", "no_grad"]
