// qpcoord native engine: SO(3) / SE(3) logarithms and their Jacobians (the IK step's pose
// and orientation errors), with the conventions of Pinocchio's log3, Jlog3, log6, Jlog6:
//   log3(R) = theta u (theta in [0, pi]); Jlog3 the inverse of SO(3)'s right Jacobian;
//   log6(M) = (V(theta)^-1 p, log3(R)) (linear part first); Jlog6 = [[Jlog3, B], [0, Jlog3]].
// Fixed-size Eigen types only: nothing here allocates.
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace qpcoord {
namespace spatial {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;
using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

/// Below this trace deficit (3 - tr < eps^(1/3), as Pinocchio) log3's angle comes from
/// sqrt(2 (1 - cos)) instead of acos.
inline double taylor_log() { return std::cbrt(std::numeric_limits<double>::epsilon()); }
/// Below this angle (rad) the coefficients of V^-1, Jlog3 and Jlog6 come from their series
/// (to theta^6): their closed forms cancel (1/theta^2 - ..., 1/theta^4 - ...) and lose
/// eps / theta^4 (Pinocchio switches at eps^(1/4) = 1.2e-4 and loses ~1e-7 near 1e-3 rad in
/// Jlog6); the series' first omitted term is below 1e-15 here.
inline constexpr double kSeries = 0.05;

/// (R - R^T) / 2 as a vector: sin(theta) u.
inline Vec3 unskew(const Mat3& R) {
  return Vec3(0.5 * (R(2, 1) - R(1, 2)), 0.5 * (R(0, 2) - R(2, 0)), 0.5 * (R(1, 0) - R(0, 1)));
}

inline void add_skew(const Vec3& v, Eigen::Ref<Mat3> M) {
  M(0, 1) -= v[2];
  M(0, 2) += v[1];
  M(1, 0) += v[2];
  M(1, 2) -= v[0];
  M(2, 0) -= v[1];
  M(2, 1) += v[0];
}

/// log3 of a rotation: theta u with theta in [0, pi]; theta returned too.
inline Vec3 log3(const Mat3& R, double& theta) {
  const double eps = std::numeric_limits<double>::epsilon();
  const double prec = taylor_log();
  const double tr = R.trace();
  const double c = 0.5 * (tr - 1.0);
  const Vec3 w = unskew(R);
  if (c >= -1.0 + prec) {
    double th;
    if (tr <= 3.0 - prec)
      th = std::acos(std::min(1.0, std::max(-1.0, c)));
    else
      th = std::sqrt(std::max(0.0, 2.0 * (1.0 - c)) + eps * eps);
    const double s2 = w.squaredNorm();
    const double k = th >= prec ? th / std::sin(th) : 1.0 + s2 / 6.0 + s2 * s2 * 3.0 / 40.0;
    theta = th;
    return k * w;
  }
  // near pi: the axis from the symmetric part, 2 R_ii - tr + 1 = 2 (1 - cos) u_i^2; the
  // largest such entry gives the best-conditioned component, the others and the sign
  // (that of sin(theta) u, i.e. of w) follow from the off-diagonal sums
  Vec3 val = 2.0 * R.diagonal().array() - tr + 1.0;
  int i0 = 0;
  if (val[1] > val[i0]) i0 = 1;
  if (val[2] > val[i0]) i0 = 2;
  const int i1 = (i0 + 1) % 3, i2 = (i0 + 2) % 3;
  const double s = std::sqrt(val[i0] + eps + eps * eps) * (R(i2, i1) >= R(i1, i2) ? 1.0 : -1.0);
  Vec3 axis;
  axis[i0] = 0.5 * s;
  axis[i1] = (R(i1, i0) + R(i0, i1)) / (2.0 * s);
  axis[i2] = (R(i2, i0) + R(i0, i2)) / (2.0 * s);
  const double cw = (R(i2, i1) - R(i1, i2)) / (2.0 * s);
  const double an = axis.norm();
  theta = 2.0 * std::atan2(an, cw);
  return (theta / an) * axis;
}

/// log3 of a unit quaternion (w, x, y, z): theta u with theta in [0, pi], as Pinocchio's
/// quaternion::log3 (the difference of two spherical joints' quaternions, conj(q0) q1): the
/// sign turned so that w >= 0, theta = 2 atan2(|xyz|, w), accurate at every angle (the
/// matrix log3 above loses ~eps / sin(theta) near pi); below |xyz|^2 = eps^(2/3) the series.
inline Vec3 log3(const Eigen::Quaterniond& quat, double& theta) {
  const double eps = std::numeric_limits<double>::epsilon();
  const double prec = taylor_log();
  const double n2 = quat.vec().squaredNorm();
  const double norm = std::sqrt(n2 + eps * eps);
  const double sign = quat.w() >= 0.0 ? 1.0 : -1.0;
  const double w = sign * quat.w();
  const double half = std::atan2(norm, w);  // theta / 2, in [0, pi/2]
  const double y_x = norm / w, y_x_sq = n2 / (w * w);
  theta = n2 < prec ? 2.0 * (1.0 - y_x_sq / 3.0) * y_x : 2.0 * half;
  const double th2_4 = theta * theta / 4.0;
  const double inv_sinc =
      n2 < prec ? 2.0 * (1.0 + th2_4 / 6.0 + 7.0 / 360.0 * th2_4 * th2_4)
                : theta / std::sin(half);
  return (inv_sinc * sign) * quat.vec();
}

/// Jlog3 at r = theta u: (theta sin / (2 (1 - cos))) I + r r^T (1/theta^2 - sin / (2 theta
/// (1 - cos))) + [r]x / 2.
inline Mat3 jlog3(double theta, const Vec3& r) {
  double alpha, diag;
  if (theta < kSeries) {
    const double t2 = theta * theta;
    alpha = 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 / 1209600.0));
    diag = 1.0 - t2 * (1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 / 30240.0));
  } else {
    const double st = std::sin(theta), ct = std::cos(theta);
    const double st_1mct = st / (1.0 - ct);
    alpha = 1.0 / (theta * theta) - st_1mct / (2.0 * theta);
    diag = 0.5 * theta * st_1mct;
  }
  Mat3 J = alpha * r * r.transpose();
  J.diagonal().array() += diag;
  add_skew(0.5 * r, J);
  return J;
}

