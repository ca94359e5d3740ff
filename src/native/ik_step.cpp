// qpcoord native engine: one differential-IK step in one call (see ik_step.hpp).
//
// The task kernels mirror the Python tasks' _refresh (qpcoord/kinematics/tasks.py,
// frame_tasks.py) term by term: the same error, Jacobian, gain, feed-forward and weights.
// The step is built from typed data only: per kernel its kind, frame slot, row selection and
// row offset (add_task), its parameters held here (gain, row weights, target, feed-forward,
// band faces, contact points: set_* setters, which the Python side calls when a task's
// parameter changed), and its output arrays (bind_rows / bind_band_rows: the task's own
// A, b or C, lower, upper, bound once). No Python attribute is read and no Python code is
// called by step(); nothing in it allocates (buffers sized when the kernel is added). A
// collision kernel's rows come from qpcoord._collision through a C entry point
// (rows_kernel.h, set_rows_kernel): the same step, no Python either.
#include "ik_step.hpp"

#include <nanobind/eigen/dense.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/vector.h>

#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "braking.hpp"
#include "hierarchy.hpp"
#include "info_dict.hpp"
#include "integrate.hpp"
#include "rows_kernel.h"
#include "spatial.hpp"
#include "support_kernels.hpp"
#include "weighted.hpp"

namespace nb = nanobind;

namespace qpcoord {
namespace {

using spatial::Mat3;
using spatial::Mat6;
using spatial::Vec3;
using spatial::Vec6;

using OutArr = nb::ndarray<double, nb::numpy, nb::c_contig, nb::device::cpu>;
/// A task's own output array (any strides): bound once by bind_rows / bind_band_rows
using RowsArr = nb::ndarray<double, nb::numpy, nb::device::cpu>;
using CMap = Eigen::Map<const Mat, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
using MMap = Eigen::Map<Mat, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

constexpr double kInf = std::numeric_limits<double>::infinity();
/// step() codes beyond the Hierarchy's: a bad q (Python re-checks it to name it), or a task
/// whose data the kernel cannot use (a kernel never given its parameters, a support polygon
/// whose contacts are collinear, a non-finite band row: Python runs the task's _refresh,
/// which raises its message).
constexpr int kBadQ = 100;
constexpr int kTaskData = 200;

/// A float64 array seen through its strides (any order), kept alive by `keep`: the views of
/// Pinocchio's data (data.J, data.oMi[j], data.com[0], data.Jcom) bound once.
struct View {
  nb::object keep;
  const double* p = nullptr;
  int64_t rows = 0, cols = 1, s0 = 1, s1 = 1;
  double operator[](int64_t i) const { return p[i * s0]; }
  double operator()(int64_t i, int64_t j) const { return p[i * s0 + j * s1]; }
};

/// A float64 buffer (native byte order, strides whole elements) of a Python object, released
/// at scope exit; ok is false (and no Python error set) for anything else.
struct Buffer {
  Py_buffer b{};
  bool got = false, ok = false;
  explicit Buffer(PyObject* o) {
    got = PyObject_GetBuffer(o, &b, PyBUF_STRIDES | PyBUF_FORMAT) == 0;
    if (!got) {
      PyErr_Clear();
      return;
    }
    ok = b.itemsize == 8 && b.format && std::strcmp(b.format, "d") == 0;
    for (int i = 0; ok && i < b.ndim; ++i) ok = b.strides[i] % 8 == 0;
  }
  ~Buffer() {
    if (got) PyBuffer_Release(&b);
  }
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
};

/// Map `h` (a float64 array of `ndim` dimensions, native byte order, read through the buffer
/// protocol) into v; false if it is not one.
bool view_of(nb::handle h, View& v, size_t ndim) {
  const Buffer a(h.ptr());
  if (!a.ok || a.b.ndim != static_cast<int>(ndim)) return false;
  v.keep = nb::borrow(h);  // keeps the memory alive after the buffer's release
  v.p = static_cast<const double*>(a.b.buf);
  v.rows = static_cast<int64_t>(a.b.shape[0]);
  v.s0 = a.b.strides[0] / 8;
  if (ndim == 2) {
    v.cols = static_cast<int64_t>(a.b.shape[1]);
    v.s1 = a.b.strides[1] / 8;
  } else {
    v.cols = 1;
    v.s1 = 1;
  }
  return true;
}

/// Copy `h`, a float64 array of shape (rows,) (cols == 0) or (rows, cols), row by row into
/// out (rows * max(cols, 1) values), read through the buffer protocol (a setter's argument:
/// no DLPack conversion, which costs more for a per-step target); every value must be
/// finite unless `inf_ok` (band faces). Throws ValueError naming `what` otherwise.
void read_values(nb::handle h, int64_t rows, int64_t cols, double* out, const char* what,
                 bool inf_ok = false) {
  const Buffer a(h.ptr());
  const int ndim = cols ? 2 : 1;
  if (!a.ok || a.b.ndim != ndim || a.b.shape[0] != rows || (cols && a.b.shape[1] != cols)) {
    const std::string shape =
        cols ? "(" + std::to_string(rows) + ", " + std::to_string(cols) + ")"
             : "(" + std::to_string(rows) + ",)";
    throw nb::value_error((std::string(what) + ": expected a float64 array of shape " + shape)
                              .c_str());
  }
  const auto* p = static_cast<const double*>(a.b.buf);
  const int64_t s0 = a.b.strides[0] / 8, s1 = cols ? a.b.strides[1] / 8 : 1;
  const int64_t nc = cols ? cols : 1;
  for (int64_t i = 0; i < rows; ++i)
    for (int64_t j = 0; j < nc; ++j) {
      const double v = p[i * s0 + j * s1];
      if (inf_ok ? std::isnan(v) : !std::isfinite(v))
        throw nb::value_error((std::string(what) + ": not finite").c_str());
      out[i * nc + j] = v;
    }
}

/// The task kernels (qpcoord.kinematics.native_step.TaskKind names them alike).
enum Kind : int {
  kPosition = 0,
  kFramePosition,
  kPose,
  kOrientation,
  kCom,
  kPosture,
  kPoseSplit,  ///< FrameTask(error="split")
  kComBand,         ///< ComBand (an inequality: support_kernels.hpp)
  kSupportPolygon,  ///< SupportPolygon (an inequality: support_kernels.hpp)
  kPositionBand,    ///< PositionBand (an inequality on the frame's position rows)
  // -- kinds after the bands: damping rows, two frames, joint couplings --
  kLMDamping,      ///< LMDamping: sqrt(mu) I, mu from its owner kernel's error (run after all)
  kRelativeFrame,  ///< RelativeFrameTask: log6 of frame in a reference frame (qidx: its slot)
  kJointCoupling,  ///< JointCouplingTask: one row sum(r_i q_i) - offset (qidx: q, v indices)
  kDamping,        ///< DampingTask: v = 0 on all nv rows, q copied into its hold array
  kLowAcceleration,  ///< LowAccelerationTask: v = v_prev (qidx: the integration plan)
  kKindEnd,        ///< one past the last kind evaluated here (not a kind)

