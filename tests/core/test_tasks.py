"""Unit tests of the task objects (:mod:`qpcoord.core.tasks`) and of :mod:`qpcoord.core.linalg`."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import qpcoord as qc
from qpcoord.core.linalg import filtered_gains, filtered_svd, null_space
from qpcoord.core.persistent import PersistentQP

# ---------------------------------------------------------------------------------------
# Equality
# ---------------------------------------------------------------------------------------


def test_equality_1d_A_is_one_row():
    t = qc.Equality([1.0, 2.0, 3.0], 4.0, name="row")
    assert t.A.shape == (1, 3)
    assert t.shape == (1, 3)
    np.testing.assert_array_equal(t.A, [[1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(t.b, [4.0])
    np.testing.assert_array_equal(t.weight, [1.0])


def test_equality_scalar_b_and_weight_broadcast():
    t = qc.Equality(np.ones((3, 2)), 2.5, weight=4.0)
    np.testing.assert_array_equal(t.b, [2.5, 2.5, 2.5])
    np.testing.assert_array_equal(t.weight, [4.0, 4.0, 4.0])


def test_equality_integer_and_column_inputs_become_float_vectors():
    t = qc.Equality([[1, 0], [0, 1]], [[3], [4]])  # ints; b as a column
    assert t.A.dtype == float and t.b.dtype == float
    assert t.b.shape == (2,)
    np.testing.assert_array_equal(t.b, [3.0, 4.0])


def test_equality_residual_is_weighted():
    A = np.array([[1.0, 2.0], [0.0, 1.0]])
    b = np.array([1.0, -1.0])
    w = np.array([4.0, 0.25])
    t = qc.Equality(A, b, weight=w)
    x = np.array([0.5, 2.0])
    np.testing.assert_allclose(t.residual(x), np.sqrt(w) * (A @ x - b))
    np.testing.assert_allclose(t.residual(np.linalg.solve(A, b)), 0.0, atol=1e-15)


def test_equality_update_replaces_numbers_in_place():
    t = qc.Equality(np.eye(2), [1.0, 2.0], name="t")
    same = t.update(b=[3.0, 4.0])
    assert same is t
    np.testing.assert_array_equal(t.b, [3.0, 4.0])
    np.testing.assert_array_equal(t.A, np.eye(2))  # untouched
    t.update(A=[[0.0, 1.0], [1.0, 0.0]], weight=[2.0, 3.0])
    np.testing.assert_array_equal(t.A, [[0.0, 1.0], [1.0, 0.0]])
    np.testing.assert_array_equal(t.weight, [2.0, 3.0])
    np.testing.assert_allclose(t.residual(np.zeros(2)), -np.sqrt([2.0, 3.0]) * [3.0, 4.0])
    t.update(b=0.0)  # scalars still broadcast
    np.testing.assert_array_equal(t.b, [0.0, 0.0])


def test_equality_update_of_a_one_row_task_accepts_1d_A():
    t = qc.Equality([1.0, 0.0], 1.0)
    t.update(A=[0.0, 2.0])
    np.testing.assert_array_equal(t.A, [[0.0, 2.0]])


def test_stack_sees_task_updates():
    """The per-step hot path: update the numbers, solve again with the same Stack."""
    reach = qc.Equality(np.eye(2), [1.0, 2.0], name="reach")
    stack = qc.Stack([reach])
    np.testing.assert_allclose(stack.solve().x, [1.0, 2.0], atol=1e-12)
    reach.update(b=[-3.0, 0.5])
    np.testing.assert_allclose(stack.solve().x, [-3.0, 0.5], atol=1e-12)
    reach.update(A=[[2.0, 0.0], [0.0, 4.0]])
    np.testing.assert_allclose(stack.solve().x, [-1.5, 0.125], atol=1e-12)


def test_equality_repr_and_label():
    t = qc.Equality(np.ones((2, 3)), 0.0, name="reach")
    assert repr(t) == "Equality(rows=2, n=3, name='reach')"
    assert t.label == "Equality 'reach'"
    assert qc.Equality([1.0], 0.0).label == "Equality (unnamed)"


# ---------------------------------------------------------------------------------------
# Inequality
# ---------------------------------------------------------------------------------------


def test_inequality_one_sided_bounds_are_infinite_on_the_other_side():
    lo_only = qc.Inequality(np.eye(2), lower=[0.0, 1.0])
    np.testing.assert_array_equal(lo_only.upper, [np.inf, np.inf])
    hi_only = qc.Inequality(np.eye(2), upper=2.0)
    np.testing.assert_array_equal(hi_only.lower, [-np.inf, -np.inf])
    np.testing.assert_array_equal(hi_only.upper, [2.0, 2.0])


def test_inequality_accepts_infinite_sides_and_equal_bounds():
    t = qc.Inequality(np.eye(3), lower=[-np.inf, 0.0, 1.0], upper=[1.0, np.inf, 1.0])
    np.testing.assert_array_equal(t.lower, [-np.inf, 0.0, 1.0])
    np.testing.assert_array_equal(t.upper, [1.0, np.inf, 1.0])


def test_inequality_1d_C_is_one_row():
    t = qc.Inequality([1.0, -1.0], lower=0.0)
    assert t.C.shape == (1, 2) and t.shape == (1, 2)


def test_inequality_violation_sign_and_weight():
    t = qc.Inequality(
        np.eye(3), lower=[-1.0, -1.0, -1.0], upper=[1.0, 1.0, 1.0], weight=[1.0, 4.0, 9.0]
    )
    x = np.array([0.5, 3.0, -2.0])  # inside, 2 above, 1 below
    np.testing.assert_allclose(t.violation(x), [0.0, 2.0 * 2.0, 3.0 * -1.0])
    assert np.all(t.violation(np.zeros(3)) == 0.0)


def test_inequality_violation_one_sided():
    t = qc.Inequality([[1.0, 1.0]], upper=1.0)
    assert t.violation(np.array([-100.0, 0.0]))[0] == 0.0
    assert t.violation(np.array([1.0, 1.0]))[0] == pytest.approx(1.0)


def test_inequality_update():
    t = qc.Inequality(np.eye(2), lower=0.0, upper=1.0, name="lim")
    assert t.update(lower=[-1.0, -2.0]) is t
    np.testing.assert_array_equal(t.lower, [-1.0, -2.0])
    np.testing.assert_array_equal(t.upper, [1.0, 1.0])
    t.update(C=[[1.0, 1.0], [1.0, -1.0]], upper=[5.0, np.inf], weight=2.0)
    np.testing.assert_array_equal(t.C, [[1.0, 1.0], [1.0, -1.0]])
    np.testing.assert_array_equal(t.upper, [5.0, np.inf])
    np.testing.assert_array_equal(t.weight, [2.0, 2.0])


def test_inequality_repr_and_label():
    t = qc.Inequality(np.ones((4, 2)), upper=1.0, name="joint limits")
    assert repr(t) == "Inequality(rows=4, n=2, name='joint limits')"
    assert t.label == "Inequality 'joint limits'"


def test_rejected_update_leaves_task_unchanged():
    """A rejected update is atomic: nothing of it is kept (a later solve would otherwise use
    unvalidated numbers, e.g. lower > upper)."""
    t = qc.Inequality([[1.0, 0.0]], lower=0.0, upper=1.0, name="lim")
    with pytest.raises(ValueError, match="lower > upper"):
        t.update(lower=2.0)
    np.testing.assert_array_equal(t.lower, [0.0])
    e = qc.Equality(np.eye(2), [1.0, 2.0], name="t")
    with pytest.raises(ValueError, match="NaN"):
        e.update(A=np.ones((2, 2)), b=[np.nan, 1.0])
    np.testing.assert_array_equal(e.A, np.eye(2))


def test_task_does_not_alias_the_callers_arrays():
    """Mutating the caller's arrays afterwards must not bypass validation."""
    A = np.eye(2)
    b = np.array([1.0, 2.0])
    t = qc.Equality(A, b)
    A[0, 0] = np.nan
    b[0] = 7.0
    np.testing.assert_array_equal(t.A, np.eye(2))
    np.testing.assert_array_equal(t.b, [1.0, 2.0])


