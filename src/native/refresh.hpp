// qpcoord native engine: the per-step copy of a compiled stack's tasks into its stacked arrays
// (CompiledStack.refresh_stacked in qpcoord/core/compile.py, done here in one pass).
//
// Each task's arrays are read through the buffer protocol at every call (no cached pointer:
// a task may hold a new array, or a NaN written into its array's base, every step), copied
// into the stacked rows (weighted by sqrt_weight where the weights are not all one). Anything
// other than the common case (an array that is not float64 of the task's shape, the levels
// pointing at their tasks' arrays after a Python-engine refresh, a Python error) makes
// refresh() return false without raising: the caller then runs the Python refresh, which
// broadcasts, converts or raises the message naming the task. Header-only (bindings.cpp).
#pragma once

#include <nanobind/nanobind.h>

#include <cstdint>
#include <cstring>
#include <vector>

namespace qpcoord {
namespace refresh {

namespace nb = nanobind;

/// The public head of a numpy array (numpy's PyArrayObject_fields: public, the same layout in
/// numpy 1.x and 2.x); read only for an object whose type is exactly numpy.ndarray and whose
/// dtype is the float64 singleton (Fast), checked once at set() on a known array.
struct NpyHead {
  PyObject_HEAD char* data;
  int nd;
  Py_ssize_t* dimensions;
  Py_ssize_t* strides;
  PyObject* base;
  PyObject* descr;
  int flags;
};

/// numpy.ndarray and the native float64 dtype (no numpy headers: the objects themselves).
struct Fast {
  PyObject* type = nullptr;
  PyObject* f64 = nullptr;
  bool ok = false;
};

/// A float64 array (native byte order, aligned, whole-element strides) of `ndim` dimensions
/// and the given shape: read from the numpy array's head (Fast) or through the buffer
/// protocol (released at scope exit); ok is false (no Python error left set) otherwise.
struct In {
  Py_buffer b{};
  bool got = false, ok = false;
  int64_t s0 = 1, s1 = 1;  // strides in elements
  const double* p = nullptr;
  In(PyObject* o, int ndim, int64_t rows, int64_t cols, const Fast& f) {
    if (f.ok && reinterpret_cast<PyObject*>(Py_TYPE(o)) == f.type) {
      const auto* h = reinterpret_cast<const NpyHead*>(o);
      if (h->descr == f.f64) {
        ok = h->nd == ndim && h->dimensions[0] == rows && (ndim == 1 || h->dimensions[1] == cols);
        for (int i = 0; ok && i < ndim; ++i) ok = h->strides[i] % 8 == 0;
        ok = ok && reinterpret_cast<std::uintptr_t>(h->data) % alignof(double) == 0;
        if (!ok) return;
        p = reinterpret_cast<const double*>(h->data);
        s0 = h->strides[0] / 8;
        s1 = ndim == 2 ? h->strides[1] / 8 : 1;
        return;
      }
    }
    got = PyObject_GetBuffer(o, &b, PyBUF_STRIDES | PyBUF_FORMAT) == 0;
    if (!got) {
      PyErr_Clear();
      return;
    }
    ok = b.ndim == ndim && b.itemsize == 8 && b.format && std::strcmp(b.format, "d") == 0 &&
         b.shape[0] == rows && (ndim == 1 || b.shape[1] == cols);
    for (int i = 0; ok && i < ndim; ++i) ok = b.strides[i] % 8 == 0;
    ok = ok && reinterpret_cast<std::uintptr_t>(b.buf) % alignof(double) == 0;
    if (!ok) return;
    p = static_cast<const double*>(b.buf);
    s0 = b.strides[0] / 8;
    s1 = ndim == 2 ? b.strides[1] / 8 : 1;
  }
  ~In() {
    if (got) PyBuffer_Release(&b);
  }
  In(const In&) = delete;
  In& operator=(const In&) = delete;
};

/// Attribute `name` of `o` (a new reference), or null with no Python error set.
inline nb::object get(nb::handle o, nb::handle name) {
  PyObject* r = PyObject_GetAttr(o.ptr(), name.ptr());
  if (!r) PyErr_Clear();
  return nb::steal(r);
}

/// dst (rows x cols, C order) = diag(w) src; w null: src.
inline void copy_rows(const In& src, const double* w, int64_t ws, int64_t rows, int64_t cols,
                      double* dst) {
  if (!w && src.s1 == 1 && src.s0 == cols) {
    std::memcpy(dst, src.p, sizeof(double) * static_cast<size_t>(rows * cols));
    return;
  }
  for (int64_t i = 0; i < rows; ++i) {
    const double* r = src.p + i * src.s0;
    double* d = dst + i * cols;
    if (w) {
      const double wi = w[i * ws];
      for (int64_t j = 0; j < cols; ++j) d[j] = wi * r[j * src.s1];
    } else {
      for (int64_t j = 0; j < cols; ++j) d[j] = r[j * src.s1];
    }
  }
}

/// The tasks of one compiled stack and where their rows go in the stacked arrays.
class Stacked {
 public:
  /// Where to write: the stacked arrays (C order, n columns); lbs/ubs the box.
  struct Dest {
    double *Aeq, *beq, *C, *lo, *hi, *sw, *lbs, *ubs;
  };