  // Rows computed by another extension module through rows_kernel.h (set_rows_kernel), from
  // 32 on: apart from the kinds evaluated here.
  kCollision = 32,  ///< CollisionAvoidance (qpcoord._collision's CollisionKernel.entry())
};

bool known_kind(int k) { return (k >= kPosition && k < kKindEnd) || k == kCollision; }
bool is_band(Kind k) { return k == kComBand || k == kSupportPolygon || k == kPositionBand; }
/// the kinds that write an Inequality (C, lower, upper): the bands and the external rows
bool is_inequality(Kind k) { return is_band(k) || k == kCollision; }
/// the bands on the CoM (their rows read data.com and data.Jcom)
bool on_com(Kind k) { return k == kComBand || k == kSupportPolygon; }

struct Frame {
  View Rj, pj;  ///< rotation and translation of the parent joint (views of data.oMi[j])
  Mat3 Rp;      ///< placement of the frame in its joint
  Vec3 pp;
  std::vector<int> cols;  ///< velocity indices of the joints supporting it
  Mat3 R;                 ///< this step's placement in the world
  Vec3 p;
};

/// A strided output array of a task (its A, b, C, lower or upper), bound once.
struct Out {
  RowsArr arr;
  double* p = nullptr;
  int64_t s0 = 0, s1 = 0;
  double& operator[](int64_t i) const { return p[i * s0]; }
  double& operator()(int64_t i, int64_t j) const { return p[i * s0 + j * s1]; }
  void set(RowsArr a) {
    arr = std::move(a);
    p = arr.data();
    s0 = arr.stride(0);
    s1 = arr.ndim() == 2 ? arr.stride(1) : 0;
  }
};

struct Kernel {
  Kind kind = kPosition;
  int frame = -1;
  int rows = 0;
  std::vector<int> sel;   ///< per row: the axis (0..5) or, for a posture, the joint's v index
  std::vector<int> qidx;  ///< posture: its difference plan (see add_task)
  int row0 = 0;
  // parameters (set_gain, set_weights, set_target / set_faces / set_contacts)
  double gain = 0.0;
  Vec sw;      ///< sqrt(weight) of each row
  Vec target;  ///< POSITION (rows), FRAME_POSITION / COM (3), POSTURE (nq)
  Vec6 vel = Vec6::Zero();  ///< feed-forward (POSITION: rows entries), if has_vel
  bool has_vel = false;
  Mat3 Rinv = Mat3::Identity();  ///< POSE: the target's inverse (R*^T, -R*^T p*);
  Vec3 pinv = Vec3::Zero();      ///< ORIENTATION: R*^T in Rinv
  // outputs: the task's own arrays (Equality: A (rows, nv), b; Inequality: C, lower, upper)
  Out A, b, lower, upper;
  Out hold;   ///< DAMPING, LOW_ACCELERATION: the task's q_hold (nq,), q at each step
  Out vprev;  ///< LOW_ACCELERATION: the task's v_prev (nv,), written at each step
  /// which of gain (1), weights (2), target (4), outputs (8) were set: step() runs a kernel
  /// only once all are (kReady)
  int given = 0;
  static constexpr int kReady = 15;
  int band = -1;  ///< a band kind: its index in IKStep::bands_
  /// kCollision: the producer's capsule (kept alive) and its entry point (set_rows_kernel)
  nb::object rows_capsule;
  const qpcoord_rows_kernel* rows_kernel = nullptr;
  /// an equality kind: the error of each row at the last step (task units; the Python
  /// task's recorded _lm_e), read by an LM_DAMPING kernel on it
  Vec err;
  // LM_DAMPING: the owner kernel's index, lm_damping and LM_ERROR_FLOOR^2 (set_lm_damping)
  int owner = -1;
  double lm = 0.0, floor_sq = 0.0;
};

struct Limit {
  bool velocity = false;  ///< VelocityLimits (else JointLimits, or AccelerationLimits)
  bool acceleration = false;  ///< AccelerationLimits
  double gain = 1.0;      ///< JointLimits: K; AccelerationLimits: the braked limits' K
  Vec lower, upper;       ///< JointLimits: q layout (all of q, or the indexed entries);
                          ///< VelocityLimits: the limit in upper; AccelerationLimits: the
                          ///< braked position limits (indexed entries)
  Vec band_rate;          ///< JointLimits: band / dt per entry (rad/s, m/s; inf: none)
  Vec amax;               ///< AccelerationLimits: a_max (nv,)
  View v_prev;            ///< AccelerationLimits: the limit's own v_prev (nv,), bound once
  std::vector<int> qi, vi;
  bool indexed = false;
  bool given = false;  ///< set_joint_limits / set_velocity_limits / set_acceleration_limits
};

class IKStep {
 public:
  IKStep(int nq, int nv, std::vector<int> meq, std::vector<int> min, bool has_bounds,
         double damping, double dt, std::vector<int> unit_blocks)
      : nq_(nq), nv_(nv), dt_(dt), unit_(std::move(unit_blocks)), meq_(meq), min_(min),
        has_bounds_(has_bounds), h_(nv, std::move(meq), std::move(min), has_bounds, damping) {
    Jt_.resize(6, nv);
    Jl_.resize(6, nv);
    row_.resize(nv);
    lo_.resize(nv);
    hi_.resize(nv);
    hi2_.resize(nv);
    hold_.resize(nq);
  }

  void bind(OutArr Aeq, OutArr beq, OutArr C, OutArr clo, OutArr chi, OutArr csw, OutArr lbs,
            OutArr ubs, OutArr box_lo, OutArr box_hi, OutArr x, OutArr res, OutArr stats,
            OutArr detail) {
    out_ = {Aeq, beq, C, clo, chi, csw, lbs, ubs, box_lo, box_hi, x, res, stats, detail};
    static constexpr size_t kNdim[14] = {2, 1, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 2, 1};
    for (size_t i = 0; i < out_.size(); ++i)
      if (out_[i].ndim() != kNdim[i]) throw nb::value_error("bind: wrong number of dimensions");
    if (Aeq.shape(1) != static_cast<size_t>(nv_) || lbs.shape(0) != static_cast<size_t>(nv_))
      throw nb::value_error("bind: arrays of another size than nv");
    bound_ = true;
  }

  void set_jacobian(nb::handle J) {
    if (!view_of(J, J_, 2) || J_.rows != 6 || J_.cols != nv_)
      throw nb::value_error("set_jacobian: expected data.J, a (6, nv) float64 array");
  }

  void set_com(nb::handle com, nb::handle Jcom) {
    if (!view_of(com, com_, 1) || com_.rows != 3 || !view_of(Jcom, Jcom_, 2) ||
        Jcom_.rows != 3 || Jcom_.cols != nv_)
      throw nb::value_error("set_com: expected data.com[0] (3,) and data.Jcom (3, nv)");
  }

  void set_coordinate_map(nb::DRef<const Mat> M) {
    if (M.rows() != nv_ || M.cols() != nv_) throw nb::value_error("coordinate map: (nv, nv)");
    M_ = M;
    mapped_ = true;
  }

  int add_frame(nb::handle R, nb::handle p, const Mat3& Rp, const Vec3& pp,
                std::vector<int> cols) {
    Frame f;
    if (!view_of(R, f.Rj, 2) || f.Rj.rows != 3 || f.Rj.cols != 3 || !view_of(p, f.pj, 1) ||
        f.pj.rows != 3)
      throw nb::value_error("add_frame: expected oMi[j].rotation (3, 3), .translation (3,)");
    for (int c : cols)
      if (c < 0 || c >= nv_) throw nb::value_error("add_frame: column out of range");
    f.Rp = Rp;
    f.pp = pp;
    f.cols = std::move(cols);
    frames_.push_back(std::move(f));
    return static_cast<int>(frames_.size()) - 1;
  }

  /// A kernel of `kind` writing rows row0.. of the stacked equalities (a band: inequalities).
  /// sel: per row, the axis of the full error (a posture: the joint's v index; a band: the
  /// rows 0..rows-1); qidx: a posture's difference plan (integrate.hpp's segments over its
  /// joints, each v index of sel in one segment: q_ref - q, the angle from q to q_ref,
  /// log3(conj(q) q_ref), log6 of a free-flyer pair or SE(2)'s log of a planar pair), a
  /// SupportPolygon's frame slots, a RELATIVE_FRAME's reference frame slot, a
  /// JOINT_COUPLING's q indices then v indices, an LM_DAMPING's owner kernel. Returns the
  /// kernel's index (the setters' k); it runs once its gain, weights, target and outputs are
  /// set.
  int add_task(int kind, int frame, std::vector<int> sel, int row0, std::vector<int> qidx) {
    if (!known_kind(kind)) throw nb::value_error("add_task: unknown kind");
    if (kind == kLMDamping) return add_damping(static_cast<Kind>(kind), sel, row0, qidx);
    const bool band = is_band(static_cast<Kind>(kind));
    const bool ineq = is_inequality(static_cast<Kind>(kind));
    const bool com = kind == kCom || on_com(static_cast<Kind>(kind));
    const bool hold = kind == kDamping || kind == kLowAcceleration;
    const bool framed =
        kind != kPosture && kind != kJointCoupling && kind != kCollision && !hold && !com;
    if (framed && (frame < 0 || frame >= (int)frames_.size()))
      throw nb::value_error("add_task: unknown frame slot");
    if (com && !com_.p) throw nb::value_error("add_task: set_com first");
    if (!bound_) throw nb::value_error("add_task: bind first");
    const int rows = static_cast<int>(sel.size());
    if (rows < 1 || row0 < 0 || row0 + rows > static_cast<int>(out_[ineq ? 2 : 0].shape(0)))
      throw nb::value_error("add_task: rows out of range");
    const int sel_end = kind == kPosture || hold ? nv_
                        : on_com(static_cast<Kind>(kind)) || kind == kCollision ? rows
                                                                                : 6;
    for (int s : sel)
      if (s < 0 || s >= sel_end) throw nb::value_error("add_task: row selection out of range");
    if (kind == kPositionBand && rows > 3)
      throw nb::value_error("add_task: a PositionBand has at most 3 rows");
    if (band) {  // sel: the rows 0..rows-1 (a PositionBand: the axes); qidx: a
                 // SupportPolygon's frame slots
      if (kind == kComBand && rows != 3) throw nb::value_error("add_task: a ComBand has 3 rows");
      for (int f : qidx)
        if (f < 0 || f >= (int)frames_.size())
          throw nb::value_error("add_task: unknown frame slot");
      if (kind == kSupportPolygon && (qidx.empty() || rows % (int)qidx.size() != 0))
        throw nb::value_error("add_task: rows must be frames x contact points");
      bands_.emplace_back();
      bands_.back().frames = qidx;
      if (kind == kSupportPolygon) bands_.back().size(rows, nv_, rows / (int)qidx.size());
    }
    if (kind == kPosture) check_posture_plan(qidx, sel);
    if (kind == kRelativeFrame &&
        (qidx.size() != 1 || qidx[0] < 0 || qidx[0] >= (int)frames_.size() || qidx[0] == frame))
      throw nb::value_error("add_task: a RELATIVE_FRAME's qidx is its reference frame's slot");
    if (hold) {  // DAMPING: no qidx; LOW_ACCELERATION: the integration plan
      if (rows != nv_ || (kind == kDamping && !qidx.empty()))
        throw nb::value_error("add_task: a DAMPING kernel has nv rows and no qidx");
      for (int r = 0; r < rows; ++r)
        if (sel[r] != r) throw nb::value_error("add_task: row selection out of range");
      if (kind == kLowAcceleration) check_plan(qidx, "add_task");
    }
    if (kind == kJointCoupling) {  // qidx: the joints' q indices, then their v indices
      const size_t n = qidx.size() / 2;
      if (rows != 1 || n < 1 || qidx.size() != 2 * n)
        throw nb::value_error("add_task: a JOINT_COUPLING has one row, q and v indices");
      for (size_t i = 0; i < n; ++i)
        if (qidx[i] < 0 || qidx[i] >= nq_ || qidx[n + i] < 0 || qidx[n + i] >= nv_)
          throw nb::value_error("add_task: q index out of range");
    }
    Kernel k;
    k.kind = static_cast<Kind>(kind);
    k.frame = frame;
    k.rows = rows;
    k.sel = std::move(sel);
    k.row0 = row0;
    k.qidx = std::move(qidx);
    k.sw.setZero(rows);
    k.err.setZero(rows);
    k.target.setZero(kind == kPosture          ? nq_
                     : kind == kPosition       ? rows
                     : kind == kLowAcceleration ? nv_
                     : kind == kJointCoupling  ? static_cast<int>(k.qidx.size() / 2) + 1
                                               : 3);
    if (band) k.band = static_cast<int>(bands_.size()) - 1;
    if (kind != kPosture && !hold) writes_a_ = true;  // its matrix changes with q
    kernels_.push_back(std::move(k));
    return static_cast<int>(kernels_.size()) - 1;
  }

