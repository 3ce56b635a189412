"""Hand-written LLVM IR, kept as `.ll` files beside this module (shipped as package data) so that it reads,
diffs and is checked as LLVM IR rather than as Python strings.

A file may name parameters as `${name}` (string.Template); `load` substitutes every one and refuses a file
whose parameters are not all given, or a parameter the file does not use. The parameters are a few numbers
and spellings that depend on the machine or on layouts defined in Python (context slots, pool words)."""

from __future__ import annotations

import string
from functools import cache
from importlib import resources


@cache
def source(name: str) -> str:
    """The text of `<name>.ll`, parameters unsubstituted."""
    return resources.files(__name__).joinpath(f"{name}.ll").read_text(encoding="utf-8")


def parameters(name: str) -> set[str]:
    """The parameter names `<name>.ll` uses."""
    pattern = string.Template.pattern
    return {m.group("braced") or m.group("named") for m in pattern.finditer(source(name))
            if m.group("braced") or m.group("named")}


def load(name: str, **params: object) -> str:
    """`<name>.ll` with each `${key}` replaced by `str(params[key])`."""
    unused = set(params) - parameters(name)
    if unused:
        raise TypeError(f"{name}.ll has no parameter(s) {sorted(unused)}")
    return string.Template(source(name)).substitute({k: str(v) for k, v in params.items()})