/// log6 of (R, p): linear part V(theta)^-1 p, angular part log3(R).
inline Vec6 log6(const Mat3& R, const Vec3& p) {
  double theta;
  const Vec3 w = log3(R, theta);
  double alpha, beta;
  if (theta < kSeries) {
    const double t2 = theta * theta;
    alpha = 1.0 - t2 * (1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 / 30240.0));
    beta = 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 / 1209600.0));
  } else {
    const double st = std::sin(theta), ct = std::cos(theta);
    alpha = theta * st / (2.0 * (1.0 - ct));
    beta = 1.0 / (theta * theta) - st / (2.0 * theta * (1.0 - ct));
  }
  Vec6 out;
  out.head<3>() = alpha * p - 0.5 * w.cross(p) + (beta * w.dot(p)) * w;
  out.tail<3>() = w;
  return out;
}

/// log6 of (quat, p), a unit quaternion and a translation, as Pinocchio's quaternion log6 (the
/// difference of two free-flyer configurations): angular part log3(quat) above, linear part
/// p - w x p / 2 + beta w x (w x p) with beta = 1/theta^2 - cot(theta/2) / (2 theta) (its
/// series (1/3 - theta^2/180) / 4 at or below theta = eps^(1/4)).
inline Vec6 log6(const Eigen::Quaterniond& quat, const Vec3& p) {
  const double eps = std::numeric_limits<double>::epsilon();
  const double sign = quat.w() >= 0.0 ? 1.0 : -1.0;
  static const double series = std::pow(eps, 0.25);
  double theta;
  const Vec3 w = log3(quat, theta);
  const double t2 = w.squaredNorm();
  const double cot_half = sign * quat.w() / std::sqrt(quat.vec().squaredNorm() + eps * eps);
  const double beta = theta <= series
                          ? (1.0 / 3.0 - t2 / 4.0 / 45.0) / 4.0
                          : 1.0 / t2 - cot_half * 0.5 / theta;
  Vec6 out;
  out.head<3>() = p - 0.5 * w.cross(p) + beta * w.cross(w.cross(p));
  out.tail<3>() = w;
  return out;
}

