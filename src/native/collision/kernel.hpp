// qpcoord native collision rows: the per-step work of CollisionAvoidance (qpcoord/kinematics/
// collision.py) in one call -- broad phase, coal distances, witness points, Jacobian rows.
//
// The model (geometries, pairs, support columns) is given once, as data; the joints' world
// placements and the world joint Jacobian are read through views of the robot's
// pinocchio.Data bound at construction (their memory does not move while the Data lives).
// A step writes the rows of the pairs closer than the influence distance (and clears the
// rows flagged active by the last step, which may have been the Python rows):
//   C_k = n·(J(p2) − J(p1)),  lower_k = −ξ (d_k − d_s) / (d_i − d_s),
// with n the unit normal from the first body's witness point p1 to the second's p2 and J(p)
// the velocity Jacobian of a point p fixed to the body (world frame, only the columns of
// the joints that move it); every other row is zero with lower −inf. The Python _refresh is
// the oracle of every number here (tests/kinematics/test_collision_native.py).
//
// Two tests skip coal for a pair that cannot be inside d_i (its row is then the zero row
// anyway, its distance inf): the bounding spheres' gap, and the pair's last exact distance
// d0 minus how far each geometry can have moved since: a point of a geometry whose ball
// (centre c, radius r) went from (R0, c0) to (R1, c1) moved at most |c1 − c0| + ‖R1 − R0‖ r
// (‖·‖ Frobenius, above the spectral norm), so d ≥ d0 − δ1 − δ2. coal's d0 is GJK's, which
// stops within its tolerance of the true distance (two runs with other support hints differ
// by up to 3e-6 m on the Panda): the pair is skipped when d0 − kSkipMargin − δ1 − δ2 >= d_i.
#pragma once

#include <coal/collision_data.h>
#include <coal/distance.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

namespace qpcoord {
namespace collision {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

/// One collision geometry: its shape, where it hangs and its broad-phase sphere.
struct Geometry {
  std::shared_ptr<coal::CollisionGeometry> shape;
  int joint = 0;              ///< parent joint (0: the world)
  Mat3 R = Mat3::Identity();  ///< placement in the parent joint's frame
  Vec3 p = Vec3::Zero();
  Vec3 centre = Vec3::Zero();  ///< bounding-sphere centre, parent joint's frame (m)
  double radius = std::numeric_limits<double>::infinity();  ///< inf: always a candidate
  std::vector<char> moves;  ///< per velocity column: does that joint move this geometry
};

/// Influence and safety distances (m), the same meaning as CollisionAvoidance's.
struct Settings {
  double min_distance = 0.02;
  double influence_distance = 0.10;
};

/// Joint placements and Jacobian as views (column-major 3x3 rotation, 3-vector, 6 x nv).
struct RobotView {
  std::vector<const double*> rotation, translation;
  const double* J = nullptr;
  int nv = 0;
};

/// Where a step writes (row-major m x nv C; m bounds, distances and active flags).
struct Output {
  double* C = nullptr;
  double* lower = nullptr;
  double* distance = nullptr;
  std::uint8_t* active = nullptr;
};

class Kernel {
 public:
  Kernel(RobotView robot, Settings settings) : robot_(std::move(robot)), settings_(settings) {}

  int add_geometry(Geometry g) {
    geoms_.push_back(std::move(g));
    world_R_.emplace_back(Mat3::Identity());
    world_p_.emplace_back(Vec3::Zero());
    world_c_.emplace_back(Vec3::Zero());
    return static_cast<int>(geoms_.size()) - 1;
  }

  void add_pair(int a, int b) {
    pairs_.push_back({a, b});
    solvers_.emplace_back(new coal::ComputeDistance(geoms_[a].shape.get(), geoms_[b].shape.get()));
    last_.emplace_back();
  }

  Geometry& geometry(int g) { return geoms_[g]; }
  int pairs() const { return static_cast<int>(pairs_.size()); }
  int geometries() const { return static_cast<int>(geoms_.size()); }
  void bind(Output out) { out_ = out; }
  const Output& output() const { return out_; }

  /// xi_eff = min(xi, (d_i - d_s) / dt) (m/s): the gain used at control period dt (s), the
  /// largest for which one first-order step cannot cross d_s (CollisionAvoidance's
  /// effective_gain, the same operations).
  double effective_gain(double gain, double dt) const {
    return std::min(gain, (settings_.influence_distance - settings_.min_distance) / dt);
  }

