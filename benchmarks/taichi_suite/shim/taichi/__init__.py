"""`import taichi` served by simgrad, so that Taichi's own test files run against simgrad unchanged
(benchmarks/taichi_tests.py puts this directory first on sys.path). Nothing here fakes a result: names
simgrad lacks raise simgrad's own errors, which then fail the tests that use them."""

import sys
import types as _pytypes

import simgrad as _simgrad
from simgrad import *  # noqa: F401,F403
from simgrad import lang as _lang

# submodules test files import by name
sys.modules[__name__ + ".lang"] = _lang
sys.modules[__name__ + "._lib"] = _simgrad._lib  # `from taichi._lib.utils import get_os_name`
_misc = _pytypes.ModuleType(__name__ + ".lang.misc")
_misc.get_host_arch_list = lambda: [_simgrad.cpu]  # type: ignore[attr-defined]  # the host is the CPU
_misc.is_arch_supported = lambda arch: arch == _simgrad.cpu  # type: ignore[attr-defined]
_misc.__getattr__ = lambda name: getattr(_simgrad, name)  # type: ignore[method-assign]  # the ti.* it holds
sys.modules[_misc.__name__] = _misc
sys.modules[__name__ + ".lang.exception"] = _simgrad  # the Taichi exception names are simgrad's
_util = _pytypes.ModuleType(__name__ + ".lang.util")


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


_util.has_pytorch = lambda: _has("torch")  # type: ignore[attr-defined]
_util.has_paddle = lambda: _has("paddle")  # type: ignore[attr-defined]
_util.to_numpy_type = lambda t: _simgrad.dtypes.from_any(t).np.type  # type: ignore[attr-defined]
sys.modules[_util.__name__] = _util
if not hasattr(_lang, "util"):
    _lang.util = _util  # type: ignore[attr-defined]  # `ti.lang.util.to_numpy_type` in test files
import simgrad.linalg as _linalg  # noqa: E402

sys.modules[__name__ + ".linalg"] = _linalg
linalg = _linalg
# Taichi's enums module: the names test files import (their values are never compared with simgrad's)
_enums = _pytypes.ModuleType(__name__ + ".lang.enums")
for _name in ("AutodiffMode", "SNodeGradType", "Layout"):
    setattr(_enums, _name, getattr(_simgrad, _name, None) or _pytypes.SimpleNamespace())
sys.modules[_enums.__name__] = _enums
sys.modules[__name__ + ".math"] = _simgrad.math
math = _simgrad.math
lang = _lang


def __getattr__(name):
    return getattr(_simgrad, name)
