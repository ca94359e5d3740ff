"""Thesis Table 6.1 row "Flatness based": :class:`FlatnessBased`.

The carriage position is a flat output of the feedback-linearised stepper
(:mod:`.pi_linearised`): with ``M ÿ_c + c ẏ_c = F_v`` the force that realises a reference
trajectory ``r_c(t)`` is ``M r̈_c + c ṙ_c``. :class:`FlatnessBased` adds this feed-forward,
computed from the rate-limited, Butterworth-filtered coarse reference by backward differences
(``ṙ ≈ (r_k − r_{k−1}) fs``, ``r̈ ≈ (r_k − 2 r_{k−1} + r_{k−2}) fs²``), to the PI of
:class:`.pi_linearised.PILinearised`; everything else (fine loop, estimate, linearisation,
limits, pre-compensation) is shared.
"""

from __future__ import annotations

from .pi_linearised import PILinearised

__all__ = ["FlatnessBased"]


class FlatnessBased(PILinearised):
    """Feedback-linearised stepper, flat-output feed-forward + PI (same parameters as
    :class:`.pi_linearised.PILinearised`)."""

    flat_feedforward = True
