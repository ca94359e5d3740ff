// qpcoord native engine: the info dict of a strict-hierarchy solve, built from the solver's
// stats and detail arrays and its counters (NativeHierarchy.solve's info;
// tests/support/native_info.py is its definition). One rule for the Hierarchy binding (bindings.cpp) and the IK step (ik_step.cpp).
// Header-only.
#pragma once

#include <nanobind/nanobind.h>

#include <array>

#include "hierarchy.hpp"

namespace qpcoord {
namespace info {

namespace nb = nanobind;

/// The dict's keys, interned once, and a template dict holding them in order (a copy of it
/// has its keys hashed and room for all: no resize when the values are set).
class Keys {
 public:
  Keys() {
    static const char* const kKeys[kSize + 1] = {
        "engine",           "hard_iterations",    "active_set_iterations",
        "min_norm_iterations", "warm_start_hits", "warm_start_seeded",
        "closed_form_levels", "qp_calls",         "uncertified",
        "stats",            "native"};
    for (int i = 0; i <= kSize; ++i) keys_[i] = nb::steal(PyUnicode_InternFromString(kKeys[i]));
    nb::dict tpl;
    for (int i = 0; i < kSize; ++i) tpl[keys_[i]] = nb::none();
    template_ = tpl;
  }

  /// The info dict of a solve: s the stats (stages x 3, row-major: per stage hard, levels...,
  /// minimum-norm step: active-set iterations, warm-start hit 0/1, closed form 0/1), d the
  /// detail (8 doubles: [5] the worst level consistency deviation, [6] its level, [7] the
  /// stages seeded on a miss); a level is uncertified when its deviation exceeds kkt_tol.
  /// "stats" holds a copy of the solver's counters (a Stats: its own object, so a later
  /// solve does not change the info of this one).
  nb::dict make(const double* s, int stages, const double* d, double kkt_tol,
                const Stats& counters) const {
    const int last = stages - 2;
    nb::list levels, closed, uncertified;
    long hits = 0, calls = 0;
    for (int k = 0; k < stages; ++k) {
      const double it = s[3 * k], h = s[3 * k + 1], c = s[3 * k + 2];
      if (k > 0 && k < stages - 1) levels.append(static_cast<long>(it));
      if (h != 0.0) ++hits;
      if (c != 0.0 && k > 0 && k <= last) closed.append(k - 1);
      if (it != 0.0 || h != 0.0) ++calls;
    }
    if (d[5] > kkt_tol) uncertified.append(nb::make_tuple(static_cast<long>(d[6]), d[5]));
    nb::dict out = nb::steal<nb::dict>(PyDict_Copy(template_.ptr()));
    if (!out.is_valid()) throw nb::python_error();
    const nb::object vals[kSize] = {keys_[kSize],  // "native"
                                nb::int_(static_cast<long>(s[0])),
                                levels,
                                nb::int_(static_cast<long>(s[3 * (stages - 1)])),
                                nb::int_(hits),
                                nb::int_(static_cast<long>(d[7])),
                                closed,
                                nb::int_(calls),
                                uncertified,
                                nb::cast(counters, nb::rv_policy::copy)};
    for (int i = 0; i < kSize; ++i)
      if (PyDict_SetItem(out.ptr(), keys_[i].ptr(), vals[i].ptr()) != 0) throw nb::python_error();
    return out;
  }

 private:
  static constexpr int kSize = 10;  ///< the dict's entries
  std::array<nb::object, kSize + 1> keys_;  ///< the entries' keys, then the engine's name
  nb::object template_;
};

}  // namespace info
}  // namespace qpcoord
