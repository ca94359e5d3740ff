"""``polish`` on an active set guessed with two nearly parallel rows."""

from __future__ import annotations

import numpy as np

from qpcoord.core.polish import active_rank, polish


def _case(delta: float):
    """``min ½yᵀHy + fᵀy``, ``H = diag(1, 1, 1e-9)`` (the third direction carries only a
    regularisation's curvature), pulled to ``y₁ = 2`` through two rows ``y₁ ≤ 1`` and
    ``y₁ + 1e-10·y₂ ≤ 1 + delta``: parallel to 1e-10. Exact optimum ``(0, 1, 0)``, value
    -1.5; the second row is satisfied with slack ``delta``, inside the activity tolerance
    (1e-7), so both are guessed active."""
    H = np.diag([1.0, 1.0, 1e-9])
    f = np.array([0.0, -2.0, 0.0])
    G = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 1e-10]])
    lo = np.full(2, -np.inf)
    hi = np.array([1.0, 1.0 + delta])
    return H, f, G, lo, hi


def test_nearly_parallel_active_rows_do_not_send_polish_far():
    """Both rows made exactly tight meet at ``y₂ = delta / 1e-10 = 10``: a step along a
    direction of curvature 1e-9 that costs 5e-8 of the objective, inside polish's slack
    (1e-7 relative), which polish kept before the rows counted as one (``active_rank``).
    Now the guess is one constraint and polish keeps the backend's point (the rows'
    right-hand sides disagree by 1e-9, more than the exact solve's 1e-10 consistency)."""
    H, f, G, lo, hi = _case(1e-9)
    y = np.array([0.0, 1.0 - 1e-10, 0.0])  # a backend's point, 1e-10 inside both rows
    out = polish(H, f, G, lo, hi, None, None, y)
    assert np.all(np.abs(out - np.array([0.0, 1.0, 0.0])) <= 1e-9), out
    obj = 0.5 * out @ H @ out + f @ out
    assert obj <= -1.5 + 1e-9


def test_active_rank_counts_rows_parallel_within_the_tolerance_once():
    """Singular values of the two rows: √2 and 7e-11; at the activity tolerance 1e-7 the
    rank is 1, at rounding (well-separated rows) it is the numerical rank."""
    _, _, G, _, _ = _case(1e-9)
    s = np.linalg.svd(G, compute_uv=False)
    assert active_rank(s, G.shape, 1e-7) == 1
    assert active_rank(s, G.shape, 1e-12) == 2
    s2 = np.linalg.svd(np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 1e-3]]), compute_uv=False)
    assert active_rank(s2, (2, 3), 1e-7) == 2
    assert active_rank(np.zeros(0), (0, 3), 1e-7) == 0
