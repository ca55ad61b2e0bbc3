// Tools at run time (poses, cylinder blades, blade and mesh files) and expected blocks (checks, regeneration,
// splicing into a scene file), against hand-computed values.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "octocut/sim/primitives.hpp"
#include "octocut/engine/scene/expected.hpp"
#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/render/render_builder.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/engine/run/tool.hpp"
#include "common/temp_dir.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;

constexpr double k_pi = std::numbers::pi;

/// A tool with the given keyframes (t, position, rotation_deg).
ToolSettings tool_with(std::vector<ToolKeyframe> keyframes) {
  ToolSettings tool;
  tool.name = "t";
  tool.keyframes = std::move(keyframes);
  return tool;
}

/// The rotation about axis `axis` by `degrees`.
sim::Mat3 rotation_about(const sim::Vec3& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * k_pi / 180.0, axis.normalized()).toRotationMatrix();
}

// ---- tool_pose ------------------------------------------------------------------------------------------------------

TEST(ToolPose, SlerpMidpointOfZeroAndNinetyDegreesAboutZIsFortyFive) {
  const ToolSettings tool = tool_with({{0.0, {0, 0, 0}, {0, 0, 0}}, {2.0, {0.02, -0.04, 0.06}, {0, 0, 90}}});
  const ToolPose pose = tool_pose(tool, 1.0);
  EXPECT_TRUE(pose.rotation.isApprox(rotation_about(sim::Vec3::UnitZ(), 45.0), 1e-14)) << pose.rotation;
  EXPECT_TRUE(pose.position.isApprox(sim::Vec3(0.01, -0.02, 0.03), 1e-15)) << pose.position.transpose();

  // A quarter of the way: 22.5 degrees, a quarter of the translation.
  const ToolPose quarter = tool_pose(tool, 0.5);
  EXPECT_TRUE(quarter.rotation.isApprox(rotation_about(sim::Vec3::UnitZ(), 22.5), 1e-14));
  EXPECT_TRUE(quarter.position.isApprox(sim::Vec3(0.005, -0.01, 0.015), 1e-15));
}

TEST(ToolPose, HeldBeforeTheFirstAndAfterTheLastKeyframe) {
  const ToolSettings tool =
      tool_with({{1.0, {0.1, 0, 0}, {30, 0, 0}}, {2.0, {0.2, 0, 0}, {0, 0, 0}}, {3.0, {0.2, 0.3, 0}, {0, 60, 0}}});
  const ToolPose before = tool_pose(tool, 0.0);
  EXPECT_EQ(before.position, sim::Vec3(0.1, 0, 0));
  EXPECT_TRUE(before.rotation.isApprox(rotation_about(sim::Vec3::UnitX(), 30.0), 1e-14));
  const ToolPose after = tool_pose(tool, 10.0);
  EXPECT_EQ(after.position, sim::Vec3(0.2, 0.3, 0));
  EXPECT_TRUE(after.rotation.isApprox(rotation_about(sim::Vec3::UnitY(), 60.0), 1e-14));
  // At a keyframe exactly, its pose; in the second interval, the second interval's interpolation.
  EXPECT_TRUE(tool_pose(tool, 2.0).position.isApprox(sim::Vec3(0.2, 0, 0), 1e-15));
  EXPECT_TRUE(tool_pose(tool, 2.0).rotation.isApprox(sim::Mat3::Identity(), 1e-14));
  EXPECT_TRUE(tool_pose(tool, 2.5).position.isApprox(sim::Vec3(0.2, 0.15, 0), 1e-15));
  EXPECT_TRUE(tool_pose(tool, 2.5).rotation.isApprox(rotation_about(sim::Vec3::UnitY(), 30.0), 1e-14));
}

TEST(ToolPose, SingleKeyframeIsConstantAndEulerOrderIsXThenYThenZ) {
  const ToolSettings tool = tool_with({{0.5, {1, 2, 3}, {90, 90, 0}}});
  // Rx(90) then Ry(90) about fixed axes: x -> x -> -z; y -> z -> x; z -> -y -> -y.
  const sim::Mat3 expected = (sim::Mat3() << 0, 1, 0, 0, 0, -1, -1, 0, 0).finished();
  for (const double t : {0.0, 0.5, 7.0}) {
    const ToolPose pose = tool_pose(tool, t);
    EXPECT_EQ(pose.position, sim::Vec3(1, 2, 3));
    EXPECT_TRUE(pose.rotation.isApprox(expected, 1e-14)) << pose.rotation;
  }
  EXPECT_TRUE(sim::euler_xyz_deg({90, 90, 0}).isApprox(expected, 1e-14));
}