  /// One step at gain xi (m/s, already the effective gain): the rows and distances of every
  /// pair into the bound output. Returns the number of rows written (pairs inside d_i).
  int update(double xi) {
    place();
    const double ds = settings_.min_distance, di = settings_.influence_distance;
    const double inf = std::numeric_limits<double>::infinity();
    const int nv = robot_.nv;
    const int m = pairs();
    int written = 0;
    for (int k = 0; k < m; ++k) {
      if (out_.active[k]) {  // the rows written by the last step (native or Python) only
        std::fill(out_.C + static_cast<std::ptrdiff_t>(k) * nv,
                  out_.C + static_cast<std::ptrdiff_t>(k + 1) * nv, 0.0);
        out_.active[k] = 0;
      }
      out_.lower[k] = -inf;
      out_.distance[k] = inf;
      const auto [a, b] = pairs_[k];
      const Geometry &ga = geoms_[a], &gb = geoms_[b];
      // broad phase: the bounding spheres' gap (an unbounded geometry is always a candidate)
      const double gap = (world_c_[a] - world_c_[b]).norm() - (ga.radius + gb.radius);
      if (!(gap < di)) continue;
      Last& last = last_[k];
      if (last.valid && last.d - kSkipMargin - moved(ga, a, last.R1, last.c1) -
                                moved(gb, b, last.R2, last.c2) >=
                            di)
        continue;
      coal::DistanceRequest request;
      coal::DistanceResult result;
      const coal::Transform3s ta(world_R_[a], world_p_[a]), tb(world_R_[b], world_p_[b]);
      const double d = (*solvers_[k])(ta, tb, request, result);
      out_.distance[k] = d;
      last = {std::isfinite(ga.radius) && std::isfinite(gb.radius) && std::isfinite(d), d,
              world_R_[a], world_R_[b], world_c_[a], world_c_[b]};
      if (!(d < di)) continue;
      const Vec3 p1 = result.nearest_points[0], p2 = result.nearest_points[1];
      Vec3 n = result.normal;
      if (!(std::abs(n.norm() - 1.0) < 1e-3)) {  // touching: no normal from coal
        n = p2 - p1;
        if (n.norm() < 1e-9) n = world_c_[b] - world_c_[a];
        n /= std::max(n.norm(), 1e-12);
      }
      row(k, n, p1, p2, ga, gb);
      out_.lower[k] = -xi * (d - ds) / (di - ds);
      out_.active[k] = 1;
      ++written;
    }
    return written;
  }

 private:
  /// A pair's last exact distance and its geometries' world rotations and ball centres then.
  struct Last {
    bool valid = false;  ///< an exact distance of two bounded geometries
    double d = 0.0;
    Mat3 R1 = Mat3::Identity(), R2 = Mat3::Identity();
    Vec3 c1 = Vec3::Zero(), c2 = Vec3::Zero();
  };
  /// m: what a pair's last distance must exceed its bound by to be skipped, above GJK's
  /// stopping error (the file's head)
  static constexpr double kSkipMargin = 1e-4;

  /// How far a point of geometry g can have moved since its ball was at (R0, c0) (m).
  double moved(const Geometry& G, int g, const Mat3& R0, const Vec3& c0) const {
    return (world_c_[g] - c0).norm() + (world_R_[g] - R0).norm() * G.radius;
  }

  /// World placement and bounding-sphere centre of every geometry.
  void place() {
    for (size_t g = 0; g < geoms_.size(); ++g) {
      const Geometry& G = geoms_[g];
      const Eigen::Map<const Mat3> Rj(robot_.rotation[G.joint]);
      const Eigen::Map<const Vec3> tj(robot_.translation[G.joint]);
      world_R_[g].noalias() = Rj * G.R;
      world_p_[g].noalias() = Rj * G.p;
      world_p_[g] += tj;
      world_c_[g].noalias() = Rj * G.centre;
      world_c_[g] += tj;
    }
  }

  /// C_k = n·J(p2)|moves(b) − n·J(p1)|moves(a); n·J(p) = n·J_lin + (p × n)·J_ang.
  void row(int k, const Vec3& n, const Vec3& p1, const Vec3& p2, const Geometry& ga,
           const Geometry& gb) {
    const int nv = robot_.nv;
    const Vec3 m1 = p1.cross(n), m2 = p2.cross(n);
    double* out = out_.C + static_cast<std::ptrdiff_t>(k) * nv;
    for (int c = 0; c < nv; ++c) {
      const double* Jc = robot_.J + 6 * static_cast<std::ptrdiff_t>(c);
      const double lin = n[0] * Jc[0] + n[1] * Jc[1] + n[2] * Jc[2];
      double v = 0.0;
      if (gb.moves[c]) v += lin + m2[0] * Jc[3] + m2[1] * Jc[4] + m2[2] * Jc[5];
      if (ga.moves[c]) v -= lin + m1[0] * Jc[3] + m1[1] * Jc[4] + m1[2] * Jc[5];
      out[c] = v;
    }
  }

  RobotView robot_;
  Settings settings_;
  Output out_;
  std::vector<Geometry> geoms_;
  std::vector<std::pair<int, int>> pairs_;
  std::vector<std::unique_ptr<coal::ComputeDistance>> solvers_;
  std::vector<Last> last_;  ///< per pair
  std::vector<Mat3> world_R_;
  std::vector<Vec3> world_p_, world_c_;
};

}  // namespace collision
}  // namespace qpcoord