  Stacked()
      : A_(intern("A")), b_(intern("b")), C_(intern("C")), lower_(intern("lower")),
        upper_(intern("upper")), sqrt_weight_(intern("sqrt_weight")),
        unit_weight_(intern("unit_weight")), aliased_(intern("_aliased")),
        bounds_(intern("bounds")), version_(intern("version")),
        bounds_version_(intern("_bounds_version")), refresh_bounds_(intern("_refresh_bounds")),
        lb_(intern("lb")), ub_(intern("ub")) {}

  /// Bind the compiled stack P, its tasks (eq: Equality, in: Inequality, in the stacked
  /// arrays' order), their row counts and first rows, n columns, the rows of P.Aeq and the
  /// destinations (d.Aeq: P.Aeq's data).
  void set(nb::handle P, const std::vector<nb::object>& eq, const std::vector<int64_t>& eq_rows,
           const std::vector<int64_t>& eq_first, const std::vector<nb::object>& in,
           const std::vector<int64_t>& in_rows, const std::vector<int64_t>& in_first, int64_t n,
           int64_t aeq_rows, const Dest& d) {
    P_ = nb::borrow(P);
    eq_ = eq;
    eq_rows_ = eq_rows;
    eq_first_ = eq_first;
    in_ = in;
    in_rows_ = in_rows;
    in_first_ = in_first;
    n_ = n;
    d_ = d;
    set_ = true;
    fast_ = Fast{};
    // the head read only if it finds P.Aeq's data, shape and strides where bind() saw them
    nb::object Aeq = get(P, intern("Aeq")), np = nb::module_::import_("numpy");
    if (!Aeq.is_valid()) return;
    Fast f{reinterpret_cast<PyObject*>(Py_TYPE(Aeq.ptr())), nullptr, true};
    nb::object f64 = np.attr("dtype")("float64");
    f.f64 = f64.ptr();
    const In probe(Aeq.ptr(), 2, aeq_rows, n, f);
    if (f.type != np.attr("ndarray").ptr() || !probe.ok || probe.got ||
        probe.p != d.Aeq || probe.s0 != n || probe.s1 != 1)
      return;
    fast_ = f;
    f64_ = f64;  // kept alive (a singleton)
  }

  bool bound() const { return set_; }

  /// The Python objects held (the compiled stack, its tasks), for the owner's tp_traverse:
  /// a task that refers back to its stack makes a cycle the collector must see through.
  int traverse(visitproc visit, void* arg) const {
    Py_VISIT(P_.ptr());
    for (const nb::object& t : eq_) Py_VISIT(t.ptr());
    for (const nb::object& t : in_) Py_VISIT(t.ptr());
    return 0;
  }

  /// Drop them (tp_clear; a collected cycle): refresh() then returns false.
  void clear() {
    set_ = false;
    P_.reset();
    eq_.clear();
    in_.clear();
  }

  /// Are numpy arrays read from their heads (else through the buffer protocol)?
  bool fast() const { return fast_.ok; }

  /// Copy every task's current numbers and the box; false: the Python refresh must run.
  bool refresh() const {
    if (!set_) return false;
    {
      nb::object al = get(P_, aliased_);
      if (!al.is_valid() || al.ptr() != Py_False) return false;
    }
    const int64_t n = n_;
    for (size_t k = 0; k < eq_.size(); ++k) {
      const nb::object& t = eq_[k];
      const int64_t m = eq_rows_[k], i = eq_first_[k];
      nb::object A = get(t, A_), b = get(t, b_), unit = get(t, unit_weight_);
      if (!A.is_valid() || !b.is_valid() || !unit.is_valid()) return false;
      const In a(A.ptr(), 2, m, n, fast_), v(b.ptr(), 1, m, 1, fast_);
      if (!a.ok || !v.ok) return false;
      const int truth = unit.ptr() == Py_True    ? 1
                        : unit.ptr() == Py_False ? 0
                                                 : PyObject_IsTrue(unit.ptr());
      if (truth < 0) {
        PyErr_Clear();
        return false;
      }
      if (truth) {
        copy_rows(a, nullptr, 0, m, n, d_.Aeq + i * n);
        copy_rows(v, nullptr, 0, m, 1, d_.beq + i);
        continue;
      }
      nb::object sw = get(t, sqrt_weight_);
      if (!sw.is_valid()) return false;
      const In w(sw.ptr(), 1, m, 1, fast_);
      if (!w.ok) return false;
      copy_rows(a, w.p, w.s0, m, n, d_.Aeq + i * n);
      copy_rows(v, w.p, w.s0, m, 1, d_.beq + i);
    }
    for (size_t k = 0; k < in_.size(); ++k) {
      const nb::object& t = in_[k];
      const int64_t m = in_rows_[k], j = in_first_[k];
      nb::object C = get(t, C_), lo = get(t, lower_), hi = get(t, upper_),
                 sw = get(t, sqrt_weight_);
      if (!C.is_valid() || !lo.is_valid() || !hi.is_valid() || !sw.is_valid()) return false;
      const In c(C.ptr(), 2, m, n, fast_), l(lo.ptr(), 1, m, 1, fast_),
          h(hi.ptr(), 1, m, 1, fast_), w(sw.ptr(), 1, m, 1, fast_);
      if (!c.ok || !l.ok || !h.ok || !w.ok) return false;
      copy_rows(c, nullptr, 0, m, n, d_.C + j * n);
      copy_rows(l, nullptr, 0, m, 1, d_.lo + j);
      copy_rows(h, nullptr, 0, m, 1, d_.hi + j);
      copy_rows(w, nullptr, 0, m, 1, d_.sw + j);
    }
    return box();
  }