# ---------------------------------------------------------------------------------------
# Bounds
# ---------------------------------------------------------------------------------------


def test_scalar_bounds_broadcast_to_the_stacks_size():
    bounds = qc.Bounds(-1.0, 2.0)
    assert repr(bounds).startswith("Bounds(")
    sol = qc.Stack([qc.Equality(np.eye(3), [5.0, -5.0, 0.5])], bounds=bounds).solve()
    np.testing.assert_allclose(sol.x, [2.0, -1.0, 0.5], atol=1e-8)


def test_bounds_none_means_open():
    bounds = qc.Bounds(upper=[1.0, 2.0])
    assert bounds.n == 2
    np.testing.assert_array_equal(bounds.lower, [-np.inf, -np.inf])
    np.testing.assert_array_equal(bounds.upper, [1.0, 2.0])


def test_bounds_update_is_used_by_the_next_solve():
    bounds = qc.Bounds([-1.0, -1.0], [1.0, 1.0], name="vel")
    stack = qc.Stack([qc.Equality(np.eye(2), [5.0, -5.0])], bounds=bounds)
    np.testing.assert_allclose(stack.solve().x, [1.0, -1.0], atol=1e-8)
    assert bounds.update(upper=[0.5, 0.5]) is bounds
    np.testing.assert_allclose(stack.solve().x, [0.5, -1.0], atol=1e-8)


