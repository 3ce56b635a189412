"""``ti._lib.utils``: the platform name Taichi programs test (``get_os_name() != "osx"`` picks the pixel order of a
fast GUI's buffer, as in ``ti.GUI(fast_gui=True).img``)."""

import platform


def get_os_name() -> str:
    """'osx', 'win', 'linux' or 'unix', from ``platform.platform()`` as Taichi names them."""
    name = platform.platform().lower()
    if name.startswith(("darwin", "macos")):
        return "osx"
    if name.startswith("windows"):
        return "win"
    if name.startswith("linux"):
        return "linux"
    return "unix"


def import_ti_python_core():
    """Taichi's C++ core module; here its stand-in, simgrad._lib.core (version and backend probes)."""
    from simgrad._lib import core

    return core
