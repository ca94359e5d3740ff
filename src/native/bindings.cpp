// nanobind module qpcoord._native: the strict-hierarchy solver of hierarchy.hpp.
#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/vector.h>

#include <array>

#include "cpu_isa.hpp"
#include "hierarchy.hpp"
#include "info_dict.hpp"
#include "refresh.hpp"
#include "weighted.hpp"
#include "ik_step.hpp"

namespace nb = nanobind;
using qpcoord::Hierarchy;
using qpcoord::Mat;
using qpcoord::Vec;

namespace {

/// A C-contiguous float64 numpy array, kept alive by the bound solver.
using Arr = nb::ndarray<double, nb::numpy, nb::c_contig, nb::device::cpu>;
using CMap = Eigen::Map<const Mat, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
using MMap = Eigen::Map<Mat, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
using CVMap = Eigen::Map<const Vec>;
using MVMap = Eigen::Map<Vec>;

/// The solver with its input and output arrays bound once (bind()): a per-step run() passes
/// two scalars, no array conversion (the arrays are the stacked buffers the Python side
/// refreshes in place).
struct Bound : Hierarchy {
  using Hierarchy::Hierarchy;
  std::array<Arr, 12> a;  // Aeq beq C lo hi sw lb ub x res stats detail
  bool bound = false;

  static CMap cmat(const Arr& m) {  // row-major (r, c) seen as a column-major r x c
    const auto r = static_cast<Eigen::Index>(m.shape(0)), c = static_cast<Eigen::Index>(m.shape(1));
    return CMap(m.data(), r, c, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, c));
  }
  static MMap mmat(Arr& m) {
    const auto r = static_cast<Eigen::Index>(m.shape(0)), c = static_cast<Eigen::Index>(m.shape(1));
    return MMap(m.data(), r, c, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, c));
  }
  static CVMap cvec(const Arr& v) { return CVMap(v.data(), static_cast<Eigen::Index>(v.shape(0))); }
  static MVMap mvec(Arr& v) { return MVMap(v.data(), static_cast<Eigen::Index>(v.shape(0))); }

  int run(bool warm, double time_left) {
    if (!bound) return static_cast<int>(qpcoord::kBadInput);
    return solve(cmat(a[0]), cvec(a[1]), cmat(a[2]), cvec(a[3]), cvec(a[4]), cvec(a[5]),
                 cvec(a[6]), cvec(a[7]), warm, time_left, mvec(a[8]), mvec(a[9]), mmat(a[10]),
                 mvec(a[11]));
  }

  /// The tasks' numbers copied into the bound arrays by step() (refresh.hpp), and the output
  /// arrays' copy methods (the x and res step() returns).
  qpcoord::refresh::Stacked stacked;
  nb::object copy_x, copy_res;
  /// info()'s keys (info_dict.hpp: the rule shared with the IK step)
  qpcoord::info::Keys info_keys;

  void set_tasks(nb::handle P, const std::vector<nb::object>& eq,
                 const std::vector<int64_t>& eq_rows, const std::vector<int64_t>& eq_first,
                 const std::vector<nb::object>& in, const std::vector<int64_t>& in_rows,
                 const std::vector<int64_t>& in_first, nb::handle x, nb::handle res) {
    if (!bound) throw nb::value_error("set_tasks: call bind first");
    const qpcoord::refresh::Stacked::Dest d =
        qpcoord::refresh::checked_dest(a, eq, eq_rows, eq_first, in, in_rows, in_first);
    const int64_t n = static_cast<int64_t>(a[0].shape(1));
    copy_x = x.attr("copy");
    copy_res = res.attr("copy");
    stacked.set(P, eq, eq_rows, eq_first, in, in_rows, in_first, n,
                static_cast<int64_t>(a[0].shape(0)), d);
  }

  /// The info dict of the last call (info_dict.hpp, from the bound stats / detail).
  nb::dict info(double kkt_tol) const {
    if (!bound) throw nb::value_error("info: call bind first");
    const Arr& st = a[10];
    return info_keys.make(st.data(), static_cast<int>(st.shape(0)), a[11].data(), kkt_tol);
  }

  /// refresh + run + (x copy, res copy, info) in one call; an int status when the solve
  /// failed, kRefreshInPython when the tasks need the Python refresh (nothing solved).
  nb::object step(bool warm, double time_left, double kkt_tol) {
    if (!stacked.bound() || !copy_x.is_valid())
      throw nb::value_error("step: call set_tasks first");
    if (!stacked.refresh()) return nb::int_(kRefreshInPython);
    int code;
    try {
      code = run(warm, time_left);
    } catch (const std::bad_alloc&) {
      code = static_cast<int>(qpcoord::kBadInput);
    }
    if (code) return nb::int_(code);
    nb::object x = nb::steal(PyObject_CallNoArgs(copy_x.ptr()));
    if (!x.is_valid()) throw nb::python_error();
    nb::object r = nb::steal(PyObject_CallNoArgs(copy_res.ptr()));
    if (!r.is_valid()) throw nb::python_error();
    return nb::make_tuple(x, r, info(kkt_tol));
  }

  /// step()'s answer when a task's data is not the common case (see refresh.hpp)
  static constexpr int kRefreshInPython = -1;
};

