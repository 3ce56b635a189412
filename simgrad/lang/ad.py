"""The `ti.ad` namespace."""

from simgrad.lang.checkpoint import checkpoint
from simgrad.lang.forward_mode import FwdMode
from simgrad.lang.tape import SNodeGradType, Tape, clear_all_gradients, grad_for, grad_replaced, no_grad
from simgrad.runtime.tensors import GradPair as with_grad

__all__ = ["checkpoint", "FwdMode", "SNodeGradType", "Tape", "clear_all_gradients", "grad_for", "grad_replaced",
           "no_grad", "with_grad"]
