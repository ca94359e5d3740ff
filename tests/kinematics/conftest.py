"""Fixtures shared by the kinematics tests."""

from support.native_ik import robots  # noqa: F401 (the test robots, a module-scoped fixture)