def test_scalar_bounds_can_be_shared_by_stacks_of_different_sizes():
    limit = qc.Bounds(-1.0, 1.0)
    two = qc.Stack([qc.Equality(np.eye(2), 5.0)], bounds=limit)
    three = qc.Stack([qc.Equality(np.eye(3), -5.0)], bounds=limit)
    np.testing.assert_allclose(two.solve().x, [1.0, 1.0], atol=1e-8)
    np.testing.assert_allclose(three.solve().x, [-1.0, -1.0, -1.0], atol=1e-8)


# ---------------------------------------------------------------------------------------
# linalg
# ---------------------------------------------------------------------------------------


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(
    tau=st.floats(1e-9, 1e3),
    rel=hnp.arrays(np.float64, st.integers(1, 8), elements=st.floats(1e-6, 1e3)),
)
def test_filtered_gains_follow_the_documented_rule(tau, rel):
    s = np.sort(rel * tau)[::-1]  # singular values come sorted, largest first
    g = filtered_gains(s, tau)
    expected = np.where(s >= tau, 1.0 / s, s / tau**2)
    np.testing.assert_allclose(g, expected, rtol=1e-12)
    assert np.all(g <= (1.0 + 1e-12) / tau)  # no gain above 1/τ


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(tau=st.floats(1e-9, 1e3), delta=st.floats(1e-12, 1e-3))
def test_filtered_gains_are_continuous_at_the_threshold(tau, delta):
    below = filtered_gains(np.array([tau * (1.0 - delta)]), tau)[0]
    at = filtered_gains(np.array([tau]), tau)[0]
    above = filtered_gains(np.array([tau * (1.0 + delta)]), tau)[0]
    assert at == pytest.approx(1.0 / tau, rel=1e-14)
    # both sides are within O(δ) of 1/τ: |g(τ(1±δ)) − 1/τ| ≤ δ/τ (+ rounding)
    assert abs(below * tau - 1.0) <= delta * (1 + 1e-9) + 1e-15
    assert abs(above * tau - 1.0) <= delta * (1 + 1e-9) + 1e-15


def test_filtered_gains_without_damping_are_the_inverse():
    s = np.array([3.0, 1.0, 1e-12])
    np.testing.assert_allclose(filtered_gains(s, 0.0), 1.0 / s)


def test_filtered_gains_do_not_depend_on_the_order_of_s():
    np.testing.assert_allclose(filtered_gains(np.array([0.5, 2.0]), 1.0), [0.5, 0.5])
    np.testing.assert_allclose(filtered_gains(np.array([2.0, 0.5]), 1.0), [0.5, 0.5])


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(
    F=st.tuples(st.integers(0, 6), st.integers(1, 6)).flatmap(
        lambda shape: hnp.arrays(np.float64, shape, elements=st.integers(-3, 3).map(float))
    )
)
def test_null_space_is_an_orthonormal_basis_of_the_kernel(F):
    N = null_space(F)
    r = F.shape[1]
    rank = np.linalg.matrix_rank(F) if F.shape[0] else 0
    assert N.shape == (r, r - rank)
    np.testing.assert_allclose(N.T @ N, np.eye(r - rank), atol=1e-12)
    if F.shape[0]:
        np.testing.assert_allclose(F @ N, 0.0, atol=1e-12 * max(1.0, np.abs(F).max()))
    # together with the row space it spans everything
    if rank:
        _, _, Vt = np.linalg.svd(F)
        basis = np.hstack((Vt[:rank].T, N))
        np.testing.assert_allclose(basis.T @ basis, np.eye(r), atol=1e-12)


def test_null_space_edge_cases():
    np.testing.assert_array_equal(null_space(np.zeros((0, 3))), np.eye(3))
    np.testing.assert_allclose(
        null_space(np.zeros((2, 3))) @ null_space(np.zeros((2, 3))).T, np.eye(3), atol=1e-15
    )
    assert null_space(np.eye(3)).shape == (3, 0)


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(
    M=st.tuples(st.integers(1, 6), st.integers(1, 6)).flatmap(
        lambda shape: hnp.arrays(np.float64, shape, elements=st.integers(-3, 3).map(float))
    )
)
def test_filtered_svd_without_damping_is_the_pseudo_inverse(M):
    U, s, Vt, rank, g = filtered_svd(M, 0.0)[:5]  # (newer versions also return tau)
    assert rank == np.linalg.matrix_rank(M)
    assert Vt.shape == (M.shape[1], M.shape[1])
    pinv = Vt[:rank].T @ (g[:, None] * U[:, :rank].T)
    np.testing.assert_allclose(pinv, np.linalg.pinv(M), atol=1e-10)
    # the trailing rows of Vt span the null space
    np.testing.assert_allclose(M @ Vt[rank:].T, 0.0, atol=1e-12 * max(1.0, np.abs(M).max()))


