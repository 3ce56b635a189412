"""``ti._lib``: stand-ins for the parts of Taichi's C++ core module that programs probe directly."""

from . import core, utils

__all__ = ["core", "utils"]
