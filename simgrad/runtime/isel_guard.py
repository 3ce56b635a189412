"""A guard against a defect of LLVM 22's X86 instruction selection (llvmlite 0.50), applied to optimised IR.

Two loads in one basic block whose byte offsets are the same value written two ways,
`shl (zext (and x, M)), K` and `zext (and (shl x, K), M << K)` (InstCombine picks one or the other by the
number of uses of `and x, M`), are separate nodes until X86's address matcher rewrites the second form into
the first while selecting an instruction; the DAG then merges the two loads and goes on using the deleted
one: an assertion (SIGABRT) in a build with assertions, undefined behaviour without. The guard points the
later load at the earlier load's pointer (the same address, so nothing changes), and the DAG merges them
from the start. tests/runtime/test_isel_guard.py holds the reduced input that crashes without it.
"""

from __future__ import annotations

import re

_NAME = r"%[-\w.$]+"
_AND = re.compile(rf"\s*({_NAME}) = and (i\d+) ({_NAME}), (\d+)$")
_SHL = re.compile(rf"\s*({_NAME}) = shl (?:nuw )?(?:nsw )?(i\d+) ({_NAME}), (\d+)$")
_ZEXT = re.compile(rf"\s*({_NAME}) = zext (?:nneg )?(i\d+) ({_NAME}) to i64$")
_GEP = re.compile(rf"\s*({_NAME}) = getelementptr (?:inbounds )?(?:nuw )?i8, ptr ({_NAME}), i64 ({_NAME})$")
_LOAD = re.compile(rf"(\s*{_NAME} = load [^,]+, ptr )({_NAME})(,.*)?$")


def _offset_key(name: str, defs: dict) -> tuple | None:
    """(x, mask, shift) when `name` is (x & mask) << shift in either spelling, with all of it in this block."""
    d = defs.get(name)
    if d is None:
        return None
    if d[0] == "shl":  # shl (zext (and x, M)), K
        inner = defs.get(d[2])
        if inner is not None and inner[0] == "zext":
            inner = defs.get(inner[2])
        if inner is not None and inner[0] == "and":
            return inner[2], inner[3] << d[3], d[3]
    if d[0] == "zext":  # zext (and (shl x, K), M)
        a = defs.get(d[2])
        if a is not None and a[0] == "and":
            s = defs.get(a[2])
            if s is not None and s[0] == "shl" and a[3] & ((1 << s[3]) - 1) == 0:
                return s[2], a[3], s[3]
    return None


def merge_same_address_loads(ir: str) -> str | None:
    """`ir` with each load that reads an address an earlier load of its block reads through another
    spelling made to use that load's pointer; None when there is none (the common case)."""
    if " = and " not in ir or " = shl " not in ir:
        return None
    lines = ir.split("\n")
    changed = False
    defs: dict = {}
    seen: dict = {}  # (base, x, mask, shift) -> the first pointer of this block
    for k, line in enumerate(lines):
        if not line.startswith("  ") or line.endswith(":") or not line.strip():
            if line and not line.startswith(" "):  # a label, `}` or a new function: a new block
                defs, seen = {}, {}
            continue
        if (m := _AND.match(line)) or (m := _SHL.match(line)):
            defs[m.group(1)] = (line.split(" = ")[1].split()[0], m.group(2), m.group(3), int(m.group(4)))
        elif m := _ZEXT.match(line):
            defs[m.group(1)] = ("zext", m.group(2), m.group(3), 0)
        elif m := _GEP.match(line):
            key = _offset_key(m.group(3), defs)
            if key is not None:
                defs[m.group(1)] = ("gep", m.group(2), key)
        elif m := _LOAD.match(line):
            pointer = str(m.group(2))
            d = defs.get(pointer)
            if d is not None and d[0] == "gep":
                first = seen.setdefault((d[1], *d[2]), pointer)
                if first != pointer:
                    lines[k] = f"{m.group(1)}{first}{m.group(3) or ''}"
                    changed = True
    return "\n".join(lines) if changed else None