/// Jlog6 of (R, p) (6 x 6, linear rows first).
inline Mat6 jlog6(const Mat3& R, const Vec3& p) {
  double t;
  const Vec3 w = log3(R, t);
  const Mat3 A = jlog3(t, w);
  const double t2 = t * t;
  double beta, beta_dot_over_theta;
  if (t < kSeries) {
    beta = 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 / 1209600.0));
    // beta'(t) / t
    beta_dot_over_theta = 1.0 / 360.0 + t2 * (1.0 / 7560.0 + t2 * (1.0 / 201600.0));
  } else {
    const double tinv = 1.0 / t, t2inv = tinv * tinv;
    const double st = std::sin(t), ct = std::cos(t);
    const double inv_2_2ct = 1.0 / (2.0 * (1.0 - ct));
    beta = t2inv - st * tinv * inv_2_2ct;
    beta_dot_over_theta = -2.0 * t2inv * t2inv + (1.0 + st * tinv) * t2inv * inv_2_2ct;
  }
  const double wTp = w.dot(p);
  const Vec3 v = (beta_dot_over_theta * wTp) * w - (t2 * beta_dot_over_theta + 2.0 * beta) * p;
  Mat3 C = v * w.transpose() + beta * w * p.transpose();
  C.diagonal().array() += wTp * beta;
  add_skew(0.5 * p, C);
  Mat6 J;
  J.topLeftCorner<3, 3>() = A;
  J.topRightCorner<3, 3>() = C * A;
  J.bottomLeftCorner<3, 3>().setZero();
  J.bottomRightCorner<3, 3>() = A;
  return J;
}

/// The checks of qpcoord.kinematics.frame_tasks' rigid-transform fast path on a 4x4 whose
/// entry (i, j) is p[i s0 + j s1], term by term as its scalar Python (same sums, same order):
/// the 16 entries' sum finite, the last row (0, 0, 0, 1) within tol, max |R^T R - I| <= tol
/// and |det R - 1| <= tol.
inline bool rigid_ok(const double* p, std::int64_t s0, std::int64_t s1, double tol) {
  auto at = [&](int i, int j) { return p[i * s0 + j * s1]; };
  double sum = 0.0;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) sum += at(i, j);
  if (!std::isfinite(sum)) return false;
  const double last = std::max(std::max(std::abs(at(3, 0)), std::abs(at(3, 1))),
                               std::max(std::abs(at(3, 2)), std::abs(at(3, 3) - 1.0)));
  if (last > tol) return false;
  const double a = at(0, 0), b = at(0, 1), c = at(0, 2), d = at(1, 0), e = at(1, 1),
               f = at(1, 2), g = at(2, 0), h = at(2, 1), i = at(2, 2);
  const double gram = std::max({std::abs(a * a + d * d + g * g - 1.0),
                                std::abs(b * b + e * e + h * h - 1.0),
                                std::abs(c * c + f * f + i * i - 1.0),
                                std::abs(a * b + d * e + g * h), std::abs(a * c + d * f + g * i),
                                std::abs(b * c + e * f + h * i)});
  const double det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
  return gram <= tol && std::abs(det - 1.0) <= tol;
}

}  // namespace spatial
}  // namespace qpcoord
