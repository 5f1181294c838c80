"""The warning a moved module's old import path gives, naming the path to use instead."""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Callable
from typing import Any


def warn_moved(old: str, new: str) -> None:
    """A ``DeprecationWarning`` that ``old`` is now ``new``, raised where the import was written
    (past ``importlib.import_module``; ``warnings`` itself skips the import system's bootstrap), so
    the default filters show it to the code that must change; ``python -m OLD`` is that code."""
    caller = sys._getframe(1)
    if caller.f_globals.get("__name__") == "__main__":
        level, frame = 2, None
    else:  # level 2 is the old module's body, 3 the code importing it
        level, frame = 3, caller.f_back
    while frame is not None and _is_import_machinery(frame.f_code.co_filename):
        level += not _is_bootstrap(frame.f_code.co_filename)
        frame = frame.f_back
    message = f"{old} moved to {new}: import it from there; the old path goes in the next release"
    warnings.warn(message, DeprecationWarning, stacklevel=level)


def _is_bootstrap(filename: str) -> bool:
    """A frame ``warnings`` leaves out when it counts levels (as its ``_is_internal_frame``)."""
    return "importlib" in filename and "_bootstrap" in filename


def _is_import_machinery(filename: str) -> bool:
    """Whether a frame belongs to the import system rather than to code that imports."""
    return _is_bootstrap(filename) or filename == importlib.__file__


def forwarding(old: str, new: str, names: list[str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``old`` that reads each of ``names`` from ``new`` on first use, so
    that importing ``client`` loads none of the server's package."""

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {old!r} has no attribute {name!r}")
        return getattr(importlib.import_module(new), name)

    return __getattr__
