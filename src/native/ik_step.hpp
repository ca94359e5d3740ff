// qpcoord native engine: one differential-IK step in one call (qpcoord/kinematics/native_step.py).
//
// An IKStep is compiled once from an IK: which task kernel writes which rows of the stacked
// arrays of the IK's compiled stack, the frames it reads (views of Pinocchio's data, bound
// once), the limit boxes. Each step() then, with Pinocchio's computeJointJacobians (and the
// CoM Jacobian) already run on the robot's data: checks q, computes every native task's error
// and Jacobian into the rows of its task and of the stacked arrays, the intersected limit box,
// and solves the strict hierarchy (qpcoord::Hierarchy) into the bound outputs.
#pragma once

#include <nanobind/nanobind.h>

namespace qpcoord {

/// Add IKStep and the spatial test functions (log3, Jlog3, log6, Jlog6) to the module.
void bind_ik_step(nanobind::module_& m);

}  // namespace qpcoord
