#pragma once
// Camera maths for the renderer, free of GL: look-at and perspective matrices (OpenGL conventions: right-handed
// eye space looking down -z, clip-space depth in [-1, 1]), projection of points to pixels, and the arthroscope's
// follow-the-tool update.
#include <Eigen/Core>

namespace octocut::engine {

/// A perspective camera. With `arthroscope` set, a light sits at the lens and `mask` blacks out everything outside
/// a centred circle of `mask_radius` (a fraction of half the image height), as an arthroscope's round view does.
struct Camera {
  Eigen::Vector3d position{0.0, -0.1, 0.05};  ///< eye position, m
  Eigen::Vector3d target{0.0, 0.0, 0.0};      ///< point looked at, m
  Eigen::Vector3d up{0.0, 0.0, 1.0};          ///< approximate up direction (not parallel to the view direction)
  double fov_deg = 60.0;                      ///< vertical field of view, degrees, in (0, 180)
  double near = 1e-3;                         ///< near clip distance, m, > 0
  double far = 10.0;                          ///< far clip distance, m, > near
  bool arthroscope = false;                   ///< light at the lens
  bool mask = false;                          ///< circular mask
  double mask_radius = 1.0;                   ///< mask radius / half the image height, (0, ...]
};

/// The view matrix that maps world to eye space: the eye at the origin looking down -z with `up` projected to +y.
/// Throws std::invalid_argument when eye == target or `up` is parallel to the view direction.
Eigen::Matrix4d look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up);

/// The OpenGL perspective projection (gluPerspective): vertical field of view in degrees, aspect = width / height,
/// near and far clip distances in metres. Throws std::invalid_argument on a non-positive or inverted range.
Eigen::Matrix4d perspective(double fov_deg, double aspect, double near, double far);

/// The camera's view matrix, look_at(position, target, up).
Eigen::Matrix4d view_matrix(const Camera& camera);

/// The camera's projection matrix for an image of width × height pixels.
Eigen::Matrix4d projection_matrix(const Camera& camera, int width, int height);

/// Where a world point lands in an image of width × height pixels: x to the right and y down from the top-left
/// corner of the image (pixel centres at +0.5), and z the window depth in [0, 1]. w <= 0 (behind the eye) gives
/// non-finite coordinates.
Eigen::Vector3d project_to_pixel(const Camera& camera, int width, int height, const Eigen::Vector3d& world);

/// Moves the camera rigidly with a tool: the target goes to `tool_tip` and the eye keeps its offset from the target,
/// so the view direction and distance stay fixed while the camera follows. `tool_tip` in m.
void follow_tool(Camera& camera, const Eigen::Vector3d& tool_tip);

}  // namespace octocut::engine