 private:
  static nb::object intern(const char* s) { return nb::steal(PyUnicode_InternFromString(s)); }

  /// The box as CompiledStack._refresh_bounds resolves it, into lbs/ubs (nothing without
  /// bounds: they stay +-inf).
  bool box() const {
    nb::object B = get(P_, bounds_);
    if (!B.is_valid()) return false;
    if (B.is_none()) return true;
    nb::object v = get(B, version_), pv = get(P_, bounds_version_);
    if (!v.is_valid() || !pv.is_valid()) return false;
    if (v.ptr() != pv.ptr()) {
      const int same = PyObject_RichCompareBool(v.ptr(), pv.ptr(), Py_EQ);
      if (same < 0) {
        PyErr_Clear();
        return false;
      }
      if (!same) {  // the bounds changed: CompiledStack._refresh_bounds resolves them
        PyObject* r = PyObject_CallMethodNoArgs(P_.ptr(), refresh_bounds_.ptr());
        if (!r) {
          PyErr_Clear();  // the Python refresh raises it again, with its message
          return false;
        }
        Py_DECREF(r);
      }
    }
    nb::object lb = get(P_, lb_), ub = get(P_, ub_);
    if (!lb.is_valid() || !ub.is_valid()) return false;
    const In l(lb.ptr(), 1, n_, 1, fast_), u(ub.ptr(), 1, n_, 1, fast_);
    if (!l.ok || !u.ok) return false;
    copy_rows(l, nullptr, 0, n_, 1, d_.lbs);
    copy_rows(u, nullptr, 0, n_, 1, d_.ubs);
    return true;
  }

  nb::object A_, b_, C_, lower_, upper_, sqrt_weight_, unit_weight_, aliased_, bounds_, version_,
      bounds_version_, refresh_bounds_, lb_, ub_;
  nb::object P_;
  std::vector<nb::object> eq_, in_;
  std::vector<int64_t> eq_rows_, eq_first_, in_rows_, in_first_;
  int64_t n_ = 0;
  Dest d_{};
  bool set_ = false;
  Fast fast_;
  nb::object f64_;
};

/// set_tasks' checks, shared by the Hierarchy (bindings.cpp) and Weighted (weighted.cpp)
/// bindings: the bound arrays a (Aeq beq C lo hi sw lb ub first: shape(0) rows, shape(1)
/// columns) agree in their columns, the task lists match their row counts and first rows,
/// and every task's rows lie inside its arrays; nb::value_error naming what is wrong.
/// Returns where each array's data is (Stacked::set's destinations).
template <typename Arrays>
Stacked::Dest checked_dest(Arrays& a, const std::vector<nb::object>& eq,
                           const std::vector<int64_t>& eq_rows,
                           const std::vector<int64_t>& eq_first,
                           const std::vector<nb::object>& in,
                           const std::vector<int64_t>& in_rows,
                           const std::vector<int64_t>& in_first) {
  const int64_t n = static_cast<int64_t>(a[0].shape(1));
  if (static_cast<int64_t>(a[2].shape(1)) != n || static_cast<int64_t>(a[6].shape(0)) != n ||
      static_cast<int64_t>(a[7].shape(0)) != n)
    throw nb::value_error("set_tasks: the bound arrays' columns differ");
  if (eq.size() != eq_rows.size() || eq.size() != eq_first.size() ||
      in.size() != in_rows.size() || in.size() != in_first.size())
    throw nb::value_error("set_tasks: tasks, row counts and first rows differ in length");
  for (size_t k = 0; k < eq.size(); ++k)
    if (eq_rows[k] < 0 || eq_first[k] < 0 ||
        eq_first[k] + eq_rows[k] > static_cast<int64_t>(a[0].shape(0)) ||
        eq_first[k] + eq_rows[k] > static_cast<int64_t>(a[1].shape(0)))
      throw nb::value_error("set_tasks: equality rows outside Aeq");
  for (size_t k = 0; k < in.size(); ++k)
    for (int i = 2; i < 6; ++i)
      if (in_rows[k] < 0 || in_first[k] < 0 ||
          in_first[k] + in_rows[k] > static_cast<int64_t>(a[i].shape(0)))
        throw nb::value_error("set_tasks: inequality rows outside C");
  return Stacked::Dest{a[0].data(), a[1].data(), a[2].data(), a[3].data(),
                       a[4].data(), a[5].data(), a[6].data(), a[7].data()};
}

}  // namespace refresh
}  // namespace qpcoord
