#pragma once
// The viewer's camera controls and the tool in the hand, free of GL and GLFW: orbit, pan, zoom and framing of a
// Camera; the pose of the held tool from the mouse (a ray through the pixel onto the tissue, or onto the view plane
// at the tool's depth), the depth offset and the roll.
#include <optional>
#include <string>

#include "octocut/engine/render/render_scene.hpp"
#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/pose.hpp"

namespace octocut::engine {

/// Rotates the eye about the target: `dx` pixels about the up axis, `dy` about the camera's right axis (0.005 rad
/// per pixel), never closer than 5 degrees to the up axis.
void orbit(Camera& camera, double dx, double dy);
/// Moves eye and target together in the view plane by `dx`, `dy` pixels of a window `height` pixels high (the
/// target moves as the point under the mouse would).
void pan(Camera& camera, double dx, double dy, int height);
/// Moves the eye toward the target: the distance is multiplied by 0.85^steps.
void zoom(Camera& camera, double steps);
/// Points the camera at the centre of the first tissue mesh of `scene` from a distance at which its bounding sphere
/// fills the vertical field of view; the view direction is kept.
void frame_object(Camera& camera, const RenderScene& scene);

/// The ray through pixel (x, y) of a window width × height pixels (x right, y down from the top left), from the eye:
/// origin (m) and unit direction.
struct Ray {
  Eigen::Vector3d origin, direction;
};
Ray pixel_ray(const Camera& camera, double x, double y, int width, int height);
/// The smallest ray parameter (m) at which `ray` meets a triangle of `mesh` (its model transform applied), if any.
std::optional<double> intersect(const Ray& ray, const RenderMesh& mesh);

/// The tool a person holds.
class HandTool {
 public:
  /// Tool `index` of `scene`; its rotation starts as at its first cut event on the timeline (or its first keyframe).
  HandTool(const Scene& scene, std::size_t index);
  [[nodiscard]] const std::string& name() const { return m_name; }
  /// Adds `depth_steps` steps along the view ray (+ deeper; a step is 1% of the eye-target distance, applied at the
  /// next follow) and `roll_steps` steps of 5 degrees about the tool's z axis.
  void adjust(double depth_steps, double roll_steps);
  /// The pose under the mouse at (x, y) of a window width × height: the tool's origin where the pixel's ray meets
  /// the tissue (the first tissue mesh of `frame`), moved by the depth offset along the ray; off the tissue, where
  /// the ray meets the view plane through the last position. Nullopt when the ray meets neither. A tool that
  /// collides meets the tissue only to be placed the first time; after that it moves in the view plane through its
  /// last position (and in depth by the offset): the tissue it pushed away must not pull it deeper at the next move
  /// (the deformed surface under the mouse is where the tool itself pushed it).
  std::optional<sim::Pose> follow(const Camera& camera, const RenderScene& frame, double x, double y, int width,
                                  int height);
  [[nodiscard]] const sim::Pose& pose() const { return m_pose; }
  /// True once follow() has placed the tool.
  [[nodiscard]] bool placed() const { return m_placed; }

 private:
  std::string m_name;
  sim::Mat3 m_base = sim::Mat3::Identity();  // the rotation before the roll
  double m_roll_deg = 0.0;     // about the tool's z axis, degrees
  double m_depth_steps = 0.0;  // along the view ray, steps
  sim::Pose m_pose;            // the last pose given
  bool m_placed = false;       // m_pose came from follow()
  bool m_collides = false;     // the tool takes part in contact: it snaps onto the tissue only when first placed
  double m_plane_depth = 0.0;  // depth steps already applied to m_pose (a colliding tool's view-plane motion)
};

}  // namespace octocut::engine
