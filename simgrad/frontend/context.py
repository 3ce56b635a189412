"""The kernel under construction: the IR builder that operators emit into, and the source location."""

from __future__ import annotations

from simgrad.errors import Loc

_stack: list = []


def push(compiler) -> None:
    _stack.append(compiler)


def pop() -> None:
    _stack.pop()


def current():
    """The active kernel compiler, or None in Python scope."""
    return _stack[-1] if _stack else None


def builder():
    return _stack[-1].builder


def current_loc() -> Loc | None:
    return _stack[-1].builder.loc if _stack else None


def in_kernel() -> bool:
    return bool(_stack)
