"""Why kernels, fields and data_oriented objects refuse to be pickled (or copied through pickle's protocol).

Their state is native: a field is memory of one program's SNode tree, a kernel holds compiled code linked
into one process. A copy unpickled in another process (a Ray worker, concurrent.futures) would point at
nothing (taichi#8530). The way to run a program elsewhere is to build it there: simgrad.distributed calls
the user's build() inside each worker. The error says so, at the user's line that asked for the pickle
(the innermost frame outside simgrad, pickle, copy and the serialisers of Ray/cloudpickle).
"""

from __future__ import annotations

import pickle
import sys
from typing import NoReturn

from simgrad.errors import Loc, SimgradError

# modules of the pickling machinery (by top-level package), not of the user who asked for the pickle
_MACHINERY = frozenset(("simgrad", "pickle", "_pickle", "copyreg", "copy", "cloudpickle", "ray", "multiprocessing",
                        "concurrent"))


class SimgradPicklingError(SimgradError, pickle.PicklingError):
    """A simgrad object with native state was asked to be pickled."""


def user_loc() -> Loc | None:
    """The innermost frame outside simgrad and the pickling machinery."""
    frame = sys._getframe(1)
    while frame is not None:
        module = frame.f_globals.get("__name__") or ""
        if module.partition(".")[0] not in _MACHINERY and not frame.f_code.co_filename.startswith("<"):
            return Loc(frame.f_code.co_filename, frame.f_lineno)
        frame = frame.f_back  # type: ignore[assignment]
    return None


def refuse_pickle(what: str, defined: Loc | None = None) -> NoReturn:
    """Raise the error of a `__reduce__`: `what` names the object, `defined` is where it was made."""
    where = f" (defined at {defined})" if defined is not None else ""
    raise SimgradPicklingError(
        f"{what}{where} cannot be pickled: it lives in this process's simgrad program (native memory and "
        "code). Build the program inside the worker instead: pass a function that creates the fields and "
        "kernels (simgrad.distributed.map_value_and_grad(build, ...) calls build() in each worker), and send "
        "only numpy arrays and plain values across processes", user_loc())


def function_loc(fn) -> Loc | None:
    """Where a Python function is defined."""
    code = getattr(fn, "__code__", None)
    return Loc(code.co_filename, code.co_firstlineno) if code is not None else None
