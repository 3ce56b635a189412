"""The few `taichi.lang.impl` names that public programs call (`ti.lang.impl.get_runtime().prog`)."""

from __future__ import annotations

from simgrad.lang.program import Program, get_program


class _Runtime:
    @property
    def prog(self) -> Program:
        return get_program()

    @property
    def default_fp(self):
        return get_program().config.default_fp

    @property
    def default_ip(self):
        return get_program().config.default_ip


def get_runtime() -> _Runtime:
    return _Runtime()


def current_cfg():
    """The ti.init configuration (arch, default_fp, default_ip, debug, ...), as Taichi's current_cfg()."""
    return get_program().config