/// Cyclic garbage collection of a Hierarchy that holds its stack's tasks (set_tasks): a task
/// referring back to the stack that owns the solver makes a cycle through this object.
int bound_traverse(PyObject* self, visitproc visit, void* arg) {
  Py_VISIT(Py_TYPE(self));
  if (!nb::inst_ready(self)) return 0;
  const Bound* h = nb::inst_ptr<Bound>(self);
  Py_VISIT(h->copy_x.ptr());
  Py_VISIT(h->copy_res.ptr());
  return h->stacked.traverse(visit, arg);
}

int bound_clear(PyObject* self) {
  Bound* h = nb::inst_ptr<Bound>(self);
  h->stacked.clear();
  h->copy_x.reset();
  h->copy_res.reset();
  return 0;
}

PyType_Slot bound_slots[] = {{Py_tp_traverse, reinterpret_cast<void*>(bound_traverse)},
                             {Py_tp_clear, reinterpret_cast<void*>(bound_clear)},
                             {0, nullptr}};

bool dims_ok(const std::array<Arr, 12>& a) {
  static constexpr int kNdim[12] = {2, 1, 2, 1, 1, 1, 1, 1, 1, 1, 2, 1};
  for (int i = 0; i < 12; ++i)
    if (a[i].ndim() != static_cast<size_t>(kNdim[i])) return false;
  return true;
}

}  // namespace

// One source, several modules (CMakeLists.txt): qpcoord._native for baseline x86-64 and, where
// the compiler takes -march=x86-64-v3, qpcoord._native_x86_64_v3; ISA names the build's level.
#ifndef QPCOORD_NATIVE_MODULE
#define QPCOORD_NATIVE_MODULE _native
#endif
#ifndef QPCOORD_NATIVE_ISA
#define QPCOORD_NATIVE_ISA "baseline"
#endif

