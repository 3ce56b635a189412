"""Automatic differentiation of kernels (reverse mode in the IR) and the Tape across launches."""

from simgrad.autodiff import api  # noqa: F401
