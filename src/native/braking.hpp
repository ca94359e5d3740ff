// qpcoord native engine: the braking speed of a joint before a position limit, the native
// form of qpcoord/kinematics/braking.py's braking_speed (the same terms in the same order;
// see that module for the derivation).
#pragma once

#include <cmath>

namespace qpcoord {
namespace braking {

/// Largest speed (rad/s, m/s) toward a limit at distance D (rad, m; negative outside it,
/// inf for none) from which a joint decelerating by at most a (> 0, inf for none) still
/// stops before it, keeping the position-limit box v <= (K/dt) D of gain K in (0, 1] at
/// every step of period dt (s): min over integer j >= 0 of
/// f(j) = (A + B j + C j^2) / (1 + K j), at the integers beside f's real minimiser;
/// (K/dt) D outside the limit.
inline double speed(double D, double a, double dt, double K) {
  if (D < 0.0) return (K / dt) * D;
  const double s = a * dt;
  const double A = (K / dt) * D;
  const double B = s * (1.0 - 0.5 * K);
  const double C = 0.5 * K * s;
  // f is convex in j >= 0 (or increasing): its real minimiser solves
  // C K j^2 + 2 C j + (B - K A) = 0 (NaN or inf for a = inf or D = inf: j = 0)
  const double root = (std::sqrt(C * C - C * K * (B - K * A)) - C) / (C * K);
  const double j0 = std::floor(std::isfinite(root) && root > 0.0 ? root : 0.0);
  double best = A;
  for (const double j : {j0, j0 + 1.0}) {
    const double f = (A + B * j + C * j * j) / (1.0 + K * j);
    if (f < best) best = f;  // NaN (inf / inf): not a bound
  }
  return best;
}

}  // namespace braking
}  // namespace qpcoord