  /// An LM_DAMPING kernel (add_task's rows for it): nv rows sel = 0..nv-1 from row0, qidx
  /// = {the owner kernel's index} (added before it; not a damping kernel).
  int add_damping(Kind kind, const std::vector<int>& sel, int row0,
                  const std::vector<int>& qidx) {
    if (!bound_) throw nb::value_error("add_task: bind first");
    if (static_cast<int>(sel.size()) != nv_ || row0 < 0 ||
        row0 + nv_ > static_cast<int>(out_[0].shape(0)))
      throw nb::value_error("add_task: an LM_DAMPING kernel has nv rows within the equalities");
    for (int r = 0; r < nv_; ++r)
      if (sel[r] != r) throw nb::value_error("add_task: row selection out of range");
    if (qidx.size() != 1 || qidx[0] < 0 || qidx[0] >= static_cast<int>(kernels_.size()) ||
        kernels_[qidx[0]].kind == kLMDamping)
      throw nb::value_error("add_task: an LM_DAMPING kernel's qidx is its owner kernel");
    Kernel k;
    k.kind = kind;
    k.rows = nv_;
    k.sel = sel;
    k.row0 = row0;
    k.owner = qidx[0];
    k.sw.setZero(nv_);
    k.err.setZero(nv_);
    writes_a_ = true;
    kernels_.push_back(std::move(k));
    return static_cast<int>(kernels_.size()) - 1;
  }

  /// An LM_DAMPING kernel's lm_damping (dimensionless, >= 0) and the square of the error
  /// floor below which its rows are zero (LM_ERROR_FLOOR^2, task units^2).
  void set_lm_damping(int k, double lm, double floor_sq) {
    Kernel& K = kernel(k, "set_lm_damping");
    if (K.kind != kLMDamping) throw nb::value_error("set_lm_damping: not an LM_DAMPING kernel");
    if (!(std::isfinite(lm) && lm >= 0.0 && std::isfinite(floor_sq) && floor_sq >= 0.0))
      throw nb::value_error("set_lm_damping: lm_damping and the floor must be finite, >= 0");
    K.lm = lm;
    K.floor_sq = floor_sq;
    K.given |= 4;
  }

  /// Kernel k's gain K (1/s; finite).
  void set_gain(int k, double gain) {
    Kernel& K = kernel(k, "set_gain");
    if (!std::isfinite(gain)) throw nb::value_error("set_gain: the gain is not finite");
    K.gain = gain;
    K.given |= 1;
  }

  /// Kernel k's row weights, as sqrt(weight) (rows,): finite.
  void set_weights(int k, nb::handle sqrt_weight) {
    Kernel& K = kernel(k, "set_weights");
    read_values(sqrt_weight, K.rows, 0, K.sw.data(), "set_weights");
    K.given |= 2;
  }

  /// Kernel k's target and feed-forward (velocity None: none), by kind:
  /// POSITION y* (rows,) m and dy*/dt (rows,) m/s; FRAME_POSITION and COM the point (3,) m
  /// and its velocity (3,) m/s; POSE and POSE_SPLIT T* (4, 4) and the target's body twist
  /// (6,) m/s, rad/s; ORIENTATION R* (3, 3) and its angular velocity (3,) rad/s, target
  /// frame; POSTURE q_ref (nq,), no velocity; RELATIVE_FRAME T* (4, 4) of the frame in its
  /// reference; JOINT_COUPLING (ratios..., offset). Finite values; the caller has checked
  /// that a rotation is one (the task's set_target).
  void set_target(int k, nb::handle target, nb::handle velocity) {
    Kernel& K = kernel(k, "set_target");
    if (is_inequality(K.kind)) throw nb::value_error("set_target: a band kernel (set_faces)");
    int nvel = 3;
    switch (K.kind) {
      case kPose:
      case kPoseSplit:
      case kRelativeFrame: {
        double T[16];
        read_values(target, 4, 4, T, "set_target");
        Vec3 pt;
        for (int i = 0; i < 3; ++i) {
          pt[i] = T[4 * i + 3];
          for (int j = 0; j < 3; ++j) K.Rinv(j, i) = T[4 * i + j];
        }
        K.pinv.noalias() = -(K.Rinv * pt);
        nvel = 6;
        break;
      }
      case kOrientation: {
        double R[9];
        read_values(target, 3, 3, R, "set_target");
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) K.Rinv(j, i) = R[3 * i + j];
        break;
      }
      case kPosition:
        nvel = K.rows;
        [[fallthrough]];
      default:
        read_values(target, K.target.size(), 0, K.target.data(), "set_target");
    }
    if (velocity.is_none()) {
      K.has_vel = false;
    } else {
      if (K.kind == kPosture) throw nb::value_error("set_target: a posture has no velocity");
      read_values(velocity, nvel, 0, K.vel.data(), "set_target: velocity");
      K.has_vel = true;
    }
    K.given |= 4;
  }

  /// Kernel k has no usable target (the task's data could not be set): step() returns
  /// kTaskData + k until a target is set again.
  void forget_target(int k) { kernel(k, "forget_target").given &= ~4; }

  /// A COM_BAND (3,) or POSITION_BAND (rows,) kernel's faces lower, upper (m; NaN
  /// rejected, +-inf on its side).
  void set_faces(int k, nb::handle lower, nb::handle upper) {
    Kernel& K = kernel(k, "set_faces");
    if (K.kind != kComBand && K.kind != kPositionBand)
      throw nb::value_error("set_faces: not a band with faces");
    support::Band& b = bands_[K.band];
    read_values(lower, K.rows, 0, b.lo.data(), "set_faces: lower", true);
    read_values(upper, K.rows, 0, b.hi.data(), "set_faces: upper", true);
    K.given |= 4;
  }

  /// A SUPPORT_POLYGON kernel's contact points (points per frame, 3), frame coordinates
  /// (m), and margin (m).
  void set_contacts(int k, nb::handle points, double margin) {
    Kernel& K = kernel(k, "set_contacts");
    if (K.kind != kSupportPolygon) throw nb::value_error("set_contacts: not a support polygon");
    support::Band& b = bands_[K.band];
    if (!std::isfinite(margin)) throw nb::value_error("set_contacts: margin not finite");
    read_values(points, b.points.rows(), 3, b.points.data(), "set_contacts");
    b.margin = margin;
    K.given |= 4;
  }

  /// A DAMPING or LOW_ACCELERATION kernel's arrays: the task's own (nq,) float64 q_hold,
  /// into which each step copies q (NaN in its first entry: no step yet), and a
  /// LOW_ACCELERATION's (nv,) v_prev, which each step writes (velocity None for a DAMPING).
  /// Its only parameters: the kernel runs once these are bound.
  void bind_hold(int k, RowsArr hold, nb::handle velocity) {
    Kernel& K = kernel(k, "bind_hold");
    if (K.kind != kDamping && K.kind != kLowAcceleration)
      throw nb::value_error("bind_hold: not a DAMPING or LOW_ACCELERATION kernel");
    if (hold.ndim() != 1 || hold.shape(0) != static_cast<size_t>(nq_))
      throw nb::value_error("bind_hold: expected a (nq,) float64 array");
    if (velocity.is_none() != (K.kind == kDamping))
      throw nb::value_error("bind_hold: a LOW_ACCELERATION kernel's v_prev, only");
    if (!velocity.is_none()) {
      RowsArr v = nb::cast<RowsArr>(velocity, false);
      if (v.ndim() != 1 || v.shape(0) != static_cast<size_t>(nv_))
        throw nb::value_error("bind_hold: v_prev must be a (nv,) float64 array");
      K.vprev.set(std::move(v));
    }
    K.hold.set(std::move(hold));
    K.given |= 4;
  }