TEST(ToolPose, AgreesWithTheRenderPropsPoseConvention) {
  // The same keyframes as a tool and as a render prop give the same transform at every time, ends included.
  const std::vector<ToolKeyframe> keys = {
      {0.2, {0.01, 0.02, 0.03}, {10, -20, 30}}, {0.7, {-0.01, 0.0, 0.05}, {170, 45, -60}}, {1.1, {0, 0, 0}, {0, 0, 0}}};
  const ToolSettings tool = tool_with(keys);
  RenderProp prop;
  for (const ToolKeyframe& k : keys) prop.keyframes.push_back({k.t, k.position, k.rotation_deg});
  for (const double t : {0.0, 0.2, 0.3, 0.45, 0.7, 0.9, 1.1, 2.0}) {
    const ToolPose pose = tool_pose(tool, t);
    const Eigen::Matrix4d expected = prop_pose(prop, t);
    EXPECT_TRUE(pose.rotation.isApprox(expected.topLeftCorner<3, 3>(), 1e-14)) << t;
    EXPECT_TRUE(pose.position.isApprox(expected.topRightCorner<3, 1>(), 1e-14) ||
                (pose.position - expected.topRightCorner<3, 1>()).norm() < 1e-16)
        << t;
    // A proper rotation.
    EXPECT_NEAR(pose.rotation.determinant(), 1.0, 1e-14);
    EXPECT_TRUE((pose.rotation.transpose() * pose.rotation).isApprox(sim::Mat3::Identity(), 1e-14));
  }
}

// ---- cylinder_blade -------------------------------------------------------------------------------------------------

TEST(CylinderBlade, ClosedOutwardWithThePolygonPrismVolume) {
  const double r = 0.001, h = 0.004;
  double previous_error = std::numeric_limits<double>::infinity();
  for (const int n : {3, 4, 8, 32, 256, 1024}) {
    sim::TriMesh blade = sim::cylinder_mesh(r, h, n);
    EXPECT_EQ(blade.num_vertices(), std::size_t(2 * n + 2));
    EXPECT_EQ(blade.num_triangles(), std::size_t(4 * n));
    // Closed, manifold, consistently oriented, free of self-intersections: validate_mesh throws otherwise, and it
    // would warn about (and flip) an inward mesh.
    EXPECT_TRUE(validate_mesh(blade, "cylinder", true).empty()) << n;
    // The exact volume of the prism over the regular n-gon.
    const double exact = n / 2.0 * r * r * std::sin(2.0 * k_pi / n) * h;
    EXPECT_NEAR(sim::signed_volume(blade), exact, 1e-12 * exact) << n;
    // It tends to pi r^2 h from below.
    const double error = k_pi * r * r * h - sim::signed_volume(blade);
    EXPECT_GT(error, 0.0);
    EXPECT_LT(error, previous_error);
    previous_error = error;
    // Centred on the origin, axis z.
    const sim::Box3 box = sim::bounds(blade);
    EXPECT_NEAR(box.min.z(), -h / 2, 1e-18);
    EXPECT_NEAR(box.max.z(), h / 2, 1e-18);
    EXPECT_NEAR(box.max.x(), r, 1e-18);
  }
  EXPECT_LT(previous_error, 1e-5 * k_pi * r * r * h);
}

TEST(CylinderBlade, RejectsBadArguments) {
  EXPECT_THROW(sim::cylinder_mesh(0.0, 1.0, 8), std::invalid_argument);
  EXPECT_THROW(sim::cylinder_mesh(1.0, -1.0, 8), std::invalid_argument);
  EXPECT_THROW(sim::cylinder_mesh(std::numeric_limits<double>::quiet_NaN(), 1.0, 8), std::invalid_argument);
  EXPECT_THROW(sim::cylinder_mesh(1.0, 1.0, 2), std::invalid_argument);
}

// ---- blade and mesh files -------------------------------------------------------------------------------------------

