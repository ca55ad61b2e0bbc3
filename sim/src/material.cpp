#include "octocut/sim/material.hpp"

#include <algorithm>

namespace octocut::sim {

namespace {
// True when `box` meets the face rectangle (zero extent along axis) in positive area.
bool box_meets_face(const Box3& box, const Box3& face, int axis) {
  const double c = face.min[axis];
  if (c < box.min[axis] || c > box.max[axis]) return false;
  for (int d = 0; d < 3; ++d) {
    if (d == axis) continue;
    if (std::min(box.max[d], face.max[d]) - std::max(box.min[d], face.min[d]) <= 0.0) return false;
  }
  return true;
}
}  // namespace

double BoxMaterial::occupancy(const Box3& box) const {
  const double v = box.volume();
  return v > 0.0 ? std::clamp(box.overlap_volume(m_box) / v, 0.0, 1.0) : 0.0;
}

bool BoxMaterial::face_connected(const Box3& face, int axis) const { return box_meets_face(m_box, face, axis); }

double BoxSetMaterial::occupancy(const Box3& box) const {
  const double v = box.volume();
  if (v <= 0.0) return 0.0;
  double sum = 0.0;
  for (const Box3& b : m_boxes) sum += box.overlap_volume(b);
  return std::clamp(sum / v, 0.0, 1.0);
}

bool BoxSetMaterial::face_connected(const Box3& face, int axis) const {
  return std::any_of(m_boxes.begin(), m_boxes.end(), [&](const Box3& b) { return box_meets_face(b, face, axis); });
}

Box3 BoxSetMaterial::bounds() const {
  if (m_boxes.empty()) return {};
  Box3 r = m_boxes.front();
  for (const Box3& b : m_boxes) {
    r.min = r.min.cwiseMin(b.min);
    r.max = r.max.cwiseMax(b.max);
  }
  return r;
}

}  // namespace octocut::sim