  /// A LOW_ACCELERATION kernel's previous velocity (nv,) for its next step only (its task's
  /// set_previous), instead of the one measured from the two last configurations.
  void set_previous(int k, nb::handle v) {
    Kernel& K = kernel(k, "set_previous");
    if (K.kind != kLowAcceleration)
      throw nb::value_error("set_previous: not a LOW_ACCELERATION kernel");
    read_values(v, nv_, 0, K.target.data(), "set_previous");
    K.has_vel = true;
  }

  /// The arrays an equality kernel writes its rows into (the task's own A (rows, nv) and b
  /// (rows,), unweighted: the stacked rows get sqrt(weight) x them).
  void bind_rows(int k, RowsArr A, RowsArr b) {
    Kernel& K = kernel(k, "bind_rows");
    if (is_inequality(K.kind))
      throw nb::value_error("bind_rows: a band kernel (bind_band_rows)");
    if (A.ndim() != 2 || A.shape(0) != (size_t)K.rows || A.shape(1) != (size_t)nv_ ||
        b.ndim() != 1 || b.shape(0) != (size_t)K.rows)
      throw nb::value_error("bind_rows: A must be (rows, nv), b (rows,)");
    K.A.set(std::move(A));
    K.b.set(std::move(b));
    K.given |= 8;
  }

  /// The arrays a band kernel writes its rows into (the task's own C (rows, nv), lower and
  /// upper (rows,)).
  void bind_band_rows(int k, RowsArr C, RowsArr lower, RowsArr upper) {
    Kernel& K = kernel(k, "bind_band_rows");
    if (!is_inequality(K.kind)) throw nb::value_error("bind_band_rows: not a band kernel");
    const size_t r = K.rows;
    if (C.ndim() != 2 || C.shape(0) != r || C.shape(1) != (size_t)nv_ || lower.ndim() != 1 ||
        lower.shape(0) != r || upper.ndim() != 1 || upper.shape(0) != r)
      throw nb::value_error("bind_band_rows: C must be (rows, nv), lower and upper (rows,)");
    K.A.set(std::move(C));
    K.lower.set(std::move(lower));
    K.upper.set(std::move(upper));
    K.given |= 8;
  }

  /// A COLLISION kernel's rows: `capsule`, a PyCapsule named QPCOORD_ROWS_KERNEL_CAPSULE
  /// (rows_kernel.h; qpcoord._collision's CollisionKernel.entry()) of the kernel's rows x nv
  /// rows, held until another is set. It stands for the kernel's target (set_target).
  void set_rows_kernel(int k, nb::handle capsule) {
    Kernel& K = kernel(k, "set_rows_kernel");
    if (K.kind != kCollision) throw nb::value_error("set_rows_kernel: not a COLLISION kernel");
    auto* e = static_cast<const qpcoord_rows_kernel*>(
        PyCapsule_GetPointer(capsule.ptr(), QPCOORD_ROWS_KERNEL_CAPSULE));
    if (!e) {
      PyErr_Clear();
      throw nb::value_error("set_rows_kernel: expected a capsule named "
                            QPCOORD_ROWS_KERNEL_CAPSULE);
    }
    if (e->rows != K.rows || e->cols != nv_ || !e->update || !e->C || !e->lower)
      throw nb::value_error("set_rows_kernel: the rows kernel's shape is not (rows, nv)");
    K.rows_capsule = nb::borrow(capsule);
    K.rows_kernel = e;
    K.given |= 4;
  }

  /// The hull edges of a SUPPORT_POLYGON kernel at the last step (its task's `edges`).
  int edges(int k) {
    Kernel& K = kernel(k, "edges");
    if (K.kind != kSupportPolygon) throw nb::value_error("edges: not a support polygon");
    return bands_[K.band].edges;
  }

  /// A JointLimits box over qi -> vi (both empty: all of q, q and v sharing one layout).
  /// Returns its index for set_joint_limits.
  int add_joint_limits(std::vector<int> qi, std::vector<int> vi) {
    Limit L;
    L.indexed = !qi.empty() || !vi.empty();
    if (qi.size() != vi.size()) throw nb::value_error("add_joint_limits: sizes do not match");
    if (!L.indexed && nq_ != nv_)
      throw nb::value_error("add_joint_limits: an unindexed box needs nq == nv");
    for (size_t i = 0; i < qi.size(); ++i)
      if (qi[i] < 0 || qi[i] >= nq_ || vi[i] < 0 || vi[i] >= nv_)
        throw nb::value_error("add_joint_limits: index out of range");
    const int n = L.indexed ? static_cast<int>(qi.size()) : nv_;
    L.lower.setZero(n);
    L.upper.setZero(n);
    L.band_rate.setZero(n);
    L.qi = std::move(qi);
    L.vi = std::move(vi);
    limits_.push_back(std::move(L));
    return static_cast<int>(limits_.size()) - 1;
  }

  /// JointLimits i's gain K (in (0, 1]), limits (rad, m; +-inf for no limit) and band rates
  /// (JointLimits.band_rate: the band is band_rate * dt; rad/s, m/s, inf for none) in the
  /// layout of add_joint_limits (the indexed entries, or all of q).
  void set_joint_limits(int i, double gain, nb::handle lower, nb::handle upper,
                        nb::handle band_rate) {
    Limit& L = limit(i, "set_joint_limits");
    if (L.velocity) throw nb::value_error("set_joint_limits: a velocity limit");
    if (!std::isfinite(gain)) throw nb::value_error("set_joint_limits: gain not finite");
    read_values(lower, L.lower.size(), 0, L.lower.data(), "set_joint_limits: lower", true);
    read_values(upper, L.upper.size(), 0, L.upper.data(), "set_joint_limits: upper", true);
    read_values(band_rate, L.band_rate.size(), 0, L.band_rate.data(),
                "set_joint_limits: band_rate", true);
    L.gain = gain;
    L.given = true;
  }

  /// A VelocityLimits box; returns its index for set_velocity_limits.
  int add_velocity_limits() {
    Limit L;
    L.velocity = true;
    L.upper.setZero(nv_);
    limits_.push_back(std::move(L));
    return static_cast<int>(limits_.size()) - 1;
  }

  /// An AccelerationLimits box: v_prev its own (nv,) float64 array of the previous step's
  /// velocity (read at every step: bound once, written in place by its record / reset),
  /// braking before the position limits of q indices qi -> v indices vi (both empty: no
  /// braking). Returns its index for set_acceleration_limits.
  int add_acceleration_limits(std::vector<int> qi, std::vector<int> vi, nb::handle v_prev) {
    Limit L;
    L.acceleration = true;
    L.indexed = true;
    if (qi.size() != vi.size())
      throw nb::value_error("add_acceleration_limits: sizes do not match");
    for (size_t i = 0; i < qi.size(); ++i)
      if (qi[i] < 0 || qi[i] >= nq_ || vi[i] < 0 || vi[i] >= nv_)
        throw nb::value_error("add_acceleration_limits: index out of range");
    if (!view_of(v_prev, L.v_prev, 1) || L.v_prev.rows != nv_)
      throw nb::value_error("add_acceleration_limits: v_prev must be a (nv,) float64 array");
    L.amax.setZero(nv_);
    L.lower.setZero(static_cast<Eigen::Index>(qi.size()));
    L.upper.setZero(static_cast<Eigen::Index>(qi.size()));
    L.qi = std::move(qi);
    L.vi = std::move(vi);
    limits_.push_back(std::move(L));
    return static_cast<int>(limits_.size()) - 1;
  }

  /// AccelerationLimits i's a_max (nv,) (rad/s^2, m/s^2; > 0, inf for none), and the gain K
  /// (in (0, 1]) and limits (rad, m; +-inf for none) of the position limits it brakes before
  /// (the entries of add_acceleration_limits).
  void set_acceleration_limits(int i, nb::handle amax, double gain, nb::handle lower,
                               nb::handle upper) {
    Limit& L = limit(i, "set_acceleration_limits");
    if (!L.acceleration)
      throw nb::value_error("set_acceleration_limits: not an acceleration limit");
    if (!(gain > 0.0 && gain <= 1.0))
      throw nb::value_error("set_acceleration_limits: gain not in (0, 1]");
    read_values(amax, nv_, 0, L.amax.data(), "set_acceleration_limits: limit", true);
    for (int j = 0; j < nv_; ++j)
      if (!(L.amax[j] > 0.0)) throw nb::value_error("set_acceleration_limits: limit not > 0");
    read_values(lower, L.lower.size(), 0, L.lower.data(), "set_acceleration_limits: lower",
                true);
    read_values(upper, L.upper.size(), 0, L.upper.data(), "set_acceleration_limits: upper",
                true);
    L.gain = gain;
    L.given = true;
  }

  /// Limit i has no usable data: step() returns kBadInput until it is set again.
  void forget_limit(int i) { limit(i, "forget_limit").given = false; }

