"""A Python function's source as an AST whose line and column numbers match the user's file."""

from __future__ import annotations

import ast
import inspect
import textwrap
from dataclasses import dataclass

from simgrad.errors import Loc, SimgradSyntaxError


@dataclass
class FunctionSource:
    func: object
    file: str
    tree: ast.FunctionDef | ast.AsyncFunctionDef
    globals: dict
    closure: dict
    text: str = ""  # the source as written, and its first line: part of the kernel cache key
    start: int = 0
    names: list | None = None  # every name in the source, in order (fingerprint.py fills it in)

    def loc(self, node: ast.AST) -> Loc:
        return Loc(self.file, getattr(node, "lineno", self.tree.lineno), getattr(node, "col_offset", 0))


_cache: dict = {}


def get_source(func) -> FunctionSource:
    code = func.__code__
    cached = _cache.get(code)
    if cached is not None and cached.func is func:
        return cached
    file = inspect.getsourcefile(func) or code.co_filename
    try:
        lines, start = inspect.getsourcelines(func)
    except (OSError, TypeError) as e:
        raise SimgradSyntaxError(f"cannot read the source of {func.__qualname__}: {e}") from None
    text = "".join(lines)
    dedented = textwrap.dedent(text)
    indent = len(lines[0]) - len(lines[0].lstrip()) if dedented != text else 0
    module = ast.parse(dedented)
    ast.increment_lineno(module, start - 1)
    if indent:
        for node in ast.walk(module):
            if hasattr(node, "col_offset"):
                node.col_offset += indent
                end = getattr(node, "end_col_offset", None)
                if end is not None:
                    node.end_col_offset = end + indent  # type: ignore[attr-defined]
    fdef = module.body[0]
    if not isinstance(fdef, (ast.FunctionDef, ast.AsyncFunctionDef)):
        raise SimgradSyntaxError(f"{func.__qualname__} is not a plain function definition")
    closure = {}
    if func.__closure__:
        for name, cell in zip(code.co_freevars, func.__closure__):
            try:
                closure[name] = cell.cell_contents
            except ValueError:
                pass
    src = FunctionSource(func, file, fdef, func.__globals__, closure, text, start)
    _cache[code] = src
    return src
