// nanobind module qpcoord._native: the strict-hierarchy solver of hierarchy.hpp.
#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/vector.h>

#include "hierarchy.hpp"

namespace nb = nanobind;
using qpcoord::Hierarchy;
using qpcoord::Mat;
using qpcoord::Vec;

NB_MODULE(_native, m) {
  m.doc() = "qpcoord's native strict-hierarchy engine (C++17, Eigen); use qpcoord.core.native";
  m.attr("ABI_VERSION") = qpcoord::kAbiVersion;
  m.attr("OK") = static_cast<int>(qpcoord::kOk);
  m.attr("INFEASIBLE_EQ") = static_cast<int>(qpcoord::kInfeasibleEq);
  m.attr("INFEASIBLE_HARD") = static_cast<int>(qpcoord::kInfeasibleHard);
  m.attr("NON_FINITE") = static_cast<int>(qpcoord::kNonFinite);
  m.attr("NOT_CONVERGED") = static_cast<int>(qpcoord::kNotConverged);
  m.attr("BAD_INPUT") = static_cast<int>(qpcoord::kBadInput);
  m.attr("TIME_LIMIT") = static_cast<int>(qpcoord::kTimeLimit);
  m.attr("CHECK_FAILED") = static_cast<int>(qpcoord::kCheckFailed);

  nb::class_<Hierarchy>(m, "Hierarchy",
                        "Strict-hierarchy least squares of one stack structure (sizes fixed).")
      .def(nb::init<int, std::vector<int>, std::vector<int>, bool, double>(), nb::arg("n"),
           nb::arg("meq"), nb::arg("min"), nb::arg("has_bounds"), nb::arg("damping"))
      .def(
          "solve",
          [](Hierarchy& h, nb::DRef<const Mat> Aeq, nb::DRef<const Vec> beq,
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
      .def_prop_ro("n", &Hierarchy::n)
      .def_prop_ro("num_levels", &Hierarchy::num_levels)
      .def_prop_ro("damping", &Hierarchy::damping);
}