  /// VelocityLimits i's limit (nv,) (rad/s, m/s; inf for no limit).
  void set_velocity_limits(int i, nb::handle limit_) {
    Limit& L = limit(i, "set_velocity_limits");
    if (!L.velocity) throw nb::value_error("set_velocity_limits: a joint limit");
    read_values(limit_, nv_, 0, L.upper.data(), "set_velocity_limits", true);
    L.given = true;
  }

  /// Limits: 0 none, 1 native (the added ones), 2 the box already in box_lo / box_hi.
  int limits_mode = 0;
  /// The kernel that returned kTaskData (its index), or -1.
  int failed = -1;
  /// The weighted QP's last step rebuilt its factor (set by step()).
  bool refactored = false;

  /// The plan of integrate::run (kind, idx_q, idx_v, size per segment, covering q) and the
  /// (nq,) array step(..., integrate=True) writes q_next = integrate(q, x dt) into.
  void set_integrator(std::vector<int> plan, OutArr q_next) {
    if (q_next.ndim() != 1 || q_next.shape(0) != static_cast<size_t>(nq_))
      throw nb::value_error("set_integrator: q_next must be (nq,)");
    check_plan(plan, "set_integrator");
    plan_ = std::move(plan);
    q_next_ = q_next;
    integrator_ = true;
  }

  /// Solve the weighted QP (weighted.hpp, method="weighted") instead of the strict hierarchy:
  /// regularization and weight_ratio as NativeWeighted's, active the (n + hard rows + soft
  /// inequality rows,) output of Weighted::solve. The hierarchy's stats stay untouched.
  void set_weighted(double regularization, double weight_ratio, OutArr active) {
    if (!bound_) throw nb::value_error("set_weighted: bind first");
    if (active.ndim() != 1) throw nb::value_error("set_weighted: active must be a vector");
    w_ = std::make_unique<Weighted>(nv_, meq_, min_, has_bounds_, regularization, weight_ratio);
    const int blocks = static_cast<int>(meq_.size());
    int rows = nv_ + (blocks ? meq_[0] + min_[0] : 0);
    for (int b = 1; b < blocks; ++b) rows += min_[b];
    if (active.shape(0) != static_cast<size_t>(rows))
      throw nb::value_error("set_weighted: active has the wrong size");
    active_ = active;
  }

  /// Is the weighted QP the step's solver (set_weighted)?
  bool weighted() const { return static_cast<bool>(w_); }

  /// refactor: for the weighted QP, a matrix the kernels do not write changed (the Python
  /// side's matrix_version check); a kernel that writes a task's A always refactors.
  /// q: a float64 (native byte order) vector of nq entries, read through the buffer protocol
  /// (a nanobind ndarray argument costs 0.2 us more per call: numpy's DLPack export); anything
  /// else returns kBadQ (the Python side checks q first and names it).
  int step(nb::handle q, bool warm, double time_left, bool integrate = false,
           bool refactor = true) {
    failed = -1;
    if (!bound_ || !J_.p) return kBadInput;
    const Buffer qb(q.ptr());
    if (!qb.ok || qb.b.ndim != 1 || qb.b.shape[0] != nq_) return kBadQ;
    const int64_t qs = qb.b.strides[0] / 8;
    const double* qp = static_cast<const double*>(qb.b.buf);
    double sum = 0.0;
    for (int i = 0; i < nq_; ++i) sum += qp[i * qs];
    if (!std::isfinite(sum)) return kBadQ;
    for (size_t u = 0; u + 1 < unit_.size(); u += 2) {
      double s2 = 0.0;
      for (int i = unit_[u]; i < unit_[u] + unit_[u + 1]; ++i) s2 += qp[i * qs] * qp[i * qs];
      if (std::abs(std::sqrt(s2) - 1.0) > 1e-6) return kBadQ;
    }
    for (Frame& f : frames_) {
      Mat3 Rj;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) Rj(i, j) = f.Rj(i, j);
      const Vec3 pj(f.pj[0], f.pj[1], f.pj[2]);
      f.R.noalias() = Rj * f.Rp;
      f.p.noalias() = Rj * f.pp;
      f.p += pj;
    }
    // the damping kernels after the others: they read their owner's error or rows
    for (const bool damping : {false, true}) {
      for (size_t i = 0; i < kernels_.size(); ++i) {
        if ((kernels_[i].kind == kLMDamping) != damping) continue;
        if (kernels_[i].given != Kernel::kReady || !run_kernel(kernels_[i], qp, qs)) {
          failed = static_cast<int>(i);
          return kTaskData + static_cast<int>(i);
        }
      }
    }
    double* lbs = out_[6].data();
    double* ubs = out_[7].data();
    double* blo = out_[8].data();
    double* bhi = out_[9].data();
    if (limits_mode == 1) {
      for (const Limit& L : limits_)
        if (!L.given) return kBadInput;  // the Python side sets every limit before a step
      box(qp, qs);
      for (int i = 0; i < nv_; ++i) {
        blo[i] = lbs[i] = lo_[i];
        bhi[i] = ubs[i] = hi_[i];
      }
    } else if (limits_mode == 2) {
      for (int i = 0; i < nv_; ++i) {
        lbs[i] = blo[i];
        ubs[i] = bhi[i];
      }
    }
    int code;
    if (w_) {
      const bool re = refactor || writes_a_;
      code = w_->solve(cmat(out_[0]), cvec(out_[1]), cmat(out_[2]), cvec(out_[3]),
                       cvec(out_[4]), cvec(out_[5]), cvec(out_[6]), cvec(out_[7]), warm,
                       time_left, re, mvec(out_[10]), mvec(out_[11]), mvec(out_[13]),
                       mvec(active_));
      refactored = re;
    } else {
      code = h_.solve(cmat(out_[0]), cvec(out_[1]), cmat(out_[2]), cvec(out_[3]),
                      cvec(out_[4]), cvec(out_[5]), cvec(out_[6]), cvec(out_[7]), warm,
                      time_left, mvec(out_[10]), mvec(out_[11]), mmat(out_[12]),
                      mvec(out_[13]));
    }
    if (integrate && code == 0) {
      if (!integrator_) return kBadInput;
      integrate::run(plan_.data(), static_cast<int>(plan_.size() / 4), qp, qs, out_[10].data(),
                     dt_, q_next_.data());
    }
    return code;
  }

  /// The x, res and q_next arrays whose copies solve_step returns (their bound copy
  /// methods: the arrays bound as x, res and set_integrator's q_next).
  void set_copies(nb::handle x, nb::handle res, nb::handle q_next) {
    copy_x_ = x.attr("copy");
    copy_res_ = res.attr("copy");
    copy_q_next_ = q_next.is_none() ? nb::object() : nb::object(q_next.attr("copy"));
  }

  /// step() and, on success, (x.copy(), res.copy(), info(kkt_tol), q_next.copy() or None) in
  /// one call (None: integrate was False); else step()'s status code (an int).
  nb::object solve_step(nb::handle q, bool warm, double time_left, bool integrate,
                        double kkt_tol) {
    if (!copy_x_.is_valid()) throw nb::value_error("solve_step: call set_copies first");
    if (w_) throw nb::value_error("solve_step: the strict hierarchy's step (not weighted)");
    const int code = step(q, warm, time_left, integrate, true);
    if (code) return nb::int_(code);
    nb::object x = nb::steal(PyObject_CallNoArgs(copy_x_.ptr()));
    if (!x.is_valid()) throw nb::python_error();
    nb::object r = nb::steal(PyObject_CallNoArgs(copy_res_.ptr()));
    if (!r.is_valid()) throw nb::python_error();
    nb::object qn = nb::none();
    if (integrate) {
      if (!copy_q_next_.is_valid()) throw nb::value_error("solve_step: no q_next bound");
      qn = nb::steal(PyObject_CallNoArgs(copy_q_next_.ptr()));
      if (!qn.is_valid()) throw nb::python_error();
    }
    return nb::make_tuple(x, r, info(kkt_tol), qn);
  }

  /// The Python objects held (the views of Pinocchio's data, the copy methods), for
  /// tp_traverse. (The tasks' output arrays are held as nanobind ndarrays: arrays, which
  /// refer to no task.)
  int traverse(visitproc visit, void* arg) const {
    auto view = [&](const View& v) { return v.keep.is_valid() ? visit(v.keep.ptr(), arg) : 0; };
    int rc = 0;
    for (const nb::object* o : {&copy_x_, &copy_res_, &copy_q_next_})
      if (o->is_valid() && (rc = visit(o->ptr(), arg))) return rc;
    for (const View* v : {&J_, &com_, &Jcom_})
      if ((rc = view(*v))) return rc;
    for (const Frame& f : frames_)
      if ((rc = view(f.Rj)) || (rc = view(f.pj))) return rc;
    for (const Kernel& k : kernels_)
      if (k.rows_capsule.is_valid() && (rc = visit(k.rows_capsule.ptr(), arg))) return rc;
    for (const Limit& L : limits_)
      if ((rc = view(L.v_prev))) return rc;
    return 0;
  }

