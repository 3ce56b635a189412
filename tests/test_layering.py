"""The layering of docs/ARCHITECTURE.md, checked on the source: ir, passes, autodiff and codegen import
nothing from lang or frontend (not even inside functions), lang nothing from frontend or compiler, and the
stages (the packages under simgrad/) import each other without any cycle. An AST walk over every module,
so a function-local import counts too."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "simgrad"
LOWER = ("ir", "passes", "autodiff", "codegen")
UPPER = ("simgrad.lang", "simgrad.frontend")


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text())
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module))
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return out


def _stage(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "simgrad" or len(parts) < 2:
        return None
    return parts[1] if (PKG / parts[1]).is_dir() else None


def test_lower_stages_import_nothing_from_lang_or_frontend():
    bad = []
    for stage in LOWER:
        for path in sorted((PKG / stage).rglob("*.py")):
            for line, name in _imports(path):
                if name.startswith(UPPER):
                    bad.append(f"{path.relative_to(PKG.parent)}:{line} imports {name}")
    assert not bad, "\n".join(bad)


def test_no_import_cycles_between_stages():
    edges: dict[str, set[str]] = {}
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG)
        if len(rel.parts) < 2:
            continue  # top-level modules (the public namespace, errors, dtypes) are not stages
        src = rel.parts[0]
        for _line, name in _imports(path):
            dst = _stage(name)
            if dst is not None and dst != src:
                edges.setdefault(src, set()).add(dst)
    # depth-first search for a cycle
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        path.append(n)
        for m in sorted(edges.get(n, ())):
            if state.get(m) == 1:
                return path[path.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        path.pop()
        state[n] = 2
        return None

    for n in sorted(edges):
        if n not in state:
            cycle = visit(n)
            assert cycle is None, f"stage import cycle: {' -> '.join(cycle)}; edges {edges}"


def test_lang_imports_neither_frontend_nor_compiler():
    """lang (fields, types, operators) sits below the frontend that lowers it and the compiler that drives
    both: what lang needs of a kernel under construction (inline a ti.func, emit a fill) it asks of the
    compiler on ir/context.py's stack."""
    bad = []
    for path in sorted((PKG / "lang").rglob("*.py")):
        for line, name in _imports(path):
            if name.startswith(("simgrad.frontend", "simgrad.compiler")):
                bad.append(f"{path.relative_to(PKG.parent)}:{line} imports {name}")
    assert not bad, "\n".join(bad)


def test_nothing_imports_the_compiler_stage_but_the_public_namespace():
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG)
        if len(rel.parts) < 2 or rel.parts[0] == "compiler":
            continue
        for line, name in _imports(path):
            if name.startswith("simgrad.compiler"):
                bad.append(f"{rel}:{line} imports {name}")
    assert not bad, "\n".join(bad)
