"""User-facing errors. Each names the user's file and line and shows the offending source line with a
caret; each also subclasses the builtin exception a Python user would expect."""

from __future__ import annotations

import linecache
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from types import FrameType

_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep

# whether a kernel is being compiled: ir/context.py (the kernel stack, above this module) installs its
# in_kernel; before that module is loaded no kernel can be compiling
compiling: Callable[[], bool] = lambda: False


@dataclass(frozen=True)
class Loc:
    """A place in the user's source: file, 1-based line, 0-based column."""

    file: str
    line: int
    col: int = 0

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"

    def render(self) -> str:
        src = linecache.getline(self.file, self.line).rstrip("\n")
        if not src:
            return f'File "{self.file}", line {self.line}'
        stripped = src.lstrip()
        indent = len(src) - len(stripped)
        caret = " " * max(0, self.col - indent) + "^"
        return f'File "{self.file}", line {self.line}:\n    {stripped}\n    {caret}'


def caller_loc() -> Loc | None:
    """The user's line that called into simgrad (the innermost frame outside the package), for errors
    raised in Python scope."""
    if compiling():
        return None  # compiling a kernel: the statement being compiled is the place
    frame: FrameType | None = sys._getframe(1)
    while frame is not None and (frame.f_code.co_filename.startswith("<launcher")  # generated launchers
                                 or os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE)):
        frame = frame.f_back
    if frame is None:
        return None
    return Loc(frame.f_code.co_filename, frame.f_lineno)


class SimgradError(Exception):
    """Base of every simgrad error; `loc` (when known) is rendered above the message."""

    def __init__(self, message: str, loc: Loc | None = None):
        self.message = message
        self.loc = loc
        super().__init__(self._text())

    def _text(self) -> str:
        if self.loc is None:
            return self.message
        return f"{self.loc.render()}\n{self.message}"

    def __str__(self) -> str:
        return self._text()


# Taichi's exception classes, with Taichi's hierarchy (taichi/lang/exception.py in 1.7.4), so that
# `except ti.TaichiRuntimeError` in existing programs catches ours. simgrad raises its own concrete classes
# below, each an instance of the Taichi class Taichi raises in that situation
# (tests/lang/test_taichi_errors.py records the situations).
class TaichiCompilationError(SimgradError):
    """What a program does wrong, found while compiling a kernel."""


class TaichiSyntaxError(TaichiCompilationError, SyntaxError):
    def __init__(self, message: str, loc: Loc | None = None):
        SimgradError.__init__(self, message, loc)
        self.args = (self._text(),)  # SyntaxError's own __str__ would show only the first argument

    def __str__(self) -> str:
        return self._text()


class TaichiNameError(TaichiCompilationError, NameError):
    pass


class TaichiIndexError(TaichiCompilationError, IndexError):
    pass


class TaichiTypeError(TaichiCompilationError, TypeError):
    pass


class TaichiRuntimeError(SimgradError, RuntimeError):
    """An error a running kernel or the runtime reports."""


class TaichiAssertionError(TaichiRuntimeError, AssertionError):
    pass


class TaichiRuntimeTypeError(TaichiRuntimeError, TypeError):
    pass


class SimgradSyntaxError(TaichiSyntaxError):
    """A Python construct the kernel language does not support, or misuse of one it does."""


class SimgradTypeError(TaichiTypeError):
    pass


class SimgradNameError(TaichiNameError):
    pass


class SimgradIndexError(TaichiIndexError):
    pass


class ArgumentTypeError(SimgradTypeError, TaichiRuntimeTypeError):
    """A kernel argument of the wrong type, found when it is passed (Taichi: TaichiRuntimeTypeError)."""


class ArgumentValueError(ArgumentTypeError, ValueError):
    """An argument its parameter kind refuses (compiler/params.py): Taichi raises ValueError for an array of
    the wrong dtype or ndim, TaichiRuntimeTypeError for a value that is no array at all."""


class AnnotationError(SimgradTypeError, TaichiSyntaxError):
    """A kernel or ti.func parameter annotation that cannot be evaluated (TaichiSyntaxError in Taichi)."""


class ArgumentCountError(SimgradTypeError, TaichiSyntaxError):
    """Too many or too few arguments, or an unknown keyword, for a kernel or ti.func (Taichi:
    TaichiSyntaxError; a TypeError as Python says)."""


class SimgradValueError(SimgradError, ValueError):
    pass


class SimgradOverflowError(SimgradError, OverflowError):
    pass


class SimgradAssertionError(TaichiAssertionError):
    pass


class SimgradRuntimeError(TaichiRuntimeError):
    pass


class FieldIndexTypeError(SimgradIndexError, TypeError):
    """A Python-scope field index that is no integer (a slice, a float): Taichi's TypeError, still an IndexError."""


class SimgradOutOfBoundError(SimgradIndexError, SimgradAssertionError):
    """An index out of bounds found at run time (debug mode): an IndexError, and an assertion failure as
    Taichi reports it ("Out of bound access")."""


class GradientError(TaichiRuntimeError):
    """A kernel that cannot be differentiated correctly: we refuse instead of returning wrong numbers."""


class SimgradNotSupportedError(SimgradError, NotImplementedError):
    """A Taichi feature simgrad does not have (yet): said plainly, at the user's line, instead of an
    AttributeError or a silently different result."""


class AccessRuleError(GradientError, SimgradAssertionError):
    """The global data access rule checked at run time (Tape(validation=True), debug mode) failed: a
    TaichiAssertionError, as Taichi raises for it."""
