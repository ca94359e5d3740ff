// nanobind module qpcoord._native: the strict-hierarchy solver of hierarchy.hpp.
#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <array>
#include <iterator>
#include <new>
#include <string>

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
    return info_keys.make(st.data(), static_cast<int>(st.shape(0)), a[11].data(), kkt_tol,
                          stats());
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

  nb::class_<qpcoord::Settings>(m, "Settings",
                                "What a user may tune in a Hierarchy (Hierarchy.settings).")
      .def(nb::init<>())
      .def_rw("kkt_tol", &qpcoord::Settings::kkt_tol,
              "Multiplier sign tolerance of the active set, relative to the largest entry of "
              "the gradient (dimensionless). Default 1e-9 (the Python engine's KKT_TOL).")
      .def_rw("violation_tol", &qpcoord::Settings::violation_tol,
              "A level row violated at the level's optimum by more than this, relative to its "
              "scale, is frozen violated, else inherited (dimensionless). Default 1e-6.")
      .def_rw("max_iter_factor", &qpcoord::Settings::max_iter_factor,
              "Iteration cap of each active-set solve: max_iter_factor * (rows + columns) + 10 "
              "iterations. Default 6.")
      .def_rw("time_limit", &qpcoord::Settings::time_limit,
              "Wall-clock limit of one solve in seconds (inf: none); the smaller of it and the "
              "call's time_left applies. Default inf.");

  // The counters by name: their attributes, equality (every counter equal) and repr (the
  // non-zero ones) come from this one table.
  using S = qpcoord::Stats;
  struct Counter {
    const char* name;
    int S::*field;
    const char* doc;
  };
  static constexpr Counter kCounters[] = {
    {"downdates", &S::downdates, "Rows that left a working set by a QR downdate."},
    {"slack_steps", &S::slack_steps, "Least-squares steps by the slack structure."},
    {"least_distance_steps", &S::least_distance_steps, "Minimum-norm steps taken as a least-distance problem."},
    {"k_qr_reuses", &S::k_qr_reuses, "Least-squares steps that reused the projected objective's QR."},
    {"batch_rows", &S::batch_rows, "Rows added at once to a working set at a degenerate point."},
    {"reduced_trials", &S::reduced_trials, "Warm trials of a level solved in z alone."},
    {"rz_factors", &S::rz_factors, "RZ factorisations of [R11 R12]."},
    {"qr_closed_forms", &S::qr_closed_forms, "Levels whose closed form came from a QR (no SVD)."},
    {"small_rinvs", &S::small_rinvs, "QR closed forms bounded by back substitution."},
    {"zero_tail_compressions", &S::zero_tail_compressions, "Levels compressed past an exactly zero trailing block."},
    {"identity_products", &S::identity_products, "Products with an identity Z skipped."},
    {"null_space_freezes", &S::null_space_freezes, "Freezes onto null([R11 R12]) of the closed form's QR."},
    {"full_rank_freezes", &S::full_rank_freezes, "Levels that left no freedom (no freeze computed)."},
    {"wide_freezes", &S::wide_freezes, "Freezes by a wide level's own reflectors."},
    {"dependent_drops", &S::dependent_drops, "Levels whose rows lost directions dependent on frozen rows."},
    {"gram_screens", &S::gram_screens, "Dependence QRs skipped on a Cholesky proof."},
    {"freeze_memo_hits", &S::freeze_memo_hits, "Freezes restored from the freeze cache."},
    {"closed_form_memo_hits", &S::closed_form_memo_hits, "Closed forms whose factorisation was reused."},
    {"trial_memo_hits", &S::trial_memo_hits, "Warm trials whose factorisations were reused."},
    {"bound_rows_memo_hits", &S::bound_rows_memo_hits, "Stages whose bound rows came from the cache."},
    {"wy_applications", &S::wy_applications, "Changes of Z by the compact WY form (builds with FMA)."},
    {"pruned_working_sets", &S::pruned_working_sets, "Levels whose working set was stored without its rows far from the start (a zero objective)."},
    {"zero_objective_hits", &S::zero_objective_hits, "Warm trials accepted at a zero objective whatever their multipliers."},
    {"range_trials", &S::range_trials, "Warm trials whose least-squares step came from the closed form's triangular factor (no factorisation of the projected objective)."},
  };
  auto stats = nb::class_<S>(m, "Stats",
                             "Counters of one solve: how often each path and cache was taken "
                             "(they describe the work, never the answer).");
  for (const Counter& c : kCounters) stats.def_ro(c.name, c.field, c.doc);
  stats.def("__eq__", [](const S& a, const S& b) {
    for (const Counter& c : kCounters)
      if (a.*c.field != b.*c.field) return false;
    return true;
  }, nb::is_operator());
  // pickled with the Solution whose info holds it: the counters in the table's order
  stats.def("__getstate__", [](const S& s) {
    nb::list out;
    for (const Counter& c : kCounters) out.append(s.*c.field);
    return nb::tuple(out);
  });
  stats.def("__setstate__", [](S& s, const nb::tuple& state) {
    if (nb::len(state) != std::size(kCounters)) throw nb::value_error("Stats: wrong state size");
    new (&s) S();
    std::size_t i = 0;
    for (const Counter& c : kCounters) s.*c.field = nb::cast<int>(state[i++]);
  });
  stats.def("__repr__", [](const S& s) {
    std::string out = "Stats(";
    const char* sep = "";
    for (const Counter& c : kCounters)
      if (s.*c.field != 0) {
        out += sep;
        out += c.name;
        out += "=" + std::to_string(s.*c.field);
        sep = ", ";
      }
    return out + ")";
  });

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
      .def_rw("settings", &Hierarchy::settings,
              "The solver's Settings (tolerances, iteration cap, time limit), changed in place.")
      .def("invalidate_caches", &Hierarchy::invalidate_caches,
           "Forget every cached factorisation, product and freeze (the next call computes "
           "them, as when its matrices changed); the stored working sets stay.")
      .def_prop_ro(
          "stats", [](const Bound& h) { return h.stats(); },
          "A copy of the last call's Stats (the counters of the paths and caches taken).")
      .def_prop_ro("n", &Hierarchy::n)
      .def_prop_ro("num_levels", &Hierarchy::num_levels)
      .def_prop_ro("damping", &Hierarchy::damping);
  qpcoord::bind_weighted(m);
  qpcoord::bind_ik_step(m);
}