def test_filtered_svd_damps_only_below_the_threshold():
    M = np.diag([1.0, 1e-3, 1e-9])
    _, s, _, rank, g = filtered_svd(M, 1e-6)[:5]  # τ = 1e-6 · s₀ = 1e-6
    assert rank == 3
    np.testing.assert_allclose(g, [1.0, 1e3, 1e-9 / 1e-12])


# ---------------------------------------------------------------------------------------
# the rebinding rule: task.A = J is update(A=J) (validated, counted in matrix_version), so a
# cached factorisation (the weighted engine, PersistentQP) never keeps the old matrix


def _weighted_pair(seed: int = 3, n: int = 6):
    rng = np.random.default_rng(seed)
    hand = qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3), name="hand")
    posture = qc.Equality(np.eye(n), np.zeros(n), name="posture")
    keep = qc.Inequality(rng.standard_normal((2, n)), -0.2, 0.2, name="keep")
    bounds = qc.Bounds(-np.ones(n), np.ones(n))
    return [hand, [keep, posture]], bounds, rng


def _fresh_weighted(levels, bounds) -> np.ndarray:
    """The weighted answer of a stack built now (no cache) on copies of the tasks' numbers."""

    def copy(t):
        if isinstance(t, list):
            return [copy(u) for u in t]
        if isinstance(t, qc.Equality):
            return qc.Equality(t.A, t.b, weight=t.weight)
        return qc.Inequality(t.C, t.lower, t.upper, weight=t.weight)

    box = qc.Bounds(bounds.lower, bounds.upper)
    return qc.Stack([copy(t) for t in levels], bounds=box).solve(method="weighted").x


@pytest.mark.parametrize("what", ["A", "weight", "C", "bounds"])
def test_rebinding_a_matrix_weight_or_box_is_an_update_the_cached_solvers_see(what):
    levels, bounds, rng = _weighted_pair()
    hand, (keep, posture) = levels
    stack = qc.Stack(levels, bounds=bounds)
    pq = PersistentQP(stack)
    stack.solve(method="weighted")  # the weighted engine factorises once
    pq.solve()
    v_task = (hand if what in ("A", "weight") else keep).matrix_version
    if what == "A":
        hand.A = rng.standard_normal((3, 6))
    elif what == "weight":
        hand.weight = 7.0
        assert hand.weight.shape == (3,) and not hand.unit_weight
        np.testing.assert_allclose(hand.sqrt_weight, np.sqrt(7.0))
    elif what == "C":
        keep.C = rng.standard_normal((2, 6))
    else:
        version = bounds.version
        bounds.lower = -0.05 * np.ones(6)
        assert bounds.version == version + 1
    if what != "bounds":
        assert (hand if what in ("A", "weight") else keep).matrix_version == v_task + 1
    want = _fresh_weighted(levels, bounds)
    np.testing.assert_allclose(stack.solve(method="weighted").x, want, atol=1e-9)
    np.testing.assert_allclose(pq.solve().x, want, atol=1e-7)
    # and the strict solve (compiled stacks read every step)
    fresh = qc.Stack([hand, [keep, posture]], bounds=qc.Bounds(bounds.lower, bounds.upper))
    np.testing.assert_allclose(stack.solve().x, fresh.solve().x, atol=1e-9)


def test_a_rebound_matrix_is_validated_copied_and_read_only():
    t = qc.Equality(np.eye(2), [1.0, 2.0], name="hand")
    J = np.array([[1.0, 2.0], [3.0, 4.0]])
    t.A = J
    J[0, 0] = 99.0  # the task keeps its own copy
    assert t.A[0, 0] == 1.0 and not t.A.flags.writeable and not t.is_identity
    with pytest.raises(ValueError, match=r"Equality 'hand'.*shape"):
        t.A = np.ones((3, 2))
    with pytest.raises(ValueError, match="Equality 'hand'"):
        t.A = np.array([[np.nan, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="Equality 'hand'"):
        t.weight = -1.0
    np.testing.assert_array_equal(t.A, [[1.0, 2.0], [3.0, 4.0]])  # all-or-nothing
    box = qc.Bounds(-1.0, 1.0, name="vel")
    box.upper = 0.5  # scalars stay scalars
    assert box.version == 1 and box.resolve(2)[1].tolist() == [0.5, 0.5]
    with pytest.raises(ValueError, match=r"Bounds 'vel': lower > upper"):
        box.lower = 0.7
    # right-hand sides may still be rebound to the caller's buffer (per-step code writes it)
    buf = np.zeros(2)
    t.b = buf
    assert t.b is buf