class ToolFileTest : public octocut::test::TempDirTest {
 protected:

  /// Writes a scene with one tool whose blade is `blade` (a JSON value) and whose extra members are `extra`.
  std::string write_scene(const std::string& blade, const std::string& extra = "") const {
    const fs::path path = m_dir / "scene.json";
    std::ofstream(path) << R"({"object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}}},
                               "tools": [{"name": "punch", "blade": )"
                        << blade << extra << R"(, "keyframes": [{"t": 0}]}]})";
    return path.string();
  }

  /// The message of the SceneError that load_blade throws for the scene at `path`, or "(no error)".
  static std::string blade_error(const std::string& path) {
    const Scene scene = load_scene(path);
    try {
      load_blade(scene, 0);
    } catch (const SceneError& error) {
      return error.what();
    }
    return "(no error)";
  }

};

TEST_F(ToolFileTest, CylinderBladeFromTheScene) {
  const Scene scene = load_scene(write_scene(R"({"cylinder": {"radius": 0.002, "height": 0.01, "segments": 6}})"));
  const sim::TriMesh blade = load_blade(scene, 0);
  EXPECT_EQ(blade.num_triangles(), 24u);
  EXPECT_NEAR(sim::signed_volume(blade), 3.0 * 0.002 * 0.002 * std::sin(k_pi / 3.0) * 0.01, 1e-18);
  EXPECT_TRUE(load_tool_mesh(scene, 0).vertices.empty());
  EXPECT_THROW(load_blade(scene, 1), std::out_of_range);
}

TEST_F(ToolFileTest, MeshBladeIsScaledAndValidated) {
  save_mesh(m_dir / "blade.ply", sim::cylinder_mesh(2.0, 10.0, 16));  // mm
  save_mesh(m_dir / "shaft.ply", sim::cylinder_mesh(1.75, 100.0, 16));
  const Scene scene = load_scene(write_scene(R"("blade.ply", "mesh": "shaft.ply", "scale": 0.001)"));
  const sim::TriMesh blade = load_blade(scene, 0);
  const double volume = 8.0 * 0.002 * 0.002 * std::sin(k_pi / 8.0) * 0.01;
  EXPECT_NEAR(sim::signed_volume(blade), volume, 1e-6 * volume);  // float32 PLY coordinates
  EXPECT_EQ(load_tool_mesh(scene, 0).num_triangles(), 64u);
  const std::vector<ToolSummary> summary = validate_tools(scene);
  ASSERT_EQ(summary.size(), 1u);
  EXPECT_EQ(summary[0].name, "punch");
  EXPECT_EQ(summary[0].blade_triangles, 64u);
  EXPECT_EQ(summary[0].mesh_triangles, 64u);
  EXPECT_NEAR(summary[0].blade_volume_m3, volume, 1e-6 * volume);
}

TEST_F(ToolFileTest, InvertedBladeIsFlippedWithAWarning) {
  // The same cylinder with every triangle reversed: flipped back, and said so, as for a surface.
  sim::TriMesh inverted = sim::cylinder_mesh(2.0, 10.0, 16);
  for (auto& t : inverted.triangles) std::swap(t[1], t[2]);
  save_mesh(m_dir / "inverted.ply", inverted);
  const Scene scene = load_scene(write_scene(R"("inverted.ply", "scale": 0.001)"));
  std::vector<std::string> warnings;
  const sim::TriMesh blade = load_blade(scene, 0, &warnings);
  EXPECT_GT(sim::signed_volume(blade), 0.0);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0].rfind("/tools/0/blade: ", 0), 0u) << warnings[0];
  EXPECT_NE(warnings[0].find("reoriented"), std::string::npos) << warnings[0];
  // The file is named once.
  const std::size_t named = warnings[0].find("inverted.ply");
  ASSERT_NE(named, std::string::npos) << warnings[0];
  EXPECT_EQ(warnings[0].find("inverted.ply", named + 1), std::string::npos) << warnings[0];
  EXPECT_EQ(validate_tools(scene).at(0).warnings, warnings);
  // A correctly oriented blade gives none.
  save_mesh(m_dir / "ok.ply", sim::cylinder_mesh(2.0, 10.0, 16));
  warnings.clear();
  (void)load_blade(load_scene(write_scene(R"("ok.ply", "scale": 0.001)")), 0, &warnings);
  EXPECT_TRUE(warnings.empty());
}

