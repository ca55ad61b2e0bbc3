// The viewer's controls without a window: the ray through a pixel against project_to_pixel (the renderer's own
// projection), ray-mesh intersection against a plane, the camera moves (orbit keeps the distance, pan the direction,
// zoom scales the distance), and the tool in the hand placed where the ray meets the tissue, moved in depth and
// rolled.
#include "view/view_controls.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "octocut/engine/render/camera.hpp"

namespace octocut::engine {
namespace {

constexpr int kW = 640, kH = 360;

Camera camera() {
  Camera c;
  c.position = {0.01, -0.05, 0.04};
  c.target = {0.0, 0.0, 0.0};
  c.up = {0.0, 0.0, 1.0};
  c.fov_deg = 50.0;
  return c;
}

// The square [-0.05, 0.05]^2 at height z as two triangles, tissue.
RenderMesh floor(float z) {
  RenderMesh m;
  m.positions = {{-0.05f, -0.05f, z}, {0.05f, -0.05f, z}, {0.05f, 0.05f, z}, {-0.05f, 0.05f, z}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

TEST(ViewControls, PixelRayProjectsBackToItsPixel) {
  const Camera c = camera();
  for (const auto& [x, y] : {std::pair{320.0, 180.0}, std::pair{10.5, 20.25}, std::pair{600.0, 350.0}}) {
    const Ray ray = pixel_ray(c, x, y, kW, kH);
    EXPECT_NEAR(ray.direction.norm(), 1.0, 1e-12);
    const Eigen::Vector3d p = project_to_pixel(c, kW, kH, ray.origin + 0.07 * ray.direction);
    EXPECT_NEAR(p.x(), x, 1e-6);
    EXPECT_NEAR(p.y(), y, 1e-6);
  }
  const Ray centre = pixel_ray(c, kW / 2.0, kH / 2.0, kW, kH);
  EXPECT_TRUE(centre.direction.isApprox((c.target - c.position).normalized(), 1e-12));
}

TEST(ViewControls, RayMeetsAPlaneWhereGeometrySaysAndMissesBesideIt) {
  const Ray down{{0.01, 0.02, 0.3}, {0.0, 0.0, -1.0}};
  const std::optional<double> hit = intersect(down, floor(0.1f));
  ASSERT_TRUE(hit.has_value());
  EXPECT_NEAR(*hit, 0.2, 1e-7);
  EXPECT_FALSE(intersect(Ray{{0.2, 0.0, 0.3}, {0.0, 0.0, -1.0}}, floor(0.1f)).has_value());
  EXPECT_FALSE(intersect(Ray{{0.0, 0.0, 0.3}, {0.0, 0.0, 1.0}}, floor(0.1f)).has_value());  // behind the origin
  // The mesh's model transform counts: lifted by 0.1 m, the plane is met 0.1 m earlier.
  RenderMesh lifted = floor(0.1f);
  lifted.model(2, 3) = 0.1f;
  EXPECT_NEAR(*intersect(down, lifted), 0.1, 1e-7);
}

TEST(ViewControls, OrbitPanAndZoomMoveTheCameraAsTheyShould) {
  Camera c = camera();
  const double distance = (c.position - c.target).norm();
  orbit(c, 120.0, -40.0);
  EXPECT_NEAR((c.position - c.target).norm(), distance, 1e-12);
  EXPECT_TRUE(c.target.isApprox(Eigen::Vector3d::Zero(), 0.0));
  // Orbiting far up stops short of the pole.
  for (int i = 0; i < 100; ++i) orbit(c, 0.0, 100.0);
  EXPECT_LT(std::abs((c.position - c.target).normalized().dot(c.up)), std::cos(4.9 * M_PI / 180.0));

  Camera p = camera();
  const Eigen::Vector3d direction = (p.target - p.position).normalized();
  pan(p, 30.0, -10.0, kH);
  EXPECT_TRUE((p.target - p.position).normalized().isApprox(direction, 1e-12));
  EXPECT_NEAR((p.position - p.target).norm(), distance, 1e-12);
  // The point under the mouse moves with it: what was at the centre is now 30 px right, 10 px up.
  const Eigen::Vector3d moved = project_to_pixel(p, kW, kH, camera().target);
  EXPECT_NEAR(moved.x(), kW / 2.0 + 30.0, 1e-6);
  EXPECT_NEAR(moved.y(), kH / 2.0 - 10.0, 1e-6);

  Camera z = camera();
  zoom(z, 2.0);
  EXPECT_NEAR((z.position - z.target).norm(), distance * 0.85 * 0.85, 1e-12);
}

TEST(ViewControls, FrameObjectFitsTheTissue) {
  Camera c = camera();
  RenderScene scene;
  scene.meshes.push_back(floor(0.02f));
  frame_object(c, scene);
  EXPECT_TRUE(c.target.isApprox(Eigen::Vector3d(0.0, 0.0, 0.02), 1e-7));
  // Every corner of the square is in the image.
  for (const auto& v : scene.meshes[0].positions) {
    const Eigen::Vector3d p = project_to_pixel(c, kW, kH, v.cast<double>());
    EXPECT_GT(p.x(), 0.0);
    EXPECT_LT(p.x(), kW);
    EXPECT_GT(p.y(), 0.0);
    EXPECT_LT(p.y(), kH);
  }
}

TEST(ViewControls, TheToolInTheHandGoesWhereTheMousePointsOnTheTissue) {
  Scene scene;
  ToolSettings tool;
  tool.name = "probe";
  tool.keyframes = {PoseKey{0.0, {0.0, 0.0, 0.0}, {0.0, 0.0, 90.0}}};
  scene.tools.push_back(tool);
  HandTool hand(scene, 0);
  EXPECT_EQ(hand.name(), "probe");
  EXPECT_FALSE(hand.placed());
  const Camera c = camera();
  RenderScene frame;
  frame.meshes.push_back(floor(0.0f));
  // The tissue point (0.004, -0.003, 0) on the screen: the tool's origin lands on it.
  const Eigen::Vector3d on = {0.004, -0.003, 0.0};
  const Eigen::Vector3d px = project_to_pixel(c, kW, kH, on);
  std::optional<sim::Pose> pose = hand.follow(c, frame, px.x(), px.y(), kW, kH);
  ASSERT_TRUE(pose.has_value());
  EXPECT_TRUE(pose->position.isApprox(on, 1e-6)) << pose->position.transpose();
  EXPECT_TRUE(pose->rotation.isApprox(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix(), 1e-12));
  // Two steps deeper along the view ray (a step is 1 % of the eye-target distance), then a roll of 5 degrees.
  hand.adjust(2.0, 1.0);
  pose = hand.follow(c, frame, px.x(), px.y(), kW, kH);
  const double step = 0.01 * (c.target - c.position).norm();
  const Eigen::Vector3d ray = (on - c.position).normalized();
  EXPECT_TRUE(pose->position.isApprox(on + 2.0 * step * ray, 1e-6));
  const Eigen::Matrix3d expected = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                   Eigen::AngleAxisd(5.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_TRUE(pose->rotation.isApprox(expected, 1e-12));
  // Off the tissue (the sky above the horizon): the view plane through the last position.
  const Eigen::Vector3d last = pose->position;
  pose = hand.follow(c, frame, kW / 2.0, 5.0, kW, kH);
  ASSERT_TRUE(pose.has_value());
  const Eigen::Vector3d f = (c.target - c.position).normalized();
  EXPECT_NEAR((pose->position - last).dot(f), 0.0, 1e-9);
}

TEST(ViewControls, AToolThatCollidesMovesInTheViewPlaneOncePlaced) {
  // Placed on the tissue like any tool; then the tissue it pushed moves away from the camera (the frame shows it
  // 1 mm lower), and the next move keeps the tool in the view plane through where it was, not on the moved surface.
  Scene scene;
  ToolSettings tool;
  tool.name = "punch";
  tool.collide = true;
  tool.keyframes = {PoseKey{0.0, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}}};
  scene.tools.push_back(tool);
  HandTool hand(scene, 0);
  const Camera c = camera();
  RenderScene frame;
  frame.meshes.push_back(floor(0.0f));
  const Eigen::Vector3d on = {0.004, -0.003, 0.0};
  const Eigen::Vector3d px = project_to_pixel(c, kW, kH, on);
  std::optional<sim::Pose> pose = hand.follow(c, frame, px.x(), px.y(), kW, kH);
  ASSERT_TRUE(pose.has_value());
  EXPECT_TRUE(pose->position.isApprox(on, 1e-6));
  frame.meshes[0] = floor(-0.001f);
  const Eigen::Vector3d next = {0.006, -0.002, 0.0};
  const Eigen::Vector3d px2 = project_to_pixel(c, kW, kH, next);
  pose = hand.follow(c, frame, px2.x(), px2.y(), kW, kH);
  ASSERT_TRUE(pose.has_value());
  const Eigen::Vector3d f = (c.target - c.position).normalized();
  EXPECT_NEAR((pose->position - on).dot(f), 0.0, 1e-9);  // the view plane through the first position
  const Ray ray = pixel_ray(c, px2.x(), px2.y(), kW, kH);
  EXPECT_LT((pose->position - ray.origin).cross(ray.direction).norm(), 1e-9);  // under the mouse
  // One step deeper: along the ray by 1 % of the eye-target distance, from the plane.
  const Eigen::Vector3d before = pose->position;
  hand.adjust(1.0, 0.0);
  pose = hand.follow(c, frame, px2.x(), px2.y(), kW, kH);
  EXPECT_TRUE(pose->position.isApprox(before + 0.01 * (c.target - c.position).norm() * ray.direction, 1e-9));
  // A tool that does not collide follows the surface as it is drawn.
  scene.tools[0].collide = false;
  HandTool free_hand(scene, 0);
  frame.meshes[0] = floor(0.0f);
  (void)free_hand.follow(c, frame, px.x(), px.y(), kW, kH);
  frame.meshes[0] = floor(-0.001f);
  pose = free_hand.follow(c, frame, px2.x(), px2.y(), kW, kH);
  EXPECT_NEAR(pose->position.z(), -0.001, 1e-6);
}

}  // namespace
}  // namespace octocut::engine