  /// tp_clear: drop every Python object held; the step is unbound (step() returns
  /// kBadInput) until compiled again.
  void clear() {
    bound_ = false;
    copy_x_.reset();
    copy_res_.reset();
    copy_q_next_.reset();
    J_ = View();
    com_ = View();
    Jcom_ = View();
    frames_.clear();
    kernels_.clear();
    limits_.clear();
    bands_.clear();
  }

  /// The solve's statistics as a dict (info_dict.hpp: the rule of the Hierarchy binding's
  /// info, from the bound stats / detail).
  nb::dict info(double kkt_tol) const {
    const OutArr& st = out_[12];
    return info_keys_.make(st.data(), static_cast<int>(st.shape(0)), out_[13].data(), kkt_tol,
                           h_.stats());
  }

  /// The last strict-hierarchy solve's counters (a copy is the info's "stats").
  const Stats& counters() const { return h_.stats(); }

  /// The rows a kernel writes (for tests): its index in the order added.
  int num_tasks() const { return static_cast<int>(kernels_.size()); }

 private:
  static CMap cmat(const OutArr& m) {
    const auto r = static_cast<Eigen::Index>(m.shape(0)), c = static_cast<Eigen::Index>(m.shape(1));
    return CMap(m.data(), r, c, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, c));
  }
  static MMap mmat(OutArr& m) {
    const auto r = static_cast<Eigen::Index>(m.shape(0)), c = static_cast<Eigen::Index>(m.shape(1));
    return MMap(m.data(), r, c, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, c));
  }
  static Eigen::Map<const Vec> cvec(const OutArr& v) {
    return Eigen::Map<const Vec>(v.data(), static_cast<Eigen::Index>(v.shape(0)));
  }
  static Eigen::Map<Vec> mvec(OutArr& v) {
    return Eigen::Map<Vec>(v.data(), static_cast<Eigen::Index>(v.shape(0)));
  }

  /// World-aligned linear (rows 0-2) and angular (rows 3-5) Jacobian of frame f at its origin
  /// into Jt_ (zero outside its columns): data.J's columns moved from the world origin to p.
  void frame_jacobian(const Frame& f) {
    Jt_.setZero();
    for (int c : f.cols) {
      const Vec3 w(J_(3, c), J_(4, c), J_(5, c));
      const Vec3 v(J_(0, c), J_(1, c), J_(2, c));
      Jt_.col(c).head<3>() = v + w.cross(f.p);
      Jt_.col(c).tail<3>() = w;
    }
  }

  /// Throws ValueError (naming who) unless plan is an integration plan covering q: (kind,
  /// idx_q, idx_v, size) per segment (integrate.hpp).
  /// A posture's plan: segments as check_plan's, disjoint in v, whose v indices are
  /// exactly the rows' (sel); it need not cover q (a floating root is not in a posture).
  void check_posture_plan(const std::vector<int>& plan, const std::vector<int>& sel) const {
    check_segments(plan, "add_task", integrate::kPlanar);
    std::vector<int> owner(nv_, 0);  // setup only: how many segments hold each v index
    for (size_t s = 0; s < plan.size(); s += 4)
      for (int i = 0; i < segment_nv(plan[s], plan[s + 3]); ++i) ++owner[plan[s + 2] + i];
    int held = 0;
    for (int c : owner) {
      if (c > 1) throw nb::value_error("add_task: a posture's segments overlap");
      held += c;
    }
    for (int j : sel)
      if (owner[j] != 1) throw nb::value_error("add_task: a posture row outside its plan");
    if (held != static_cast<int>(sel.size()))
      throw nb::value_error("add_task: a posture's plan covers joints it has no row of");
  }

  static int segment_nq(int kind, int n) {
    static constexpr int kNq[5] = {0, 2, 4, 7, 4};
    return kind == integrate::kVector ? n : kNq[kind];
  }
  static int segment_nv(int kind, int n) {
    static constexpr int kNv[5] = {0, 1, 3, 6, 3};
    return kind == integrate::kVector ? n : kNv[kind];
  }

  /// Each segment (kind, idx_q, idx_v, size) of a kind up to last (an integration plan: up
  /// to kFreeFlyer; a difference: kPlanar too) and inside q and v; returns the q they hold.
  int check_segments(const std::vector<int>& plan, const char* who, int last) const {
    const std::string w(who);
    if (plan.size() % 4 != 0) throw nb::value_error((w + ": 4 ints per segment").c_str());
    int covered = 0;
    for (size_t s = 0; s < plan.size(); s += 4) {
      const int kind = plan[s], iq = plan[s + 1], iv = plan[s + 2], n = plan[s + 3];
      if (kind < integrate::kVector || kind > last)
        throw nb::value_error((w + ": unknown segment kind").c_str());
      const int nq = segment_nq(kind, n), nv = segment_nv(kind, n);
      if ((kind != integrate::kVector && n != 1) || n < 1 || iq < 0 || iv < 0 ||
          iq + nq > nq_ || iv + nv > nv_)
        throw nb::value_error((w + ": segment out of range").c_str());
      covered += nq;
    }
    return covered;
  }

  void check_plan(const std::vector<int>& plan, const char* who) const {
    if (check_segments(plan, who, integrate::kFreeFlyer) != nq_)
      throw nb::value_error((std::string(who) + ": the plan does not cover q").c_str());
  }

  Kernel& kernel(int k, const char* who) {
    if (k < 0 || k >= static_cast<int>(kernels_.size()))
      throw nb::value_error((std::string(who) + ": no kernel " + std::to_string(k)).c_str());
    return kernels_[k];
  }

  Limit& limit(int i, const char* who) {
    if (i < 0 || i >= static_cast<int>(limits_.size()))
      throw nb::value_error((std::string(who) + ": no limit " + std::to_string(i)).c_str());
    return limits_[i];
  }

  /// The kernel's selected rows a = k.sel[r] of Jt_ with right-hand sides
  /// -gain * e[a] (+ ff[a] with a feed-forward velocity), written by write_row.
  template <class VE, class VF>
  void write_error_rows(Kernel& k, int rows, double gain, const VE& e, bool has_ff,
                        const VF& ff) {
    for (int r = 0; r < rows; ++r) {
      const int a = k.sel[r];
      double bv = -gain * e[a];
      if (has_ff) bv += ff[a];
      k.err[r] = e[a];
      write_row(k, r, Jt_.row(a), bv);
    }
  }

  /// Write row r of kernel k: its task's A row (pin coordinates in src, mapped here) and b
  /// value, and the stacked row (times sqrt(weight)). (A row of a column-major matrix: an
  /// inner stride, so that no copy is made.)
  void write_row(const Kernel& k, int r,
                 const Eigen::Ref<const Eigen::RowVectorXd, 0, Eigen::InnerStride<>>& src,
                 double bval) {
    double* Aeq = out_[0].data() + static_cast<size_t>(k.row0 + r) * nv_;
    double* beq = out_[1].data() + k.row0 + r;
    const double s = k.sw[r];
    if (mapped_) {
      row_.noalias() = M_.transpose() * src.transpose();
    } else {
      row_ = src.transpose();
    }
    for (int c = 0; c < nv_; ++c) {
      k.A(r, c) = row_[c];
      Aeq[c] = row_[c] * s;
    }
    k.b[r] = bval;
    *beq = bval * s;
  }

  /// Kernel k's rows at configuration q (stride qs) from its parameters: the one place a
  /// task kind is evaluated (ik_step/kernels.hxx). False: its data cannot be used.
  bool run_kernel(Kernel& k, const double* q, int64_t qs);

  /// A band kernel (ComBand, SupportPolygon: support_kernels.hpp; PositionBand): its
  /// Inequality's C, lower, upper and the stacked rows C, clo, chi, csw from row k.row0 (C
  /// unweighted, as stacked).
  bool run_band(const Kernel& k, support::Band& b);

  /// Row r of inequality kernel k: its Inequality's C row (pin coordinates in src, mapped
  /// here), lower l, upper u, and the stacked row k.row0 + r (C unweighted, as stacked; its
  /// sqrt(weight)). False: a NaN or an empty interval, or a non-finite row.
  template <class Src>
  bool put_row(const Kernel& k, int r, const Src& src, double l, double u);

  /// A COLLISION kernel: its producer's update (rows_kernel.h), then its rows copied into
  /// the Inequality's C, lower, upper and the stacked rows (put_row). False: the update
  /// failed or a row is not usable (the task's _refresh raises its message).
  bool run_rows(const Kernel& k);

  /// An LM_DAMPING kernel: sqrt(mu) I into its task's A (b = 0) and the stacked rows, mu
  /// from its owner kernel's error at this step (LMDamping._refresh).
  bool run_damping(Kernel& k);

  /// The nv rows d I (v coordinates: no coordinate map) and right-hand side b (nullptr: 0)
  /// of an nv-row kernel (the damping kinds) into its task's A, b and the stacked rows.
  void diagonal_rows(Kernel& k, double d, const double* b);

  /// The limits' boxes intersected into lo_, hi_ (IK.refresh's rule).
  void box(const double* q, int64_t qs);

  int nq_, nv_;
  double dt_;
  std::vector<int> unit_;  ///< (start, size) of each unit-norm block of q
  std::vector<int> meq_, min_;  ///< rows per block (hard, then the levels)
  bool has_bounds_;
  std::vector<int> plan_;  ///< integrate::run's segments
  OutArr q_next_;
  bool integrator_ = false;
  Hierarchy h_;
  std::unique_ptr<Weighted> w_;  ///< set_weighted: the weighted QP solves instead of h_
  /// a kernel rewrites its task's matrix at every step (all but a posture's): the weighted
  /// QP refactors at every step
  bool writes_a_ = false;
  OutArr active_;
  std::vector<OutArr> out_;
  bool bound_ = false;
  View J_, com_, Jcom_;
  Mat M_;
  bool mapped_ = false;
  std::vector<Frame> frames_;
  std::vector<Kernel> kernels_;
  std::vector<Limit> limits_;
  /// ComBand / SupportPolygon data (support_kernels.hpp)
  std::vector<support::Band> bands_;
  info::Keys info_keys_;  ///< info()'s keys (info_dict.hpp)
  Mat Jt_, Jl_;
  Vec row_, lo_, hi_, hi2_;
  Vec hold_;  ///< (nq,) integrate::difference's contiguous q0: a q_hold, or q (a posture)
  nb::object copy_x_, copy_res_, copy_q_next_;  ///< set_copies: the outputs' copy methods
};

