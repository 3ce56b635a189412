"""A stable, diffable text form of the IR: `%3:f32 = mul %1, 2.0:f32  # sim.py:12` (constants inline)."""

from __future__ import annotations

import os

from simgrad.ir.nodes import Block, Kernel, Stmt
from simgrad.ir.ops import Op


def _attr_text(s: Stmt) -> str:
    parts = []
    for k, v in s.attrs.items():
        if k in ("loop",):
            continue
        if hasattr(v, "ir_name"):
            v = v.ir_name()
        parts.append(f"{k}={v}")
    return (" [" + ", ".join(parts) + "]") if parts else ""


def _operand_text(o: Stmt, names: dict[Stmt, str]) -> str:
    if o.op is Op.CONST:
        return f"{o.attrs['value']!r}:{o.type}"
    return names.get(o, f"%{o.id}")


def _stmt_text(s: Stmt, names: dict[Stmt, str]) -> str:
    ops = ", ".join(_operand_text(o, names) for o in s.operands)
    lhs = f"%{s.id}:{s.type} = " if s.type is not None else f"%{s.id} = " if s.op is Op.CALL else ""
    where = f"  # {os.path.basename(s.loc.file)}:{s.loc.line}" if s.loc else ""
    return f"{lhs}{s.op.name.lower()} {ops}{_attr_text(s)}".rstrip() + where


def print_block(block: Block, indent: int = 0, names: dict | None = None) -> list[str]:
    names = names if names is not None else {}
    lines = []
    pad = "  " * indent
    for s in block.stmts:
        lines.append(pad + _stmt_text(s, names))
        for i, b in enumerate(s.blocks):
            if len(s.blocks) > 1:
                lines.append(pad + ("} else {" if i else "{"))
            else:
                lines.append(pad + "{")
            lines.extend(print_block(b, indent + 1, names))
        if s.blocks:
            lines.append(pad + "}")
    return lines


def print_kernel(kernel: Kernel) -> str:
    lines = [f"kernel {kernel.name} {{", *print_block(kernel.body, 1), "}"]
    for fn in kernel.functions:
        params = ", ".join(str(t) for t in fn.params)
        rets = ", ".join(str(t) for t in fn.returns)
        lines += [f"function @{fn.name}({params}) -> ({rets}) {{", *print_block(fn.body, 1), "}"]
    return "\n".join(lines)