TEST_F(ToolFileTest, OpenBladeIsRejectedNamingThePointer) {
  sim::TriMesh open = sim::cylinder_mesh(1.0, 1.0, 8);
  open.triangles.pop_back();
  save_mesh(m_dir / "open.ply", open);
  const std::string path = write_scene(R"("open.ply")");
  const std::string prefix = path + ": /tools/0/blade: " + (m_dir / "open.ply").string() + ": ";
  const std::string message = blade_error(path);
  EXPECT_EQ(message.substr(0, prefix.size()), prefix) << message;
  EXPECT_NE(message.find("not closed"), std::string::npos) << message;
}

TEST_F(ToolFileTest, SelfIntersectingBladeIsRejectedNamingThePointer) {
  // Two closed cylinders that overlap: each is a valid solid, together they intersect.
  sim::TriMesh both = sim::cylinder_mesh(1.0, 1.0, 8);
  const sim::TriMesh other = sim::cylinder_mesh(1.0, 1.0, 8);
  const auto offset = static_cast<std::int32_t>(both.vertices.size());
  for (const sim::Vec3& v : other.vertices) both.vertices.push_back(v + sim::Vec3(0.5, 0.1, 0.2));
  for (const auto& t : other.triangles) both.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
  save_mesh(m_dir / "crossed.ply", both);
  const std::string path = write_scene(R"("crossed.ply")");
  const std::string message = blade_error(path);
  EXPECT_EQ(message.rfind(path + ": /tools/0/blade: " + (m_dir / "crossed.ply").string() + ": ", 0), 0u) << message;
  EXPECT_NE(message.find("intersect"), std::string::npos) << message;
}

TEST_F(ToolFileTest, NanBladeIsRejectedNamingThePointer) {
  sim::TriMesh blade = sim::cylinder_mesh(1.0, 1.0, 8);
  blade.vertices[3].x() = std::numeric_limits<double>::quiet_NaN();
  save_mesh(m_dir / "nan.ply", blade);
  const std::string path = write_scene(R"("nan.ply")");
  const std::string message = blade_error(path);
  EXPECT_EQ(message.rfind(path + ": /tools/0/blade: " + (m_dir / "nan.ply").string() + ": ", 0), 0u) << message;
  EXPECT_NE(message.find("non-finite"), std::string::npos) << message;
}

TEST_F(ToolFileTest, BadToolMeshNamesItsPointer) {
  sim::TriMesh open = sim::cylinder_mesh(1.0, 1.0, 8);
  open.triangles.pop_back();
  save_mesh(m_dir / "open.ply", open);
  const std::string path = write_scene(R"({"cylinder": {"radius": 1, "height": 1}})", R"(, "mesh": "open.ply")");
  const Scene scene = load_scene(path);
  EXPECT_NO_THROW(load_blade(scene, 0));
  try {
    load_tool_mesh(scene, 0);
    ADD_FAILURE() << "no error";
  } catch (const SceneError& error) {
    EXPECT_EQ(std::string(error.what()).rfind(path + ": /tools/0/mesh: " + (m_dir / "open.ply").string() + ": ", 0),
              0u)
        << error.what();
  }
  EXPECT_THROW(validate_tools(scene), SceneError);
}

// ---- check_expected -------------------------------------------------------------------------------------------------

constexpr const char* k_report = R"({
  "status": "ok", "steps": 50, "sim_time_s": 0.05,
  "counts": {"elements": 812, "dofs": 1203},
  "stability": {"finite": true, "max_speed_m_s": 0.25},
  "cuts": [{"t": 0.01, "status": "ok", "removed_volume_m3": 1.25e-7}],
  "probes": {"tip": {"displacement": [0.0, 0.0, -0.002]}}
})";

TEST(CheckExpected, EveryKindPasses) {
  const std::string expected = R"({
    "/status": "ok", "/stability/finite": true, "/steps": 50, "/sim_time_s": 0.05,
    "/counts/elements": {"min": 700, "max": 900}, "/counts/dofs": {"min": 1000},
    "/stability/max_speed_m_s": {"max": 1},
    "/cuts/0/removed_volume_m3": {"value": 1.2e-7, "rel": 0.05},
    "/probes/tip/displacement/2": {"value": -0.0021, "abs": 1e-4},
    "/cuts/0/status": "ok"
  })";
  EXPECT_EQ(check_expected(expected, k_report), std::vector<std::string>{});
  EXPECT_EQ(expected_check_count(expected), 10u);
  EXPECT_EQ(check_expected("{}", k_report), std::vector<std::string>{});
}

