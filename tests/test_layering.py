"""The layering of docs/ARCHITECTURE.md ("Layers"), checked on the source by an AST walk over every module of
simgrad, so a function-local import counts too (only the public namespace simgrad/__init__.py is left out:
it imports everything, and nothing below it imports it).

- no import cycle between any two modules, except inside lang's operator-overloading core (CORE);
- ir, passes, autodiff and codegen import nothing from lang or frontend, lang nothing from frontend or
  compiler, and nothing but the public namespace imports the compiler stage;
- the stages (packages under simgrad/, and the top-level modules each on its own) import each other as the
  drawing in docs/ARCHITECTURE.md says: `python tests/test_layering.py` prints that drawing.

Imports under `if TYPE_CHECKING:` are not followed: they never run."""

from __future__ import annotations

import ast
import re
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "simgrad"
DOC = PKG.parent / "docs" / "ARCHITECTURE.md"
LOWER = ("ir", "passes", "autodiff", "codegen")
UPPER = ("simgrad.lang", "simgrad.frontend")
PUBLIC = "simgrad"  # the public namespace, simgrad/__init__.py

# lang's operator-overloading core, the only modules allowed to import each other round: operators on Exprs
# give Matrices for vector operands and Matrices are built from scalar ops; fields, SNodes, structs, types
# and ndarrays construct and return those values and each other. Why each one: docs/ARCHITECTURE.md "Layers".
CORE = frozenset(f"simgrad.lang.{m}" for m in (
    "expr", "operators", "matrix", "field", "snode", "factories", "types", "struct", "sparse", "ndarray"))


