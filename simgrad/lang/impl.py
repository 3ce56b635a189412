"""The few `taichi.lang.impl` names that public programs call (`ti.lang.impl.get_runtime().prog`)."""

from __future__ import annotations

from simgrad.lang.program import Program, get_program


class _ProgramView:
    """Taichi's `prog` object: the current Program's attributes, and `config()` a method as in Taichi (simgrad's
    Program keeps its config as an attribute, read all over the compiler)."""

    def __init__(self, program: Program):
        self._program = program

    def config(self):
        return self._program.config

    def __getattr__(self, name: str):
        return getattr(self._program, name)


class _Runtime:
    @property
    def prog(self) -> _ProgramView:
        return _ProgramView(get_program())

    @property
    def default_fp(self):
        return get_program().config.default_fp

    @default_fp.setter
    def default_fp(self, t) -> None:
        get_program().set_default_types(fp=t)

    def get_num_compiled_functions(self) -> int:
        """Kernel instantiations made by this program (Taichi's count of compiled kernels)."""
        return get_program().instantiations

    @property
    def default_ip(self):
        return get_program().config.default_ip

    @default_ip.setter
    def default_ip(self, t) -> None:
        get_program().set_default_types(ip=t)

    def set_default_fp(self, t) -> None:
        """Taichi's runtime method (what ti.init(default_fp=...) calls)."""
        get_program().set_default_types(fp=t)

    def set_default_ip(self, t) -> None:
        """Taichi's runtime method (what ti.init(default_ip=...) calls)."""
        get_program().set_default_types(ip=t)


def get_runtime() -> _Runtime:
    return _Runtime()


def current_cfg():
    """The ti.init configuration (arch, default_fp, default_ip, debug, ...), as Taichi's current_cfg()."""
    return get_program().config
