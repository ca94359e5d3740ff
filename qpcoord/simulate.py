"""Deprecated alias of :mod:`qpcoord.kinematics.simulation` (removed in the next release).

``qpcoord.simulate`` is also the function :func:`qpcoord.simulate`; importing this alias
module rebinds the package attribute to the module, so the module is made callable (it
calls the function) to keep ``qc.simulate(...)`` working after ``import qpcoord.simulate``.
"""

import sys
from types import ModuleType

from ._deprecated import warn_moved
from .kinematics.simulation import Trajectory, simulate

__all__ = ["Trajectory", "simulate"]


class _CallableAlias(ModuleType):
    def __call__(self, *args, **kwargs):
        return simulate(*args, **kwargs)


warn_moved(__name__, "qpcoord.kinematics.simulation")
sys.modules[__name__].__class__ = _CallableAlias
