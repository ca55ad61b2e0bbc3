#pragma once
// Basic types shared by the simulation module. Positions are in metres, times in seconds (SPEC §1).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <cstdint>

namespace octocut::sim {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using VecX = Eigen::VectorXd;
using SpMat = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

/// An axis-aligned box, m. A face is a box with zero extent along one axis.
struct Box3 {
  Vec3 min = Vec3::Zero();  ///< lower corner, m
  Vec3 max = Vec3::Zero();  ///< upper corner, m
  [[nodiscard]] double volume() const {
    const Vec3 e = (max - min).cwiseMax(0.0);
    return e.x() * e.y() * e.z();
  }
  /// Volume of the intersection with another box, m^3.
  [[nodiscard]] double overlap_volume(const Box3& o) const {
    const Vec3 e = (max.cwiseMin(o.max) - min.cwiseMax(o.min)).cwiseMax(0.0);
    return e.x() * e.y() * e.z();
  }
  [[nodiscard]] bool contains(const Vec3& p, double eps = 0.0) const {
    return (p.array() >= min.array() - eps).all() && (p.array() <= max.array() + eps).all();
  }
};

}  // namespace octocut::sim
