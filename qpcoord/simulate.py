"""Deprecated alias of :mod:`qpcoord.kinematics.simulation` (removed in the next release).

``qpcoord.simulate`` is also the function :func:`qpcoord.simulate`; importing this alias
module rebinds the package attribute to the module, so the module is made callable (it
calls the function) to keep ``qc.simulate(...)`` working after ``import qpcoord.simulate``.
"""

import sys
from types import ModuleType

from ._deprecated import warn_moved
from .kinematics import simulation as _new
from .kinematics.simulation import *  # noqa: F403

__all__ = list(_new.__all__)


def __getattr__(name: str):
    return getattr(_new, name)


class _CallableAlias(ModuleType):
    def __call__(self, *args, **kwargs):
        return _new.simulate(*args, **kwargs)


warn_moved(__name__, "qpcoord.kinematics.simulation")
sys.modules[__name__].__class__ = _CallableAlias
