// qpcoord native engine: q_next = integrate(q, v dt) on the configuration manifold, with the
// conventions of Pinocchio's integrate (qpcoord/kinematics/native_step.py compiles the plan):
//   vector space (revolute, prismatic, helical, translation joints): q + v dt;
//   continuous joint, (cos, sin) pair (SO(2)): rotated by the angle v dt, then Pinocchio's
//     first-order renormalisation (3 - |q|^2) / 2;
//   spherical joint, quaternion (x, y, z, w) (SO(3)): q * exp3(v dt) (exp3's quaternion has
//     w = cos(t/2), no sign rule, as Pinocchio), then the renormalisation;
//   free-flyer (SE(3)): (p, q) * exp6(v dt) with v = (linear, angular) in the base frame: the
//     translation p + R(q) V(w) u, the quaternion q * exp3(w), sign kept toward q, then the
//     renormalisation.
// Fixed-size Eigen types only: nothing here allocates.
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <cstdint>
#include <limits>

#include "spatial.hpp"

namespace qpcoord {
namespace integrate {

enum Segment : int {
  kVector = 0,      ///< n coordinates, q + v dt
  kCircle = 1,      ///< one (cos, sin) pair
  kSpherical = 2,   ///< one quaternion (x, y, z, w)
  kFreeFlyer = 3,   ///< translation (3) then quaternion (4); velocity (linear, angular)
  kPlanar = 4,      ///< (x, y, cos, sin); velocity (vx, vy, w): difference only (no run)
};

using Vec3 = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;

/// exp3(w) as a unit quaternion (series below the angle where sin(t/2)/t loses digits).
inline Quat exp3_quat(const Vec3& w) {
  const double t2 = w.squaredNorm();
  if (t2 < 1e-8) {  // t < 1e-4: the series' first omitted term ~ t^4/3840 < 1e-19
    const double c = 1.0 - t2 / 8.0 + t2 * t2 / 384.0;
    const double k = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0;
    return Quat(c, k * w[0], k * w[1], k * w[2]);
  }
  const double t = std::sqrt(t2);
  const double s = std::sin(0.5 * t), c = std::cos(0.5 * t);
  const double k = s / t;
  return Quat(c, k * w[0], k * w[1], k * w[2]);
}

/// Pinocchio's first-order renormalisation of a nearly unit vector.
template <typename V>
inline void first_order_normalize(V& x) {
  x *= (3.0 - x.squaredNorm()) / 2.0;
}

/// (1 - cos t) / t^2 and (t - sin t) / t^3 (series below 1e-2 rad).
inline void v_coefficients(double t2, double& a, double& b) {
  if (t2 < 1e-4) {
    a = 0.5 - t2 / 24.0 + t2 * t2 / 720.0 - t2 * t2 * t2 / 40320.0;
    b = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0 - t2 * t2 * t2 / 362880.0;
    return;
  }
  const double t = std::sqrt(t2);
  a = (1.0 - std::cos(t)) / t2;
  b = (t - std::sin(t)) / (t2 * t);
}

/// out = integrate(q, v dt) over the plan (kind, idx_q, idx_v, size) * count. q and out may
/// be the same memory. q is read with stride qs; v and out are contiguous.
inline void run(const int* plan, int count, const double* q, int64_t qs, const double* v,
                double dt, double* out) {
  for (int s = 0; s < count; ++s) {
    const int kind = plan[4 * s], iq = plan[4 * s + 1], iv = plan[4 * s + 2], n = plan[4 * s + 3];
    switch (kind) {
      case kVector:
        for (int i = 0; i < n; ++i) out[iq + i] = q[(iq + i) * qs] + v[iv + i] * dt;
        break;
      case kCircle: {
        const double c = q[iq * qs], sn = q[(iq + 1) * qs], w = v[iv] * dt;
        const double cw = std::cos(w), sw = std::sin(w);
        Eigen::Vector2d r(c * cw - sn * sw, sn * cw + c * sw);
        first_order_normalize(r);
        out[iq] = r[0];
        out[iq + 1] = r[1];
        break;
      }
      case kSpherical: {
        const Quat q0(q[(iq + 3) * qs], q[iq * qs], q[(iq + 1) * qs], q[(iq + 2) * qs]);
        Quat r = q0 * exp3_quat(Vec3(v[iv], v[iv + 1], v[iv + 2]) * dt);  // no sign rule
        first_order_normalize(r.coeffs());
        for (int i = 0; i < 4; ++i) out[iq + i] = r.coeffs()[i];
        break;
      }
      case kFreeFlyer: {
        const Vec3 p0(q[iq * qs], q[(iq + 1) * qs], q[(iq + 2) * qs]);
        const Quat q0(q[(iq + 6) * qs], q[(iq + 3) * qs], q[(iq + 4) * qs], q[(iq + 5) * qs]);
        const Vec3 u = Vec3(v[iv], v[iv + 1], v[iv + 2]) * dt;
        const Vec3 w = Vec3(v[iv + 3], v[iv + 4], v[iv + 5]) * dt;
        double a, b;
        v_coefficients(w.squaredNorm(), a, b);
        const Vec3 wxu = w.cross(u);
        const Vec3 tr = u + a * wxu + b * w.cross(wxu);  // V(w) u
        const Vec3 p = p0 + q0.toRotationMatrix() * tr;
        Quat r = q0 * exp3_quat(w);
        if (r.coeffs().dot(q0.coeffs()) < 0) r.coeffs() = -r.coeffs();
        first_order_normalize(r.coeffs());
        for (int i = 0; i < 3; ++i) out[iq + i] = p[i];
        for (int i = 0; i < 4; ++i) out[iq + 3 + i] = r.coeffs()[i];
        break;
      }
      default:
        break;
    }
  }
}

/// out = difference(q0, q1) / dt over the plan: the velocity v with integrate(q0, v dt) = q1,
/// with Pinocchio's conventions: q1 - q0 on a vector space; the angle of the (cos, sin) pair
/// q1 in the frame of q0 (atan2); log3(conj(q0) q1) of a quaternion pair (spatial.hpp);
/// log6(M0^-1 M1) of a free-flyer pair (linear, angular), both logs from quaternions; the
/// SE(2) log of a planar pair. q0 is contiguous, q1 read with
/// stride qs; out is written at the plan's v indices only (a plan may cover part of v).
inline void difference(const int* plan, int count, const double* q0, const double* q1,
                       int64_t qs, double dt, double* out) {
  for (int s = 0; s < count; ++s) {
    const int kind = plan[4 * s], iq = plan[4 * s + 1], iv = plan[4 * s + 2], n = plan[4 * s + 3];
    switch (kind) {
      case kVector:
        for (int i = 0; i < n; ++i) out[iv + i] = (q1[(iq + i) * qs] - q0[iq + i]) / dt;
        break;
      case kCircle: {
        const double ca = q0[iq], sa = q0[iq + 1], cb = q1[iq * qs], sb = q1[(iq + 1) * qs];
        out[iv] = std::atan2(ca * sb - sa * cb, ca * cb + sa * sb) / dt;
        break;
      }
      case kSpherical: {
        const Quat a(q0[iq + 3], q0[iq], q0[iq + 1], q0[iq + 2]);
        const Quat b(q1[(iq + 3) * qs], q1[iq * qs], q1[(iq + 1) * qs], q1[(iq + 2) * qs]);
        double theta;
        const Vec3 w = spatial::log3(Quat(a.conjugate() * b), theta);  // as Pinocchio's
        for (int i = 0; i < 3; ++i) out[iv + i] = w[i] / dt;
        break;
      }
      case kFreeFlyer: {
        const Vec3 pa(q0[iq], q0[iq + 1], q0[iq + 2]);
        const Vec3 pb(q1[iq * qs], q1[(iq + 1) * qs], q1[(iq + 2) * qs]);
        const Quat a(q0[iq + 6], q0[iq + 3], q0[iq + 4], q0[iq + 5]);
        const Quat b(q1[(iq + 6) * qs], q1[(iq + 3) * qs], q1[(iq + 4) * qs], q1[(iq + 5) * qs]);
        const auto d = spatial::log6(Quat(a.conjugate() * b), a.conjugate() * (pb - pa));
        for (int i = 0; i < 6; ++i) out[iv + i] = d[i] / dt;
        break;
      }
      case kPlanar: {  // Pinocchio's SE(2) log of (R0^T R1, R0^T (p1 - p0)); the angle by atan2
        const double c0 = q0[iq + 2], s0 = q0[iq + 3];
        const double c1 = q1[(iq + 2) * qs], s1 = q1[(iq + 3) * qs];
        const double dx = q1[iq * qs] - q0[iq], dy = q1[(iq + 1) * qs] - q0[iq + 1];
        const double px = c0 * dx + s0 * dy, py = c0 * dy - s0 * dx;
        const double t = std::atan2(c0 * s1 - s0 * c1, c0 * c1 + s0 * s1);
        const double ta = std::abs(t), t2 = t * t;
        const double alpha = ta < 1e-4 ? 1.0 - t2 / 12.0 - t2 * t2 / 720.0
                                       : ta * std::sin(ta) / (2.0 * (1.0 - std::cos(ta)));
        out[iv] = (alpha * px + t / 2.0 * py) / dt;
        out[iv + 1] = (alpha * py - t / 2.0 * px) / dt;
        out[iv + 2] = t / dt;
        break;
      }
      default:
        break;
    }
  }
}

}  // namespace integrate
}  // namespace qpcoord