def _modules() -> dict[str, Path]:
    out = {}
    for path in PKG.rglob("*.py"):
        parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _is_type_checking(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and (
        (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
        or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"))


def _walk(node: ast.AST):
    """ast.walk, skipping the bodies of `if TYPE_CHECKING:`."""
    todo = [node]
    while todo:
        n = todo.pop()
        yield n
        if _is_type_checking(n):
            todo += getattr(n, "orelse", [])
            continue
        todo.extend(ast.iter_child_nodes(n))


def _imports(module: str) -> list[tuple[int, str]]:
    """(line, imported name) for every import in `module`, relative ones made absolute; `from a import b`
    gives `a.b`."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in _walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            out += [(node.lineno, f"{base}.{a.name}") for a in node.names]
    return out


def _resolve(name: str) -> str | None:
    """The simgrad module an imported name lives in: itself when it is a module, else the longest module
    prefix (`simgrad.lang.operators.cast` -> simgrad.lang.operators)."""
    parts = name.split(".")
    while parts:
        if ".".join(parts) in MODULES:
            return ".".join(parts)
        parts.pop()
    return None


def module_graph() -> dict[str, dict[str, int]]:
    """{module: {imported module: first line}} over every simgrad module but the public namespace."""
    graph: dict[str, dict[str, int]] = {}
    for m in MODULES:
        if m == PUBLIC:
            continue
        edges = graph.setdefault(m, {})
        for line, name in _imports(m):
            dst = _resolve(name)
            if dst is not None and dst not in (m, PUBLIC):
                edges.setdefault(dst, line)
    return graph


def strongly_connected(graph: dict[str, dict[str, int]]) -> list[set[str]]:
    """The components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(comp)
    return out


def cycle_through(graph: dict[str, dict[str, int]], start: str, within: set[str]) -> list[str]:
    """A shortest import cycle from `start` back to it, inside one strongly connected component."""
    prev: dict[str, str] = {}
    todo = [start]
    while todo:
        nxt = []
        for v in todo:
            for w in sorted(graph[v]):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return path[::-1] + [start]
                if w in within and w not in prev:
                    prev[w] = v
                    nxt.append(w)
        todo = nxt
    raise AssertionError("not in a cycle")


def _describe(graph, cycle: list[str]) -> str:
    return " -> ".join(f"{a} (line {graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" -> {cycle[-1]}"


def stage_of(module: str) -> str:
    """A package under simgrad/ is a stage; a top-level module (errors, dtypes, debug, testing) is its own."""
    return module.split(".")[1]


def stage_graph() -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for m, edges in module_graph().items():
        src = stage_of(m)
        out.setdefault(src, set()).update(stage_of(d) for d in edges if stage_of(d) != src)
    return out


def stage_drawing() -> str:
    """The stages in import order (each line imports only from lines above it), as docs/ARCHITECTURE.md
    shows them."""
    graph = stage_graph()
    done: list[str] = []
    while len(done) < len(graph):
        ready = sorted(s for s in graph if s not in done and graph[s] <= set(done))
        assert ready, f"stage cycle among {sorted(set(graph) - set(done))}"
        done += ready
    public = {stage_of(m) for m in MODULES if m != PUBLIC and any(_resolve(n) == PUBLIC for _, n in _imports(m))}
    width = max(len(s) for s in graph)
    return "\n".join(f"{s:<{width}} -> {', '.join(sorted(graph[s])) or '(nothing)'}"
                     + (" + the public namespace" if s in public else "") for s in done)


def test_no_import_cycles_outside_the_lang_core():
    graph = module_graph()
    bad = []
    for comp in strongly_connected(graph):
        for m in sorted(comp - CORE):
            bad.append(_describe(graph, cycle_through(graph, m, comp)))
    assert not bad, "import cycles outside lang's core:\n" + "\n".join(bad)


def test_the_core_is_one_cycle_and_as_documented():
    """CORE is exactly the modules that still import each other round (a module that leaves the cycle
    leaves CORE and the doc), and docs/ARCHITECTURE.md names each."""
    comps = [c for c in strongly_connected(module_graph()) if c & CORE]
    assert comps == [set(CORE)], f"lang's core is now {comps}: update CORE and docs/ARCHITECTURE.md"
    layers = DOC.read_text().split("## Layers", 1)[1]
    missing = [m for m in sorted(CORE) if f"lang/{m.rsplit('.', 1)[1]}.py" not in layers]
    assert not missing, f"docs/ARCHITECTURE.md 'Layers' does not name {missing}"


def test_cycle_finder_finds_and_prints_a_cycle():
    graph = {"a": {"b": 3}, "b": {"c": 4}, "c": {"a": 7, "d": 1}, "d": {}}
    (comp,) = strongly_connected(graph)
    assert comp == {"a", "b", "c"}
    assert _describe(graph, cycle_through(graph, "b", comp)) == "b (line 4) -> c (line 7) -> a (line 3) -> b"


def test_function_local_and_relative_imports_count(tmp_path):
    src = "from __future__ import annotations\nfrom typing import TYPE_CHECKING\nif TYPE_CHECKING:\n" \
          "    from simgrad.lang import operators\n\ndef f():\n    from . import nodes\n    import simgrad.errors\n"
    MODULES["simgrad.ir._probe"] = p = tmp_path / "_probe.py"
    try:
        p.write_text(src)
        assert sorted(n for _, n in _imports("simgrad.ir._probe")) == [
            "__future__.annotations", "simgrad.errors", "simgrad.ir.nodes", "typing.TYPE_CHECKING"]
    finally:
        del MODULES["simgrad.ir._probe"]


def test_stage_drawing_is_the_documented_one():
    drawing = stage_drawing()
    blocks = re.findall(r"```\n(.*?)```", DOC.read_text().split("## Layers", 1)[1], re.S)
    assert blocks and blocks[0].strip() == drawing, (
        "docs/ARCHITECTURE.md 'Layers' must show the stage graph as the code has it:\n" + drawing)


def test_lower_stages_import_nothing_from_lang_or_frontend():
    bad = []
    for m in MODULES:
        if m != PUBLIC and stage_of(m) in LOWER:
            bad += [f"{m}:{line} imports {name}" for line, name in _imports(m) if name.startswith(UPPER)]
    assert not bad, "\n".join(bad)


def test_lang_imports_neither_frontend_nor_compiler():
    """lang (fields, types, operators) sits below the frontend that lowers it and the compiler that drives
    both: what lang needs of a kernel under construction (inline a ti.func, emit a fill) it asks of the
    compiler on ir/context.py's stack."""
    bad = []
    for m in MODULES:
        if m.startswith("simgrad.lang."):
            bad += [f"{m}:{line} imports {name}" for line, name in _imports(m)
                    if name.startswith(("simgrad.frontend", "simgrad.compiler"))]
    assert not bad, "\n".join(bad)


def test_nothing_imports_the_compiler_stage_but_the_public_namespace():
    bad = []
    for m in MODULES:
        if m == PUBLIC or stage_of(m) == "compiler":
            continue
        bad += [f"{m}:{line} imports {name}" for line, name in _imports(m) if name.startswith("simgrad.compiler")]
    assert not bad, "\n".join(bad)


if __name__ == "__main__":
    print(stage_drawing())