NB_MODULE(QPCOORD_NATIVE_MODULE, m) {
  m.doc() = "qpcoord's native strict-hierarchy engine (C++17, Eigen); use qpcoord.core.native";
  m.attr("ABI_VERSION") = qpcoord::kAbiVersion;
  m.attr("ISA") = QPCOORD_NATIVE_ISA;
  m.def("x86_64_level", &qpcoord::x86_64_level,
        "The highest x86-64 ISA level (1 = baseline, 2, 3, 4) the running CPU and OS support "
        "(CPUID and XGETBV; 1 off x86-64).");
  m.attr("OK") = static_cast<int>(qpcoord::kOk);
  m.attr("INFEASIBLE_EQ") = static_cast<int>(qpcoord::kInfeasibleEq);
  m.attr("INFEASIBLE_HARD") = static_cast<int>(qpcoord::kInfeasibleHard);
  m.attr("NON_FINITE") = static_cast<int>(qpcoord::kNonFinite);
  m.attr("NOT_CONVERGED") = static_cast<int>(qpcoord::kNotConverged);
  m.attr("BAD_INPUT") = static_cast<int>(qpcoord::kBadInput);
  m.attr("TIME_LIMIT") = static_cast<int>(qpcoord::kTimeLimit);
  m.attr("CHECK_FAILED") = static_cast<int>(qpcoord::kCheckFailed);
  m.attr("REFRESH_IN_PYTHON") = Bound::kRefreshInPython;

  nb::class_<Bound>(m, "Hierarchy",
                    "Strict-hierarchy least squares of one stack structure (sizes fixed).",
                    nb::type_slots(bound_slots))
      .def(nb::init<int, std::vector<int>, std::vector<int>, bool, double>(), nb::arg("n"),
           nb::arg("meq"), nb::arg("min"), nb::arg("has_bounds"), nb::arg("damping"))
      .def(
          "solve",
          [](Bound& h, nb::DRef<const Mat> Aeq, nb::DRef<const Vec> beq,
             nb::DRef<const Mat> C, nb::DRef<const Vec> lo, nb::DRef<const Vec> hi,
             nb::DRef<const Vec> sw, nb::DRef<const Vec> lb, nb::DRef<const Vec> ub, bool warm,
             double time_left, nb::DRef<Vec> x_out, nb::DRef<Vec> res_out, nb::DRef<Mat> stats,
             nb::DRef<Vec> detail) {
            try {
              return h.solve(Aeq, beq, C, lo, hi, sw, lb, ub, warm, time_left, x_out, res_out,
                             stats, detail);
            } catch (const std::bad_alloc&) {
              return static_cast<int>(qpcoord::kBadInput);
            }
          },
          nb::arg("Aeq"), nb::arg("beq"), nb::arg("C"), nb::arg("lo"), nb::arg("hi"),
          nb::arg("sw"), nb::arg("lb"), nb::arg("ub"), nb::arg("warm"),
          nb::arg("time_left"), nb::arg("x_out"), nb::arg("res_out"), nb::arg("stats"),
          nb::arg("detail"))
      .def(
          "bind",
          [](Bound& h, Arr Aeq, Arr beq, Arr C, Arr lo, Arr hi, Arr sw, Arr lb, Arr ub, Arr x_out,
             Arr res_out, Arr stats, Arr detail) {
            std::array<Arr, 12> a{Aeq, beq, C, lo, hi, sw, lb, ub, x_out, res_out, stats, detail};
            if (!dims_ok(a)) throw nb::value_error("bind: wrong number of dimensions");
            h.a = a;
            h.bound = true;
          },
          nb::arg("Aeq"), nb::arg("beq"), nb::arg("C"), nb::arg("lo"), nb::arg("hi"),
          nb::arg("sw"), nb::arg("lb"), nb::arg("ub"), nb::arg("x_out"), nb::arg("res_out"),
          nb::arg("stats"), nb::arg("detail"),
          "Keep these C-contiguous float64 arrays (the solve's inputs and outputs, as solve's "
          "arguments) for run(); the outputs must be writable.")
      .def(
          "run",
          [](Bound& h, bool warm, double time_left) {
            try {
              return h.run(warm, time_left);
            } catch (const std::bad_alloc&) {
              return static_cast<int>(qpcoord::kBadInput);
            }
          },
          nb::arg("warm"), nb::arg("time_left"),
          "solve() on the bound arrays (their current numbers); returns the status code.")
      .def("set_tasks", &Bound::set_tasks, nb::arg("P"), nb::arg("eq"), nb::arg("eq_rows"),
           nb::arg("eq_first"), nb::arg("ineq"), nb::arg("in_rows"), nb::arg("in_first"),
           nb::arg("x"), nb::arg("res"),
           "After bind(): the compiled stack P, its Equality and Inequality tasks in the "
           "stacked arrays' order with their row counts and first rows, and the bound x and "
           "res (their copies are step()'s answer).")
      .def("step", &Bound::step, nb::arg("warm"), nb::arg("time_left"), nb::arg("kkt_tol"),
           "The tasks' numbers copied into the bound arrays (as CompiledStack.refresh_stacked),"
           " run(), and on success (x.copy(), res.copy(), info(kkt_tol)); else the status "
           "code, REFRESH_IN_PYTHON if a task needs the Python refresh (nothing solved).")
      .def_prop_ro(
          "fast_arrays", [](const Bound& h) { return h.stacked.fast(); },
          "step() reads numpy arrays from their heads (True) or through the buffer protocol.")
      .def("info", &Bound::info, nb::arg("kkt_tol"),
           "The last call's info dict (info_dict.hpp; tests/native_info.py defines it).")
      .def_rw("seed_on_miss", &Hierarchy::seed_on_miss,
              "Seed a stage's active set (hard phase, level, minimum-norm step) from its missed "
              "stored working set (True, default) or start it cold (False; for comparisons).")
      .def_rw("downdate", &Hierarchy::downdate,
              "Downdate the working set's QR when a row leaves (True, default) or "
              "refactorise it (False; for comparisons).")
      .def_prop_ro("downdates", &Hierarchy::downdates,
                   "Rows that left a working set through a QR downdate in the last call.")
      .def_rw("rank_revealing_qr", &Hierarchy::rank_revealing_qr,
              "Closed form of a rank-deficient level from the pivoted QR of its projected "
              "equalities when the QR shows a clear rank gap (True, default), else the SVD "
              "(False: the SVD for every rank-deficient level; for comparisons).")
      .def_rw("compress_objective", &Hierarchy::compress_objective,
              "Least squares of a tall level whose closed form came from a QR on the compressed "
              "objective R (True, default) or on its projected equalities (False; comparisons).")
      .def_rw("wide_ls", &Hierarchy::wide_ls,
              "Least-squares step of a wide projected objective of full row rank from one QR "
              "of its transpose (True, default) or two QRs (False; for comparisons).")
      .def_rw("slack_ls", &Hierarchy::slack_ls,
              "A level's least-squares step with the slacks of its rows outside the working "
              "set in closed form (True, default) or by the projected objective (False).")
      .def_prop_ro("slack_steps", &Hierarchy::slack_steps,
                   "Least-squares steps taken by slack_ls in the last call.")
      .def_rw("reuse_finish", &Hierarchy::reuse_finish,
              "The exact finish of an ill-conditioned level starts from the optimal end's "
              "factorisation and step (True, default) or recomputes them (False; A/B).")
      .def_rw("trial_qt_tail", &Hierarchy::trial_qt_tail,
              "A warm trial computes only the columns of Q Qf its least-squares step reads "
              "(True, default) or all of them (False; for comparisons).")
      .def_rw("reduce_slacks", &Hierarchy::reduce_slacks,
              "A level's warm trial in z alone, the working slack rows' slacks eliminated "
              "(True, default), or on the full (z, w) (False; for comparisons).")
      .def_rw("carry_projection", &Hierarchy::carry_projection,
              "The inherited rows' projection carried from level to level through the "
              "changes of the null-space basis (True, default) or recomputed per level "
              "(False; for comparisons).")
      .def_rw("gemv_qr", &Hierarchy::gemv_qr,
              "The pivoted QRs apply each reflector to a block of at least 48 x 8 by one "
              "matrix-vector product and one rank-one update (True; for comparisons) or by "
              "a dot and an axpy per column (False, default: as fast).")
      .def_rw("compress_zero_tail", &Hierarchy::compress_zero_tail,
              "A tall level's objective compressed also when its full pivoted QR stopped at "
              "an exactly zero trailing block (True, default) or not (False; for "
              "comparisons).")
      .def_rw("reuse_k_qr", &Hierarchy::reuse_k_qr,
              "The least-squares step's QR of the projected objective reused while the "
              "working set's QR is unchanged (True, default) or refactorised (False).")
      .def_rw("identity_z", &Hierarchy::identity_z,
              "Projections on a still-identity null-space basis copied (True, default) or "
              "multiplied (False; for comparisons).")
      .def_prop_ro("identity_products", &Hierarchy::identity_products,
                   "Products with an identity null-space basis skipped in the last call.")
      .def_rw("rz_min_norm", &Hierarchy::rz_min_norm,
              "Minimum-norm solutions of [R11 R12] w = b by its RZ factorisation (True, "
              "default) or by the QR of its transpose (False; for comparisons).")
      .def_rw("least_distance", &Hierarchy::least_distance,
              "The minimum-norm stage stepped as a least-distance problem (True, default) "
              "or by the general least squares (False; for comparisons).")
      .def_prop_ro("least_distance_steps", &Hierarchy::least_distance_steps,
                   "Least-squares steps of the last call taken by least_distance.")
      .def_rw("tight_batch", &Hierarchy::tight_batch,
              "A step blocked at length zero adds every row blocking it at length zero (True, "
              "default) or the lowest-index one (False; for comparisons).")
      .def_prop_ro("batch_rows", &Hierarchy::batch_rows,
                   "Rows of the last call added to a working set by tight_batch.")
      .def_rw("gram_screen", &Hierarchy::gram_screen,
              "The dependence test of a level's moving rows skips its pivoted QR where a "
              "Cholesky of their shifted Gram matrix proves them independent (True, default; "
              "x bit for bit the same) or always factorises (False; for comparisons).")
      .def_prop_ro("gram_screens", &Hierarchy::gram_screens,
                   "Levels of the last call whose dependence QR gram_screen skipped.")
      .def_rw("grow_seed", &Hierarchy::grow_seed,
              "A missed stored set of a stage without slack rows grown by the rows its point "
              "violates before the seed (True) or the seed alone (False, default).")
      .def_prop_ro("grown_seeds", &Hierarchy::grown_seeds,
                   "Stages of the last call started from a grown stored set (grow_seed).")
      .def_prop_ro("rz_factors", &Hierarchy::rz_factors,
                   "RZ factorisations of the last call (rz_min_norm).")
      .def_prop_ro("k_qr_reuses", &Hierarchy::k_qr_reuses,
                   "Least-squares steps of the last call that reused K's QR (reuse_k_qr).")
      .def_rw("null_space_freeze", &Hierarchy::null_space_freeze,
              "A rank-deficient tall level frozen by the null space of its QR (default) or not.")
      .def_rw("wy_right", &Hierarchy::wy_right,
              "Z's changes by 16 or more reflectors in the compact WY form (default in the "
              "x86-64-v3 build) or not.")
      .def_prop_ro("wy_applications", &Hierarchy::wy_applications,
                   "Changes of Z or Cin Z of the last call in the compact WY form.")
      .def_prop_ro("null_space_freezes", &Hierarchy::null_space_freezes,
                   "Levels of the last call frozen by null_space_freeze.")
      .def_rw("full_rank_freeze", &Hierarchy::full_rank_freeze,
              "A level of full rank left without freedom directly (default) or by the freeze.")
      .def_prop_ro("full_rank_freezes", &Hierarchy::full_rank_freezes,
                   "Levels of the last call frozen by full_rank_freeze.")
      .def_prop_ro("dependent_drops", &Hierarchy::dependent_drops,
                   "Levels of the last call whose rows lost directions dependent to rounding.")
      .def_rw("wide_freeze", &Hierarchy::wide_freeze,
              "A wide level frozen by the reflectors of its M^T's QR (True, default), or by "
              "the freeze (False; for comparisons).")
      .def_prop_ro("wide_freezes", &Hierarchy::wide_freezes,
                   "Levels of the last call frozen by wide_freeze.")
      .def_rw("freeze_memo", &Hierarchy::freeze_memo,
              "A level's freeze whose inputs (Z, Cin Z, the level's rows, kind, rank, violated "
              "rows) are bit for bit the previous call's: its stored outputs restored (True, "
              "default), or every freeze computed (False; for comparisons).")
      .def_prop_ro("freeze_memo_hits", &Hierarchy::freeze_memo_hits,
                   "Freezes of the last call restored by freeze_memo.")
      .def_rw("trial_memo", &Hierarchy::trial_memo,
              "A stage's warm trial whose working rows and objective are bit for bit the "
              "previous call's, its factorisations untouched since: reused (True, default), or "
              "every trial factorised (False; for comparisons).")
      .def_prop_ro("trial_memo_hits", &Hierarchy::trial_memo_hits,
                   "Trials of the last call whose factorisations trial_memo reused.")
      .def_rw("bound_rows_memo", &Hierarchy::bound_rows_memo,
              "A stage whose Z on entry is bit for bit the previous call's copies its bound "
              "rows (Z's rows scaled to unit norm) from that call's (True, default), or "
              "projects and scales every row (False; for comparisons).")
      .def_prop_ro("bound_rows_memo_hits", &Hierarchy::bound_rows_memo_hits,
                   "Stages of the last call whose bound rows bound_rows_memo copied.")
      .def_rw("closed_form_memo", &Hierarchy::closed_form_memo,
              "A level whose rows and Z on entry are bit for bit the previous call's keeps "
              "M = A Z and its closed form's QR or SVD (True, default), or computes them "
              "(False; for comparisons).")
      .def_prop_ro("closed_form_memo_hits", &Hierarchy::closed_form_memo_hits,
                   "Levels of the last call whose closed-form factorisation was reused.")
      .def_rw("small_rinv", &Hierarchy::small_rinv,
              "The QR closed form's bound on sigma_rank by back substitution up to rank 16 "
              "(default) or by Eigen's blocked triangular solve.")
      .def_prop_ro("small_rinvs", &Hierarchy::small_rinvs,
                   "QR closed forms of the last call bounded by small_rinv.")
      .def_prop_ro("zero_tail_compressions", &Hierarchy::zero_tail_compressions,
                   "Levels of the last call compressed by compress_zero_tail.")
      .def_prop_ro("gemv_steps", &Hierarchy::gemv_steps,
                   "Reflectors of the last call applied by gemv_qr's matrix-vector product "
                   "and rank-one update.")
      .def_prop_ro("reduced_trials", &Hierarchy::reduced_trials,
                   "Warm trials of the last call solved in z alone (reduce_slacks).")
      .def_prop_ro("qr_closed_forms", &Hierarchy::qr_closed_forms,
                   "Levels whose closed form came from a QR (no SVD) in the last call.")
      .def_prop_ro("n", &Hierarchy::n)
      .def_prop_ro("num_levels", &Hierarchy::num_levels)
      .def_prop_ro("damping", &Hierarchy::damping);
  qpcoord::bind_weighted(m);
  qpcoord::bind_ik_step(m);
}
