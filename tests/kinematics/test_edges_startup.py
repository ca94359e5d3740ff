"""Starting outside a joint position limit: ``IK(..., outside_limits=...)`` reports and
recovers within the speed and acceleration limits, or raises naming the joints."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.kinematics.startup import OutsideLimitsError
from qpcoord.kinematics.tasks import AccelerationLimits

DT = 0.01
A_MAX = 20.0
# the Kinova's neutral() is below the lower limits of its joints 2, 3 and 5
OUTSIDE = ("j2s6s200_joint_2", "j2s6s200_joint_3", "j2s6s200_joint_5")


@pytest.fixture(scope="module")
def kinova():
    return qc.robots.load("kinova")


def _ik(robot, engine, policy="recover", accel=True):
    limits = [qc.JointLimits(robot), qc.VelocityLimits(robot)]
    if accel:
        limits.append(AccelerationLimits(robot, A_MAX))
    hold = qc.PostureTask(robot, robot.neutral())
    return qc.IK(robot, [hold], dt=DT, limits=limits, engine=engine, outside_limits=policy)


@pytest.mark.parametrize("engine", ["native", "python"])
def test_recover_reports_and_respects_the_limits(kinova, engine):
    ik = _ik(kinova, engine)
    q = kinova.neutral()
    lower = qc.JointLimits(kinova)
    up0, down0 = lower.distances(q)
    v, sol = ik.step(q)
    report = sol.info["outside_limits"]
    assert sorted(report) == sorted(OUTSIDE)
    # signed excess q − q_min (< 0: below the lower limit), rad
    names = [kinova.model.names[j] for j in range(1, kinova.model.njoints)]
    by_name = dict(zip([names[i] for i in lower.joints], down0, strict=True))
    for name in OUTSIDE:
        assert report[name] == pytest.approx(by_name[name], rel=1e-12)
        assert report[name] < -0.3
    vs, reported, was_outside = [np.zeros(kinova.nv), v], [True], [True]
    q = kinova.integrate(q, v, DT)
    for _ in range(200):  # 0.82 rad back at the 0.63 rad/s speed limit: ~1.3 s
        up, down = lower.distances(q)
        was_outside.append(min(up.min(), down.min()) < -1e-10)
        q, v, sol = ik.step_integrate(q)
        vs.append(v)
        reported.append("outside_limits" in sol.info)
    vs = np.array(vs)
    # back inside every limit, within the speed and acceleration limits all along
    up, down = lower.distances(q)
    assert min(up.min(), down.min()) >= -1e-10
    assert np.all(np.abs(vs) <= kinova.velocity_limit * (1 + 1e-9))
    assert (np.abs(np.diff(vs, axis=0)) / DT).max() <= A_MAX * (1 + 1e-9)
    # reported at every step while outside, and no more once back
    assert reported == was_outside
    assert 100 < sum(reported) < 200
    assert not ik.start_check.pending
    # a reset checks again
    ik.reset()
    assert "outside_limits" in ik.step(kinova.neutral())[1].info


def test_inside_no_report_and_no_more_checks(kinova):
    ik = _ik(kinova, None)
    q = kinova.neutral()
    q[[2, 3, 6]] = [1.5, 1.0, 1.0]  # joints 2, 3, 5 inside their limits
    v, sol = ik.step(q)
    assert "outside_limits" not in sol.info
    assert not ik.start_check.pending


@pytest.mark.parametrize("engine", ["native", "python"])
def test_raise_names_the_joints(kinova, engine):
    ik = _ik(kinova, engine, policy="raise")
    with pytest.raises(OutsideLimitsError, match="j2s6s200_joint_2") as err:
        ik.step(kinova.neutral())
    assert sorted(err.value.joints) == sorted(OUTSIDE)
    assert all(excess < 0 for excess in err.value.joints.values())
    assert isinstance(err.value, ValueError)
    with pytest.raises(OutsideLimitsError):
        ik.step_integrate(kinova.neutral())


def test_raise_above_an_upper_limit_on_a_fixed_base():
    panda = qc.robots.load("panda")
    q = np.clip(np.zeros(panda.nq), panda.lower + 0.1, panda.upper - 0.1)
    q[1] = panda.upper[1] + 0.25
    ik = qc.IK(panda, [qc.PostureTask(panda, q)], dt=DT, outside_limits="raise")
    with pytest.raises(OutsideLimitsError, match=r"panda_joint2 by \+0\.25") as err:
        ik.step(q)
    assert err.value.joints == {"panda_joint2": pytest.approx(0.25, abs=1e-12)}


@pytest.mark.parametrize("bad", ["ignore", None, 1])
def test_bad_policy_is_named(kinova, bad):
    with pytest.raises(ValueError, match="outside_limits"):
        qc.IK(kinova, [qc.PostureTask(kinova, kinova.neutral())], dt=DT, outside_limits=bad)
