"""Thin aliases for the module paths of qpcoord 0.1 (before the layered layout).

``qpcoord/stack.py`` and its siblings are one-line modules that call :func:`moved`: the old
path keeps working for one release, warns once with a :class:`DeprecationWarning` that names
the new path, and *is* the new module afterwards (``sys.modules`` maps the old name to it), so
attribute access, ``from ... import ...`` and ``unittest.mock.patch`` on the old path act on
the new module.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from types import ModuleType

__all__ = ["moved", "warn_moved"]


def _stacklevel(skip: int) -> int:
    """``warnings.warn`` stack level of the importing code: the first frame, above the
    ``skip`` innermost ones (this module and the alias module), outside importlib."""
    frame = sys._getframe(skip + 1)
    level = skip + 1
    while frame is not None and "importlib" in frame.f_code.co_filename:
        frame = frame.f_back
        level += 1
    return level


def warn_moved(old: str, new: str, skip: int = 2) -> None:
    """Warn that module ``old`` moved to ``new`` (:class:`DeprecationWarning`), attributed
    to the code that imports ``old`` (``skip``: frames of the alias machinery to pass)."""
    warnings.warn(
        f"the module {old} moved to {new}; the old path is deprecated and will be removed "
        f"in the next release (names exported by `import qpcoord as qc` are unchanged)",
        DeprecationWarning,
        stacklevel=_stacklevel(skip),
    )


def moved(old: str, new: str) -> ModuleType:
    """Make module path ``old`` an alias of module ``new``: warn, then map ``old`` to it.

    Called by the alias module ``old`` itself while it is being imported; the import
    machinery then returns ``sys.modules[old]``, i.e. the module ``new``.
    """
    module = importlib.import_module(new)
    warn_moved(old, new, skip=3)
    sys.modules[old] = module
    return module
