// qpcoord native engine: one differential-IK step in one call (qpcoord/kinematics/native_step.py).
//
// An IKStep is compiled once from an IK: which task kernel (a kind of the enum Kind) writes
// which rows of the stacked arrays of the IK's compiled stack, the frames it reads (views of
// Pinocchio's data, bound once), the limit boxes; each kernel's parameters (gain, weights,
// target, ...) are held here and changed through typed setters, its outputs are the task's
// own arrays bound once. Each step() then, with Pinocchio's computeJointJacobians (and the
// CoM Jacobian) already run on the robot's data: checks q, computes every kernel's error and
// Jacobian into the rows of its task and of the stacked arrays, the intersected limit box,
// and solves the strict hierarchy (qpcoord::Hierarchy) into the bound outputs. It reads no
// Python attribute and calls no Python code.
#pragma once

#include <nanobind/nanobind.h>

namespace qpcoord {

/// Add IKStep and the spatial test functions (log3, Jlog3, log6, Jlog6) to the module.
void bind_ik_step(nanobind::module_& m);

}  // namespace qpcoord