TEST(CheckExpected, EachFailureKindHasItsLine) {
  const std::string expected = R"({
    "/status": "failed",
    "/stability/finite": false,
    "/steps": 49,
    "/sim_time_s": 0.0500001,
    "/counts/elements": {"min": 700, "max": 800},
    "/counts/dofs": {"min": 1300},
    "/stability/max_speed_m_s": {"max": 0.2},
    "/cuts/0/removed_volume_m3": {"value": 1.3e-7, "rel": 0.01},
    "/probes/tip/displacement/2": {"value": -0.0025, "abs": 1e-4, "rel": 0.1},
    "/counts/tets": 3,
    "/cuts/1/status": "ok",
    "/status~1x": "ok",
    "/name": "x",
    "/counts/elements~0": 1,
    "/steps/0": 1,
    "/cuts/0/status": 3,
    "/cuts/0/t": "0.01"
  })";
  const std::vector<std::string> expected_failures = {
      R"(/status: "ok", expected "failed")",
      "/stability/finite: true, expected false",
      "/steps: 50, expected 49",
      "/sim_time_s: 0.05 not within 0.0500001 ± 5.00001e-11",
      "/counts/elements: 812 not in [700, 800]",
      "/counts/dofs: 1203 not >= 1300",
      "/stability/max_speed_m_s: 0.25 not <= 0.2",
      "/cuts/0/removed_volume_m3: 1.25e-07 not within 1.3e-07 ± 1.3e-09",
      "/probes/tip/displacement/2: -0.002 not within -0.0025 ± 0.00025",
      "/counts/tets: missing from the report",
      "/cuts/1/status: missing from the report",
      "/status~1x: missing from the report",
      "/name: missing from the report",
      "/counts/elements~0: missing from the report",
      "/steps/0: missing from the report",
      R"(/cuts/0/status: "ok" is not a number)",
      R"(/cuts/0/t: 0.01 is not a string (expected "0.01"))",
  };
  EXPECT_EQ(check_expected(expected, k_report), expected_failures);
}

TEST(CheckExpected, ToleranceBoundariesAreInclusive) {
  // |x - v| <= max(abs, rel |v|): 812 vs 800 with rel 0.02 (tolerance 16) or abs 12 passes, with abs 11.5 fails.
  EXPECT_TRUE(check_expected(R"({"/counts/elements": {"value": 800, "rel": 0.02}})", k_report).empty());
  EXPECT_TRUE(check_expected(R"({"/counts/elements": {"value": 800, "abs": 12}})", k_report).empty());
  EXPECT_EQ(check_expected(R"({"/counts/elements": {"value": 800, "abs": 11.5, "rel": 0.01}})", k_report),
            std::vector<std::string>{"/counts/elements: 812 not within 800 ± 11.5"});
  EXPECT_TRUE(check_expected(R"({"/counts/elements": {"min": 812, "max": 812}})", k_report).empty());
  // An integer in the report equals a float written as an integer-valued number.
  EXPECT_TRUE(check_expected(R"({"/counts/elements": 812.0})", k_report).empty());
}

TEST(CheckExpected, MalformedInputThrows) {
  EXPECT_THROW(check_expected("{", k_report), std::invalid_argument);
  EXPECT_THROW(check_expected("[]", k_report), std::invalid_argument);
  EXPECT_THROW(check_expected("{}", "nope"), std::invalid_argument);
  try {
    check_expected(R"({"/a": {"value": 1, "min": 0}})", k_report);
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& error) {
    EXPECT_STREQ(error.what(), R"(expected block: /~1a/min: cannot be combined with "value")");
  }
  EXPECT_THROW(check_expected(R"({"counts": 1})", k_report), std::invalid_argument);
}

// ---- regenerate_expected --------------------------------------------------------------------------------------------

