"""The kernel under construction: a stack of the compilers whose builder operators emit into (anything with
`.builder`), and the source location. In ir/ so that lang operators and the IR builder meet without lang
depending on the frontend. errors.py sits below ir and asks whether a kernel is compiling through the
`errors.compiling` hook this module installs."""

from __future__ import annotations

from simgrad import errors
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


errors.compiling = in_kernel
