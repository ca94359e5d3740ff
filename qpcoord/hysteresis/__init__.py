"""Piezo hysteresis: classical Preisach model and its inverse compensator (thesis appendix C).

Thesis → qpcoord.hysteresis:

- Eqs C.1–C.4, C.8 (Everett function on a mesh, bilinear cells, Fig. C.5):
  :class:`PreisachModel` (``levels``, ``everett``, ``everett_at``, ``major_loop``);
- identification from first-order reversal curves (Eq. C.3, Fig. C.3): :func:`identify`,
  :func:`forc_program`, :meth:`PreisachModel.from_forc`;
- Eqs C.5–C.7 + wipe-out (output with memory of extrema): :class:`PreisachStage`
  (``reset``/``step``, per sample), :meth:`PreisachModel.evaluate` and
  :meth:`PreisachStage.run` (vectorised);
- Eqs C.9–C.11 + descending case (inverse, feed-forward compensation):
  :class:`PreisachCompensator` (``reset``/``step``);
- open-loop "without compensation": :meth:`PreisachModel.linear_command`;
- synthetic stacks (not the model): :class:`RelayPiezo`, :class:`BoucWenPiezo`.

Units: volts (V) in, metres (m) out. Per-sample objects take ``reset()`` and
``step(value) -> float`` (the interface of the DDL fine stage's optional hysteresis
element): :class:`PreisachStage` maps volts to metres or, with ``output="volts"``, to the
*effective voltage* that a hysteresis-free stage with the same stroke would need;
:class:`PreisachCompensator` maps the desired metres (or effective volts) to the voltage to
apply. Inputs outside the identified range or NaN raise :class:`ValueError` (or saturate
with ``clip=True``; NaN always raises).

Example::

    from qpcoord import hysteresis as hy
    piezo = hy.BoucWenPiezo()
    model = hy.identify(piezo, np.linspace(0, 10, 21))
    comp = hy.PreisachCompensator(model)
    u = comp.run(x_desired)            # V, feed-forward
    piezo.reset(); x = piezo.run(u)    # m, ≈ x_desired
"""

from __future__ import annotations

from .forc import forc_program, identify
from .inverse import PreisachCompensator
from .memory import PreisachStage
from .piezo import BoucWenPiezo, RelayPiezo
from .preisach import PreisachModel

__all__ = [
    "BoucWenPiezo",
    "PreisachCompensator",
    "PreisachModel",
    "PreisachStage",
    "RelayPiezo",
    "forc_program",
    "identify",
]
