/* qpcoord native engine: the C interface by which another extension module hands the IK step
 * (ik_step.cpp) a kernel of inequality rows it computes itself -- qpcoord._collision's
 * collision rows (collision/bindings.cpp), built on a library (coal) that qpcoord._native
 * does not link.
 *
 * The producer returns a PyCapsule named QPCOORD_ROWS_KERNEL_CAPSULE whose pointer is a
 * qpcoord_rows_kernel; the capsule keeps the producer's object, and so ctx, C and lower,
 * alive. The IK step holds the capsule and, at each step, after Pinocchio's kinematics of
 * that step's q (the producer reads the robot's pinocchio.Data it was built on), calls
 * update(ctx, gain, dt): it writes the rows' C (rows x cols, row-major, unweighted) and lower
 * bounds (rows) into its own buffers; every row's upper bound is +inf. A row without a
 * constraint this step is a zero row with lower -inf (a constant row count). update returns
 * the number of constrained rows (>= 0), or < 0 when it failed (the rows are then unusable).
 * It allocates nothing, calls no Python and does not throw.
 *
 * A change of this struct or of the meaning of its members changes the capsule's name. */
#ifndef QPCOORD_ROWS_KERNEL_H
#define QPCOORD_ROWS_KERNEL_H

#define QPCOORD_ROWS_KERNEL_CAPSULE "qpcoord.rows_kernel.1"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct qpcoord_rows_kernel {
  void* ctx;
  /* gain: the task's gain as the user set it; dt: the control period (s) */
  int (*update)(void* ctx, double gain, double dt);
  const double* C;
  const double* lower;
  int rows, cols;
} qpcoord_rows_kernel;

#ifdef __cplusplus
}
#endif

#endif /* QPCOORD_ROWS_KERNEL_H */