TEST(RegenerateExpected, MovesEveryCheckToTheReportAndKeepsTolerances) {
  const std::string old_block = R"({"/steps": 40, "/status": "failed", "/sim_time_s": 0.04,
    "/counts/elements": {"min": 700, "max": 800},
    "/counts/dofs": {"min": 1000},
    "/stability/max_speed_m_s": {"min": 0.1, "max": 0.3},
    "/cuts/0/removed_volume_m3": {"rel": 0.05, "value": 1e-7},
    "/probes/tip/displacement/2": {"value": 0, "abs": 1e-4},
    "/counts/tets": 5})";
  const std::string regenerated = regenerate_expected(old_block, k_report);
  // [700, 800]: midpoint 750, relative half-width 1/15; around 812: 812 -+ 54.13 -> [757, 867] (integers outward).
  // [0.1, 0.3]: midpoint 0.2, relative half-width 1/2; around 0.25: [0.125, 0.375].
  // One-sided bounds and checks the report lacks stay as they were; key order is kept, as in the block.
  EXPECT_EQ(regenerated, R"({
  "/steps": 50,
  "/status": "ok",
  "/sim_time_s": 0.05,
  "/counts/elements": {"min": 757, "max": 867},
  "/counts/dofs": {"min": 1000},
  "/stability/max_speed_m_s": {"min": 0.125, "max": 0.375},
  "/cuts/0/removed_volume_m3": {"rel": 0.05, "value": 1.25e-07},
  "/probes/tip/displacement/2": {"value": -0.002, "abs": 0.0001},
  "/counts/tets": 5
})");
  // Round trip: every check the report can satisfy now passes; the missing pointer still fails.
  EXPECT_EQ(check_expected(regenerated, k_report), std::vector<std::string>{"/counts/tets: missing from the report"});
  // Regenerating twice from the same report changes nothing but widens nothing either.
  const std::string again = regenerate_expected(regenerated, k_report);
  EXPECT_EQ(check_expected(again, k_report), std::vector<std::string>{"/counts/tets: missing from the report"});
}

TEST(RegenerateExpected, ZeroMidpointKeepsAbsoluteWidthsAndFloatsRoundOutward) {
  const std::string report = R"({"a": 0.0, "b": 0.123456789, "c": 5})";
  const std::string block = R"({"/a": {"min": -1, "max": 3}, "/b": {"min": -0.5, "max": 0.5}, "/c": {"min": 4.5, "max": 5.5}})";
  // /a: x = 0 -> the same offsets from the midpoint 1: [-2, 2] (x is a float, so the bounds are floats).
  // /b: midpoint 0 -> the same offsets: [0.123456789 - 0.5, 0.123456789 + 0.5], rounded to 6 digits.
  // /c: midpoint 5, relative half-width 0.1 -> [4.5, 5.5].
  EXPECT_EQ(regenerate_expected(block, report), R"({
  "/a": {"min": -2.0, "max": 2.0},
  "/b": {"min": -0.376543, "max": 0.623457},
  "/c": {"min": 4.5, "max": 5.5}
})");
  EXPECT_EQ(regenerate_expected("{}", report), "{}");
}

// ---- splicing a block into a scene file -----------------------------------------------------------------------------

TEST(ReplaceExpectedBlock, KeepsEveryOtherByte) {
  const std::string scene = "{\n  \"name\": \"x\",  \"object\": {\"surface\": \"a}\\\"b.ply\"},\n"
                            "  \"expected\": {\"/steps\": [1, {\"x\": \"}\"}]},\n  \"seed\": 3\n}\n";
  EXPECT_EQ(expected_block_text(scene), "{\"/steps\": [1, {\"x\": \"}\"}]}");
  const std::string block = "{\n  \"/steps\": 2\n}";
  EXPECT_EQ(replace_expected_block(scene, block),
            "{\n  \"name\": \"x\",  \"object\": {\"surface\": \"a}\\\"b.ply\"},\n"
            "  \"expected\": {\n    \"/steps\": 2\n  },\n  \"seed\": 3\n}\n");
  EXPECT_EQ(expected_block_text("{\"name\": \"x\"}"), "");
  EXPECT_THROW(replace_expected_block("{\"name\": \"x\"}", block), std::invalid_argument);
  EXPECT_THROW(expected_block_text("[1]"), std::invalid_argument);
}

}  // namespace
}  // namespace octocut::engine