/// Cyclic garbage collection of an IKStep: it holds Python objects (views of Pinocchio's
/// data, bound copy methods of its output arrays).
int ik_step_traverse(PyObject* self, visitproc visit, void* arg) {
  Py_VISIT(Py_TYPE(self));
  if (!nb::inst_ready(self)) return 0;
  return nb::inst_ptr<IKStep>(self)->traverse(visit, arg);
}

int ik_step_clear(PyObject* self) {
  if (nb::inst_ready(self)) nb::inst_ptr<IKStep>(self)->clear();
  return 0;
}

}  // namespace
}  // namespace qpcoord

#include "ik_step/kernels.hxx"

namespace qpcoord {
namespace {

PyType_Slot ik_step_slots[] = {{Py_tp_traverse, reinterpret_cast<void*>(ik_step_traverse)},
                               {Py_tp_clear, reinterpret_cast<void*>(ik_step_clear)},
                               {0, nullptr}};

}  // namespace

void bind_ik_step(nb::module_& m) {
  // the task kinds (qpcoord.kinematics.native_step.TaskKind names them alike)
  nb::enum_<Kind>(m, "IKTaskKind", nb::is_arithmetic(), "The native IK step's task kernels.")
      .value("POSITION", kPosition)
      .value("FRAME_POSITION", kFramePosition)
      .value("POSE", kPose)
      .value("ORIENTATION", kOrientation)
      .value("COM", kCom)
      .value("POSTURE", kPosture)
      .value("POSE_SPLIT", kPoseSplit)
      .value("COM_BAND", kComBand)
      .value("SUPPORT_POLYGON", kSupportPolygon)
      .value("POSITION_BAND", kPositionBand)
      // the damping kernels
      .value("LM_DAMPING", kLMDamping)
      .value("RELATIVE_FRAME", kRelativeFrame)
      .value("JOINT_COUPLING", kJointCoupling)
      .value("DAMPING", kDamping)
      .value("LOW_ACCELERATION", kLowAcceleration)

      .value("COLLISION", kCollision);
  nb::class_<IKStep>(m, "IKStep",
                     "One differential-IK step in one call: task rows, limit box and strict "
                     "hierarchy (qpcoord.kinematics.native_step builds it).",
                     nb::type_slots(ik_step_slots))
      .def(nb::init<int, int, std::vector<int>, std::vector<int>, bool, double, double,
                    std::vector<int>>(),
           nb::arg("nq"), nb::arg("nv"), nb::arg("meq"), nb::arg("min"), nb::arg("has_bounds"),
           nb::arg("damping"), nb::arg("dt"), nb::arg("unit_blocks"))
      .def("bind", &IKStep::bind)
      .def("set_jacobian", &IKStep::set_jacobian)
      .def("set_com", &IKStep::set_com)
      .def("set_coordinate_map", &IKStep::set_coordinate_map)
      .def("add_frame", &IKStep::add_frame)
      .def("add_task", &IKStep::add_task, nb::arg("kind"), nb::arg("frame"), nb::arg("sel"),
           nb::arg("row0"), nb::arg("qidx"),
           "A kernel of kind (IKTaskKind) on frame slot frame (-1: none), rows sel from row0 "
           "of the stacked rows; qidx: a posture's difference plan (kind, idx_q, idx_v, size "
           "per segment), a support polygon's frame "
           "slots, a relative frame's reference slot, a joint coupling's q then v indices, "
           "an LM_DAMPING's owner kernel. Returns its index k; it runs once set_gain, "
           "set_weights, its target (set_target / set_faces / set_contacts / set_lm_damping) "
           "and its outputs (bind_rows / bind_band_rows) are set.")
      .def("set_gain", &IKStep::set_gain, nb::arg("k"), nb::arg("gain"),
           "Kernel k's gain K (1/s), finite.")
      .def("set_weights", &IKStep::set_weights, nb::arg("k"), nb::arg("sqrt_weight"),
           "Kernel k's sqrt(row weights), a float64 (rows,) array, finite.")
      .def("set_target", &IKStep::set_target, nb::arg("k"), nb::arg("target"),
           nb::arg("velocity").none(),
           "Kernel k's target and feed-forward (None: none), float64 arrays: POSITION y* "
           "(rows,) and dy*/dt (rows,); FRAME_POSITION, COM (3,) and (3,); POSE, POSE_SPLIT "
           "T* (4, 4) and the target's body twist (6,); ORIENTATION R* (3, 3) and (3,); "
           "POSTURE q_ref (nq,); RELATIVE_FRAME T* (4, 4), no velocity; JOINT_COUPLING "
           "(ratios..., offset), no velocity. Finite values.")
      .def("set_faces", &IKStep::set_faces, nb::arg("k"), nb::arg("lower"), nb::arg("upper"),
           "A COM_BAND (3,) or POSITION_BAND (rows,) kernel's faces (m; -inf / inf on its "
           "side).")
      .def("set_contacts", &IKStep::set_contacts, nb::arg("k"), nb::arg("points"),
           nb::arg("margin"),
           "A SUPPORT_POLYGON kernel's contact points (per frame, 3) in frame coordinates "
           "(m) and margin (m).")
      .def("set_lm_damping", &IKStep::set_lm_damping, nb::arg("k"), nb::arg("lm_damping"),
           nb::arg("floor_sq"),
           "An LM_DAMPING kernel's lm_damping (dimensionless) and squared error floor "
           "(task units^2): its rows sqrt(mu) I, mu = lm_damping * sum(w e^2) of its owner "
           "kernel (0 when mu <= lm_damping * floor_sq).")
      .def("bind_hold", &IKStep::bind_hold, nb::arg("k"), nb::arg("hold").noconvert(),
           nb::arg("velocity").none(),
           "A DAMPING or LOW_ACCELERATION kernel's (nq,) float64 array that each step copies "
           "q into (its task's q_hold; NaN first: no step yet) and a LOW_ACCELERATION's (nv,) "
           "v_prev that each step writes (None for a DAMPING).")
      .def("set_previous", &IKStep::set_previous, nb::arg("k"), nb::arg("v"),
           "A LOW_ACCELERATION kernel's previous velocity (nv,) for its next step only.")
      .def("bind_rows", &IKStep::bind_rows, nb::arg("k"), nb::arg("A").noconvert(),
           nb::arg("b").noconvert(),
           "The writable float64 arrays (rows, nv) and (rows,) an equality kernel writes its "
           "unweighted rows into (bound until bound again).")
      .def("bind_band_rows", &IKStep::bind_band_rows, nb::arg("k"), nb::arg("C").noconvert(),
           nb::arg("lower").noconvert(), nb::arg("upper").noconvert(),
           "The writable float64 arrays (rows, nv), (rows,), (rows,) a band kernel writes "
           "its rows into.")
      .def("forget_target", &IKStep::forget_target, nb::arg("k"),
           "Kernel k has no usable target: step() returns IK_TASK_DATA + k until one is set.")
      .def("forget_limit", &IKStep::forget_limit, nb::arg("i"),
           "Limit i has no usable data: step() returns BAD_INPUT until it is set again.")
      .def("set_rows_kernel", &IKStep::set_rows_kernel, nb::arg("k"), nb::arg("capsule"),
           "A COLLISION kernel's rows: a capsule of src/native/rows_kernel.h "
           "(qpcoord._collision's CollisionKernel.entry()), called at every step.")
      .def("edges", &IKStep::edges, nb::arg("k"),
           "A SUPPORT_POLYGON kernel's hull edges at the last step.")
      .def("add_joint_limits", &IKStep::add_joint_limits, nb::arg("qi"), nb::arg("vi"),
           "A JointLimits box over the q indices qi -> v indices vi (both empty: all of q); "
           "its index for set_joint_limits.")
      .def("set_joint_limits", &IKStep::set_joint_limits, nb::arg("i"), nb::arg("gain"),
           nb::arg("lower"), nb::arg("upper"), nb::arg("band_rate"),
           "JointLimits i's gain, limits and band rates (float64, the layout of "
           "add_joint_limits).")
      .def("add_velocity_limits", &IKStep::add_velocity_limits,
           "A VelocityLimits box; its index for set_velocity_limits.")
      .def("set_velocity_limits", &IKStep::set_velocity_limits, nb::arg("i"), nb::arg("limit"),
           "VelocityLimits i's limit (nv,) float64.")
      .def("add_acceleration_limits", &IKStep::add_acceleration_limits, nb::arg("qi"),
           nb::arg("vi"), nb::arg("v_prev"),
           "An AccelerationLimits box reading v_prev (its (nv,) float64 array, bound), "
           "braking before the position limits of q indices qi -> v indices vi (empty: "
           "none); its index for set_acceleration_limits.")
      .def("set_acceleration_limits", &IKStep::set_acceleration_limits, nb::arg("i"),
           nb::arg("limit"), nb::arg("gain"), nb::arg("lower"), nb::arg("upper"),
           "AccelerationLimits i's a_max (nv,) and its braked position limits' gain and "
           "limits (float64, the entries of add_acceleration_limits).")
      .def("set_integrator", &IKStep::set_integrator, nb::arg("plan"), nb::arg("q_next"))
      .def("set_weighted", &IKStep::set_weighted, nb::arg("regularization"),
           nb::arg("weight_ratio"), nb::arg("active"))
      .def("step", &IKStep::step, nb::arg("q"), nb::arg("warm"), nb::arg("time_left"), nb::arg("integrate") = false,
           nb::arg("refactor") = true)
      .def("info", &IKStep::info, nb::arg("kkt_tol"))
      .def_prop_ro(
          "stats", [](const IKStep& s) { return s.counters(); },
          "A copy of the last strict-hierarchy solve's Stats (the counters of its paths).")
      .def("set_copies", &IKStep::set_copies, nb::arg("x"), nb::arg("res"),
           nb::arg("q_next").none(),
           "The bound x, res and q_next (None: no integrator) whose copies solve_step "
           "returns.")
      .def("solve_step", &IKStep::solve_step, nb::arg("q"), nb::arg("warm"),
           nb::arg("time_left"),
           nb::arg("integrate"), nb::arg("kkt_tol"),
           "step() (strict hierarchy) and on success (x.copy(), res.copy(), info(kkt_tol), "
           "q_next.copy() or None) in one call; else the status code.")
      .def_rw("limits_mode", &IKStep::limits_mode)
      .def_ro("failed", &IKStep::failed)
      .def_ro("refactored", &IKStep::refactored)
      .def_prop_ro("weighted", &IKStep::weighted)
      .def_prop_ro("num_tasks", &IKStep::num_tasks);
  m.attr("IK_BAD_Q") = kBadQ;
  m.attr("IK_TASK_DATA") = kTaskData;
  m.def(
      "integrate_configuration",
      [](std::vector<int> plan, nb::ndarray<const double, nb::ndim<1>, nb::device::cpu> q,
         nb::DRef<const Vec> v, double dt, OutArr out) {
        if (plan.size() % 4 != 0 || out.ndim() != 1 || out.shape(0) != q.shape(0))
          throw nb::value_error("integrate_configuration: bad plan or sizes");
        for (size_t s = 0; s < plan.size(); s += 4) {
          static constexpr int kNq[4] = {0, 2, 4, 7}, kNv[4] = {0, 1, 3, 6};
          const int kind = plan[s];
          if (kind < 0 || kind > 3) throw nb::value_error("integrate_configuration: bad kind");
          const int nq = kind == 0 ? plan[s + 3] : kNq[kind];
          const int nv = kind == 0 ? plan[s + 3] : kNv[kind];
          if (plan[s + 1] < 0 || plan[s + 2] < 0 || plan[s + 1] + nq > (int)q.shape(0) ||
              plan[s + 2] + nv > v.size())
            throw nb::value_error("integrate_configuration: segment out of range");
        }
        integrate::run(plan.data(), static_cast<int>(plan.size() / 4), q.data(), q.stride(0),
                       v.data(), dt, out.data());
      },
      nb::arg("plan"), nb::arg("q"), nb::arg("v"), nb::arg("dt"), nb::arg("out"),
      "out = integrate(q, v dt) over a plan of qpcoord.kinematics.native_step.integration_plan "
      "(for tests).");
  m.def("spatial_log3", [](const Mat3& R) {
    double th;
    return Vec3(spatial::log3(R, th));
  });
  m.def("spatial_jlog3", [](const Mat3& R) {
    double th;
    const Vec3 r = spatial::log3(R, th);
    return Mat3(spatial::jlog3(th, r));
  });
  m.def(
      "spatial_rigid_ok",
      [](nb::ndarray<const double, nb::ndim<2>, nb::device::cpu> T, double tol) {
        if (T.shape(0) != 4 || T.shape(1) != 4) return false;
        return spatial::rigid_ok(T.data(), T.stride(0), T.stride(1), tol);
      },
      nb::arg("T"), nb::arg("tol"),
      "The rigid-transform checks of FrameTask.set_target's fast path on a float64 4x4 "
      "(qpcoord.kinematics.frame_tasks._rigid_fast).");
  m.def(
      "spatial_rigid_copy",
      [](nb::handle T, double tol, nb::handle out) {
        constexpr int kOutFlags = PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE | PyBUF_FORMAT;
        // the buffer protocol, no nanobind ndarray (DLPack) conversion: 0.12 us per call
        // against 0.48 us with two ndarray arguments (timeit)
        Py_buffer o;
        bool o_ok = PyObject_GetBuffer(out.ptr(), &o, kOutFlags) == 0;
        double* dst = nullptr;
        if (o_ok) {
          o_ok = o.ndim == 2 && o.shape[0] == 4 && o.shape[1] == 4 && o.itemsize == 8 &&
                 o.format && std::strcmp(o.format, "d") == 0;
          dst = static_cast<double*>(o.buf);
          PyBuffer_Release(&o);  // out is kept alive by the caller
        } else {
          PyErr_Clear();
        }
        if (!o_ok) throw nb::type_error("spatial_rigid_copy: out must be a C-contiguous 4x4 "
                                        "float64 array, writable");
        const Buffer in(T.ptr());  // not a float64 4x4: False (the caller's full path)
        if (!in.ok || in.b.ndim != 2 || in.b.shape[0] != 4 || in.b.shape[1] != 4) return false;
        const auto* src = static_cast<const double*>(in.b.buf);
        const int64_t s0 = in.b.strides[0] / 8, s1 = in.b.strides[1] / 8;
        const bool ok = spatial::rigid_ok(src, s0, s1, tol);
        if (ok)
          for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) dst[4 * i + j] = src[i * s0 + j * s1];
        return ok;
      },
      nb::arg("T"), nb::arg("tol"), nb::arg("out"),
      "spatial_rigid_ok(T, tol) on a float64 (native byte order) 4x4 buffer and, when it "
      "holds, T copied into out (a C-contiguous 4x4 float64; untouched otherwise); False for "
      "anything else. FrameTask.set_target's fast path in one call.");
  m.def(
      "spatial_finite_copy",
      [](nb::handle v, nb::handle out) {
        constexpr int kOutFlags = PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE | PyBUF_FORMAT;
        // the buffer protocol, as spatial_rigid_copy (no DLPack conversion)
        Py_buffer o;
        bool o_ok = PyObject_GetBuffer(out.ptr(), &o, kOutFlags) == 0;
        double* dst = nullptr;
        Py_ssize_t n = 0;
        if (o_ok) {
          o_ok = o.ndim == 1 && o.itemsize == 8 && o.format && std::strcmp(o.format, "d") == 0;
          dst = static_cast<double*>(o.buf);
          n = o_ok ? o.shape[0] : 0;
          PyBuffer_Release(&o);  // out is kept alive by the caller
        } else {
          PyErr_Clear();
        }
        if (!o_ok) throw nb::type_error("spatial_finite_copy: out must be a C-contiguous float64 "
                                        "vector, writable");
        const Buffer in(v.ptr());  // not a float64 vector of out's size: False
        if (!in.ok || in.b.ndim != 1 || in.b.shape[0] != n) return false;
        const auto* src = static_cast<const double*>(in.b.buf);
        const int64_t s0 = in.b.strides[0] / 8;
        double sum = 0.0;  // NaN, inf or an overflow: not finite (the caller's full checks)
        for (Py_ssize_t i = 0; i < n; ++i) sum += src[i * s0];
        if (!std::isfinite(sum)) return false;
        for (Py_ssize_t i = 0; i < n; ++i) dst[i] = src[i * s0];
        return true;
      },
      nb::arg("v"), nb::arg("out"),
      "Copy v into out (a C-contiguous float64 vector) when v is a float64 (native byte "
      "order) vector of out's length whose entries sum to a finite number; False (out "
      "untouched) for anything else. frame_tasks._vector's fast path in one call.");
  m.def("spatial_log6", [](const Mat3& R, const Vec3& p) { return Vec6(spatial::log6(R, p)); });
  m.def("spatial_jlog6", [](const Mat3& R, const Vec3& p) { return Mat6(spatial::jlog6(R, p)); });
}

}  // namespace qpcoord
