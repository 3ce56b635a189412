"""ti.set_logging_level and Taichi's level names. simgrad prints no log lines of its own today (compiler dumps
are SIMGRAD_DEBUG's); the level is validated and kept so that programs which set it run unchanged, and
`is_logging_effective` is there for the first message that needs it."""

from __future__ import annotations

TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL = "trace", "debug", "info", "warn", "error", "critical"
_LEVELS = (TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL)
level = INFO


def set_logging_level(new_level: str) -> None:
    """Set the level (ti.TRACE ... ti.ERROR, or the same names as strings); an unknown name is an error."""
    global level
    name = str(new_level).lower()
    if name == "warning":
        name = WARN
    if name not in _LEVELS:
        raise ValueError(f"unknown logging level {new_level!r}; use one of {', '.join(_LEVELS)}")
    level = name


def is_logging_effective(at: str) -> bool:
    return _LEVELS.index(at) >= _LEVELS.index(level)
