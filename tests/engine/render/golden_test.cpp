// Golden images rendered headless (Mesa llvmpipe in CI): small deterministic scenes compared with PNGs under
// tests/engine/render/golden/ within the tolerance stated in each test's JSON file, plus checks against independent truth
// (the background colour, the mask, overlay colours at projected points, cut faces tinted red).
//
// Regenerate the references on purpose with OCTOCUT_REGENERATE_GOLDEN=1 build/bin/render_golden_test; review the
// new PNGs before committing them.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>

#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/engine/render/renderer.hpp"
#include "octocut/engine/run/world.hpp"
#include "octocut/engine/scene/scene_loader.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 160, kHeight = 120;

/// A UV sphere of radius r around c, counter-clockwise from outside.
RenderMesh sphere(const Eigen::Vector3f& c, float r, int segments, int rings, MaterialKind material) {
  RenderMesh m;
  m.material = material;
  for (int i = 0; i <= rings; ++i) {
    const float theta = float(std::numbers::pi) * float(i) / float(rings);
    for (int k = 0; k <= segments; ++k) {
      const float phi = 2.0f * float(std::numbers::pi) * float(k) / float(segments);
      const Eigen::Vector3f n(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
      m.positions.push_back(c + r * n);
      m.normals.push_back(n);
    }
  }
  for (int i = 0; i < rings; ++i)
    for (int k = 0; k < segments; ++k) {
      const int a = i * (segments + 1) + k, b = a + segments + 1;
      m.triangles.push_back({a, b, b + 1});
      m.triangles.push_back({a, b + 1, a + 1});
    }
  return m;
}

/// A closed cylinder along z from z0 to z1 (a procedural tool shaft), normals computed by the renderer.
RenderMesh cylinder(float radius, float z0, float z1, int segments) {
  RenderMesh m;
  m.material = MaterialKind::metal;
  for (int k = 0; k < segments; ++k) {
    const float phi = 2.0f * float(std::numbers::pi) * float(k) / float(segments);
    m.positions.push_back({radius * std::cos(phi), radius * std::sin(phi), z0});
    m.positions.push_back({radius * std::cos(phi), radius * std::sin(phi), z1});
  }
  const int bottom = int(m.positions.size()), top = bottom + 1;
  m.positions.push_back({0, 0, z0});
  m.positions.push_back({0, 0, z1});
  for (int k = 0; k < segments; ++k) {
    const int a = 2 * k, b = 2 * ((k + 1) % segments);
    m.triangles.push_back({a, b, b + 1});
    m.triangles.push_back({a, b + 1, a + 1});
    m.triangles.push_back({bottom, b, a});
    m.triangles.push_back({top, a + 1, b + 1});
  }
  return m;
}

/// A box as a grid of 4 x 4 cells per face (6 faces, separate vertices), as the tissue of a box object.
RenderMesh box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  RenderMesh m;
  for (int a = 0; a < 3; ++a)
    for (int side = 0; side < 2; ++side) {
      int u = (a + 1) % 3, v = (a + 2) % 3;
      if (side == 0) std::swap(u, v);
      const int first = int(m.positions.size());
      for (int j = 0; j <= 4; ++j)
        for (int i = 0; i <= 4; ++i) {
          Eigen::Vector3f p;
          p[a] = side ? hi[a] : lo[a];
          p[u] = lo[u] + (hi[u] - lo[u]) * float(i) / 4.0f;
          p[v] = lo[v] + (hi[v] - lo[v]) * float(j) / 4.0f;
          m.positions.push_back(p);
        }
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
          const int p00 = first + j * 5 + i;
          m.triangles.push_back({p00, p00 + 1, p00 + 6});
          m.triangles.push_back({p00, p00 + 6, p00 + 5});
        }
    }
  m.normals = mesh_normals(m.positions, m.triangles);
  return m;
}

RenderScene base_scene() {
  RenderScene s;
  s.width = kWidth;
  s.height = kHeight;
  s.msaa = 4;
  s.background = Eigen::Vector3f(0.2f, 0.2f, 0.2f);  // exactly 51 in 8 bits
  s.camera.position = {0.0, -4.0, 1.0};
  s.camera.target = {0.0, 0.0, 0.0};
  s.camera.up = {0.0, 0.0, 1.0};
  s.camera.fov_deg = 45.0;
  s.camera.near = 0.1;
  s.camera.far = 20.0;
  return s;
}

std::array<int, 3> pixel(const Image& image, int x, int y) {
  const std::size_t i = 3 * (std::size_t(y) * image.width + x);
  return {image.rgb[i], image.rgb[i + 1], image.rgb[i + 2]};
}

std::array<int, 3> pixel_at(const Image& image, const Camera& camera, const Eigen::Vector3d& world) {
  const Eigen::Vector3d p = project_to_pixel(camera, image.width, image.height, world);
  const int x = int(std::floor(p.x())), y = int(std::floor(p.y()));
  const bool inside = x >= 0 && y >= 0 && x < image.width && y < image.height;
  EXPECT_TRUE(inside) << "the point " << world.transpose() << " projects outside the image";
  return inside ? pixel(image, x, y) : std::array<int, 3>{-1, -1, -1};
}

class GoldenTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!renderer_available()) GTEST_SKIP() << "built without EGL";
    if (!s_renderer) s_renderer = make_renderer();
  }
  // The renderer (its EGL context) goes before exit(): by the time static destructors run, NVIDIA's driver has torn
  // itself down, and destroying the context then crashed in libepoxy (seen on an H200; llvmpipe does not mind).
  static void TearDownTestSuite() { s_renderer.reset(); }

  /// Renders `scene`, checks that a second render is bit-identical, and compares with golden/<name>.png.
  Image render_and_compare(const std::string& name, const RenderScene& scene) {
    const Image image = s_renderer->render(scene);
    EXPECT_EQ(image.width, scene.width);
    EXPECT_EQ(image.height, scene.height);
    EXPECT_EQ(s_renderer->render(scene).rgb, image.rgb) << "rendering is not deterministic";

    const fs::path dir = fs::path(OCTOCUT_SOURCE_DIR) / "tests/engine/render/golden";
    const fs::path png = dir / (name + ".png"), tolerance_file = dir / (name + ".json");
    const char* regenerate = std::getenv("OCTOCUT_REGENERATE_GOLDEN");
    if (regenerate != nullptr && std::string(regenerate) == "1") {
      write_file_atomic(png, encode_png(image, 9));
      if (!fs::exists(tolerance_file))
        write_file_atomic(tolerance_file, "{\"threshold\": 2, \"max_diff\": 48, \"max_fraction\": 0.01}\n");
      return image;
    }

    // Tolerance: a pixel differs when a channel is off by more than `threshold`; at most `max_fraction` of the
    // pixels may differ, and none by more than `max_diff`.
    const nlohmann::json tol = nlohmann::json::parse(read_file(tolerance_file));
    const int threshold = tol.at("threshold").get<int>(), max_diff = tol.at("max_diff").get<int>();
    const double max_fraction = tol.at("max_fraction").get<double>();
    const Image golden = decode_png(read_file(png), png.string());
    EXPECT_EQ(golden.width, image.width);
    EXPECT_EQ(golden.height, image.height);
    if (golden.rgb.size() != image.rgb.size()) return image;
    int worst = 0;
    long differing = 0;
    for (std::size_t p = 0; p < image.rgb.size(); p += 3) {
      int d = 0;
      for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(int(image.rgb[p + c]) - int(golden.rgb[p + c])));
      worst = std::max(worst, d);
      differing += d > threshold ? 1 : 0;
    }
    const double fraction = double(differing) / double(image.width * image.height);
    EXPECT_LE(worst, max_diff) << name;
    EXPECT_LE(fraction, max_fraction) << name;
    if (worst > max_diff || fraction > max_fraction) {
      const fs::path actual = fs::temp_directory_path() / ("octocut_golden_" + name + "_actual.png");
      write_file_atomic(actual, encode_png(image));
      ADD_FAILURE() << "the rendered image is at " << actual;
    }
    return image;
  }

  static std::unique_ptr<Renderer> s_renderer;
};

std::unique_ptr<Renderer> GoldenTest::s_renderer;

TEST_F(GoldenTest, ShadedSphere) {
  RenderScene scene = base_scene();
  scene.meshes.push_back(sphere({0, 0, 0}, 1.0f, 32, 16, MaterialKind::tissue));
  const Image image = render_and_compare("sphere", scene);
  // Background exactly the clear colour in the corners.
  EXPECT_EQ(pixel(image, 0, 0), (std::array<int, 3>{51, 51, 51}));
  EXPECT_EQ(pixel(image, kWidth - 1, kHeight - 1), (std::array<int, 3>{51, 51, 51}));
  // With the headlight, the point facing the eye is brighter than a point near the silhouette.
  const Eigen::Vector3d facing = Eigen::Vector3d(0.0, -4.0, 1.0).normalized();
  const Eigen::Vector3d grazing = Eigen::Vector3d(0.97, 0.0, 0.24).normalized();
  const auto centre = pixel_at(image, scene.camera, facing), edge = pixel_at(image, scene.camera, grazing);
  EXPECT_GT(centre[0] + centre[1] + centre[2], edge[0] + edge[1] + edge[2] + 60);
  // Tissue is pink: red above green and blue.
  EXPECT_GT(centre[0], centre[1]);
  EXPECT_GT(centre[0], centre[2]);
}

TEST_F(GoldenTest, CullingBackFacesOnTheCpuChangesNoPixel) {
  // Closed meshes drop their back faces before upload; drawing every face (no culling at all) must give the same image,
  // since the depth test hides the back faces anyway, except along silhouettes, where multisampled coverage of the
  // back faces differs. A wrongly culled front face would leave a hole of many pixels. The moved and rotated tool
  // checks the eye's transform into model space.
  RenderScene culled = base_scene();
  culled.meshes.push_back(sphere({0, 0, 0}, 1.0f, 48, 24, MaterialKind::tissue));
  RenderMesh tool = cylinder(0.2f, -0.5f, 1.5f, 24);
  tool.material = MaterialKind::metal;
  tool.model.topLeftCorner<3, 3>() = Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 1, 0).normalized()).toRotationMatrix();
  tool.model.topRightCorner<3, 1>() = Eigen::Vector3f(0.9f, -1.2f, 0.3f);
  culled.meshes.push_back(tool);
  RenderScene all = culled;
  for (RenderMesh& m : all.meshes) m.cull_back_faces = false;
  const Image a = s_renderer->render(culled), b = s_renderer->render(all);
  ASSERT_EQ(a.rgb.size(), b.rgb.size());
  long differing = 0;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) differing += std::abs(int(a.rgb[i]) - int(b.rgb[i])) > 2 ? 1 : 0;
  EXPECT_LE(double(differing) / double(a.rgb.size()), 0.005) << differing << " channel values differ";
}

TEST_F(GoldenTest, TheMultisampledRegionNeverClipsGeometry) {
  // Only the screen rectangle that geometry can reach is multisampled. A sphere partly outside the frame, alone, must
  // come out exactly as when a small second mesh in the far corner makes the rectangle cover the whole frame.
  RenderScene alone = base_scene();
  alone.meshes.push_back(sphere({1.2f, 0.0f, 0.3f}, 0.8f, 48, 24, MaterialKind::tissue));
  RenderScene wide = alone;
  RenderMesh speck = box({-2.0f, 0.0f, -1.05f}, {-1.9f, 0.1f, -0.95f});
  wide.meshes.push_back(speck);
  const Image a = s_renderer->render(alone), b = s_renderer->render(wide);
  ASSERT_EQ(a.rgb.size(), b.rgb.size());
  // Compare every pixel that the speck does not cover (its projected box, with a margin).
  Eigen::Vector3d lo(1e9, 1e9, 0), hi(-1e9, -1e9, 0);
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d corner(k & 1 ? -1.9 : -2.0, k & 2 ? 0.1 : 0.0, k & 4 ? -0.95 : -1.05);
    const Eigen::Vector3d p = project_to_pixel(wide.camera, kWidth, kHeight, corner);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  long sphere_pixels = 0, differing = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      if (x >= lo.x() - 2 && x <= hi.x() + 2 && y >= lo.y() - 2 && y <= hi.y() + 2) continue;
      const auto pa = pixel(a, x, y), pb = pixel(b, x, y);
      differing += pa != pb ? 1 : 0;
      sphere_pixels += pa != std::array<int, 3>{51, 51, 51} ? 1 : 0;
    }
  EXPECT_EQ(differing, 0);
  EXPECT_GT(sphere_pixels, 1000);  // the sphere is there, and large
}

TEST_F(GoldenTest, TissueWithCutFacesAMetalToolAndBone) {
  RenderScene scene = base_scene();
  RenderMesh tissue = box({-1.0f, -0.6f, -0.5f}, {1.0f, 0.6f, 0.3f});
  // The front face (-y) is face 2 * 1 + 0 = 2 in box(): 32 triangles from index 64. Tint its left half as cut.
  tissue.cut.assign(tissue.triangles.size(), 0);
  for (int t = 64; t < 96; ++t) {
    const auto& tri = tissue.triangles[std::size_t(t)];
    const float x = (tissue.positions[tri[0]].x() + tissue.positions[tri[1]].x() + tissue.positions[tri[2]].x()) / 3;
    if (x < 0.0f) tissue.cut[std::size_t(t)] = 1;
  }
  scene.meshes.push_back(tissue);
  // The tool: a cylinder tilted into the view, moved by its model transform.
  RenderMesh tool = cylinder(0.12f, 0.0f, 2.0f, 24);
  Eigen::Affine3f pose = Eigen::Translation3f(0.5f, -0.9f, 0.3f) * Eigen::AngleAxisf(0.6f, Eigen::Vector3f::UnitX());
  tool.model = pose.matrix();
  scene.meshes.push_back(tool);
  scene.meshes.push_back(sphere({-1.4f, 0.8f, -0.2f}, 0.5f, 24, 12, MaterialKind::bone));
  const Image image = render_and_compare("tools", scene);
  // A cut face is fresh-tissue red; the uncut half of the same face is pink (green well above the cut's).
  const auto cut = pixel_at(image, scene.camera, {-0.5, -0.6, -0.1});
  const auto uncut = pixel_at(image, scene.camera, {0.25, -0.6, -0.3});
  EXPECT_GT(cut[0], 3 * cut[1]) << cut[0] << " " << cut[1];
  EXPECT_GT(uncut[1], cut[1] + 40);
  // The tool is grey: its channels are within a few levels of each other.
  const Eigen::Vector3d on_tool = (pose * Eigen::Vector3f(0.0f, -0.12f, 0.8f)).cast<double>();
  const auto metal = pixel_at(image, scene.camera, on_tool);
  EXPECT_LE(std::abs(metal[0] - metal[2]), 25);
  EXPECT_NE(metal, (std::array<int, 3>{51, 51, 51}));
}

// A glass cylinder lying in front of a tissue sphere (as the glass press's glass lies on the cube): the tissue shows
// through it with its colour, where a metal cylinder of the same shape hides it; where only the background lies
// behind, the glass is faint. Checked against the same scene without the cylinder and with it in metal.
TEST_F(GoldenTest, GlassShowsWhatLiesBehindIt) {
  RenderScene scene = base_scene();
  scene.meshes.push_back(sphere({0.0f, 0.0f, -0.3f}, 1.0f, 48, 24, MaterialKind::tissue));
  RenderMesh glass = cylinder(0.35f, -1.2f, 1.2f, 48);
  glass.material = MaterialKind::glass;
  const float quarter_turn = 0.5f * float(std::numbers::pi);  // the cylinder's axis along x
  const Eigen::Affine3f pose =
      Eigen::Translation3f(0.0f, -1.5f, 0.0f) * Eigen::AngleAxisf(quarter_turn, Eigen::Vector3f::UnitY());
  glass.model = pose.matrix();
  glass.still = true;  // never kept in the still layer: it is blended over what is drawn after the layer
  RenderScene bare = scene, metal = scene;
  scene.meshes.push_back(glass);
  glass.material = MaterialKind::metal;
  metal.meshes.push_back(glass);
  const Image image = render_and_compare("glass", scene);
  const Image without = s_renderer->render(bare), in_metal = s_renderer->render(metal);
  // Two points inside the cylinder, below its axis (off the headlight's highlight): behind the first lies the
  // sphere, behind the second the background.
  const Eigen::Vector3d over_tissue(0.0, -1.5, -0.2), over_background(1.0, -1.5, -0.2);
  const auto tissue = pixel_at(image, scene.camera, over_tissue);
  const auto tissue_bare = pixel_at(without, scene.camera, over_tissue);
  const auto tissue_metal = pixel_at(in_metal, scene.camera, over_tissue);
  ASSERT_GT(tissue_bare[0] - tissue_bare[1], 20) << "the sphere is pink there";
  EXPECT_NE(tissue, tissue_bare) << "the glass is drawn";
  EXPECT_GE(tissue[0] - tissue[1], (tissue_bare[0] - tissue_bare[1]) / 2) << "the tissue shows through";
  EXPECT_LE(std::abs(tissue_metal[0] - tissue_metal[1]), 12) << "metal hides it";
  const auto background = pixel_at(image, scene.camera, over_background);
  EXPECT_EQ(pixel_at(without, scene.camera, over_background), (std::array<int, 3>{51, 51, 51}));
  EXPECT_NE(background, (std::array<int, 3>{51, 51, 51})) << "the glass is drawn";
  for (int c = 0; c < 3; ++c) EXPECT_LE(std::abs(background[std::size_t(c)] - 51), 45) << "and faint";
  EXPECT_GT(background[2], background[0]) << "with a blue tint";
  const auto background_metal = pixel_at(in_metal, scene.camera, over_background);
  EXPECT_GT(background_metal[1] - 51, 2 * (background[1] - 51)) << "metal is opaque";
}

TEST_F(GoldenTest, StillMeshesKeptBetweenFramesLookAsIfRedrawn) {
  // A still bone and a still box behind a moving tool that dips into the bone: each frame must equal the same scene
  // with nothing marked still (every mesh drawn afresh), also after the camera, a light, the background and the
  // still geometry change (each of which must redraw the kept layer). The tool moves, so the frames differ.
  RenderScene scene = base_scene();
  scene.meshes.push_back(sphere({-0.3f, 0.4f, 0.0f}, 0.9f, 48, 24, MaterialKind::bone));
  scene.meshes.push_back(box({0.4f, 0.6f, -1.0f}, {1.6f, 1.4f, 0.2f}));
  for (RenderMesh& m : scene.meshes) m.still = true;
  scene.meshes.push_back(cylinder(0.15f, 0.0f, 2.0f, 24));
  const auto frame = [&](float x, float y) {
    scene.meshes.back().model.topRightCorner<3, 1>() = Eigen::Vector3f(x, y, -0.6f);
    RenderScene fresh = scene;
    for (RenderMesh& m : fresh.meshes) m.still = false;
    const Image kept = s_renderer->render(scene), truth = s_renderer->render(fresh);
    EXPECT_TRUE(kept.rgb == truth.rgb) << "tool at " << x << ", " << y;
    return kept;
  };
  const Image first = frame(-0.9f, -0.8f);
  EXPECT_FALSE(frame(0.2f, -0.5f).rgb == first.rgb);
  frame(0.6f, 0.1f);
  scene.camera.target = {0.3, 0.0, 0.2};  // the eye (and its headlight) stays
  frame(0.6f, 0.1f);
  scene.camera.position = {0.5, -4.0, 1.5};
  frame(0.6f, 0.1f);
  scene.lights.push_back({Eigen::Vector3f(2.0f, -2.0f, 3.0f), Eigen::Vector3f(0.6f, 0.6f, 0.5f)});
  frame(0.6f, 0.1f);
  scene.background = Eigen::Vector3f(0.1f, 0.3f, 0.2f);
  frame(0.0f, -0.2f);
  for (Eigen::Vector3f& p : scene.meshes[0].positions) p *= 1.2f;
  frame(0.0f, -0.2f);
  scene.meshes[1].model.topRightCorner<3, 1>() = Eigen::Vector3f(-0.5f, 0.0f, 0.0f);
  frame(0.0f, -0.2f);
}

// A 1 cm block punched through its centre by a 2 mm cylinder, drawn through World as `octocut run` draws it. The rim
// of the hole must be clean: the flat top face is shaded the same right next to the hole as a little further out,
// because its normals are not averaged with the cut wall's (crease split). With averaged normals the ring of top-face
// pixels next to the rim tilts by up to 45 degrees and shades tens of levels off.
TEST_F(GoldenTest, PunchedBlockRimsAreClean) {
  const fs::path dir = fs::temp_directory_path() / "octocut_golden_punched_block";
  fs::create_directories(dir);
  write_file_atomic(dir / "scene.json", R"({
    "name": "punched block", "duration": 0.001,
    "solver": {"dt": 0.001, "gravity": [0, 0, 0]},
    "object": {"surface": {"box": {"min": [0, 0, 0], "max": [0.01, 0.01, 0.01]}},
               "material": {"young_modulus": 5e4, "poisson_ratio": 0.45},
               "octree": {"root": {"min": [-0.001, -0.001, -0.001], "size": 0.012}, "base_level": 3, "max_level": 5},
               "material_graph": {"cell_size": 0.001},
               "handles": [{"box": {"min": [-1, -1, -1], "max": [1, 1, 0.0005]}}]},
    "tools": [{"name": "punch", "blade": {"cylinder": {"radius": 0.002, "height": 0.02, "segments": 48}},
               "keyframes": [{"t": 0, "position": [0.005, 0.005, 0.005]}], "cuts": [{"t": 0}]}],
    "render": {"enabled": true, "width": 160, "height": 120, "msaa": 4,
               "camera": {"position": [0.005, -0.008, 0.026], "target": [0.005, 0.005, 0.008], "fov_deg": 40}}
  })");
  World world(load_scene((dir / "scene.json").string()), WorldOptions{.render = true});
  ASSERT_EQ(world.step().cuts.at(0).status, "ok");
  const RenderScene scene = world.render_scene();
  const Image image = render_and_compare("punched_block", scene);
  // The hole shows the background or the inside of the block, never the pink of the top face.
  const auto hole = pixel_at(image, scene.camera, {0.005, 0.005, 0.01});
  const auto top = pixel_at(image, scene.camera, {0.005, 0.0015, 0.01});
  EXPECT_GT(std::abs(hole[1] - top[1]) + std::abs(hole[0] - top[0]), 30);
  // The block is at rest (no gravity), so the truth is exact: every corner of an uncut top-face triangle has the
  // normal +z, and every corner of a cut-wall triangle a horizontal normal. Averaging across the rim would tilt both.
  const RenderMesh& tissue = scene.meshes.at(0);
  ASSERT_EQ(tissue.cut.size(), tissue.triangles.size());
  int top_corners = 0, wall_corners = 0;
  for (std::size_t f = 0; f < tissue.triangles.size(); ++f)
    for (std::int32_t v : tissue.triangles[f]) {
      const Eigen::Vector3f& n = tissue.normals[std::size_t(v)];
      if (tissue.cut[f]) {
        ++wall_corners;
        EXPECT_LT(std::abs(n.z()), 1e-4f) << "cut face " << f;
      } else if (std::abs(tissue.positions[std::size_t(v)].z() - 0.01f) < 1e-7f &&
                 (tissue.positions[std::size_t(tissue.triangles[f][0])].z() + tissue.positions[std::size_t(tissue.triangles[f][1])].z() +
                  tissue.positions[std::size_t(tissue.triangles[f][2])].z()) > 0.03f - 1e-6f) {
        ++top_corners;
        EXPECT_LT((n - Eigen::Vector3f::UnitZ()).norm(), 1e-4f) << "top face " << f;
      }
    }
  EXPECT_GT(top_corners, 100);
  EXPECT_GT(wall_corners, 100);
}

TEST_F(GoldenTest, ArthroscopeMask) {
  RenderScene scene = base_scene();
  scene.meshes.push_back(sphere({0, 0, 0}, 1.2f, 32, 16, MaterialKind::tissue));
  scene.camera.arthroscope = true;
  scene.camera.mask = true;
  scene.camera.mask_radius = 0.9;
  const Image image = render_and_compare("arthroscope", scene);
  // Outside the circle of radius 0.9 * 60 = 54 px around (80, 60): black. Inside: the scene.
  EXPECT_EQ(pixel(image, 0, 0), (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(pixel(image, 80 + 60, 60), (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(pixel(image, 80, 60 - 57), (std::array<int, 3>{0, 0, 0}));
  EXPECT_NE(pixel(image, 80, 60), (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(pixel(image, 80 + 50, 10 + 0), (std::array<int, 3>{0, 0, 0}));  // distance sqrt(50² + 50²) > 54
  EXPECT_EQ(pixel(image, 80 + 45, 60), (std::array<int, 3>{51, 51, 51}));   // inside the circle, off the sphere
}

TEST_F(GoldenTest, MaskedFramesEqualUnmaskedOnesInsideTheCircleAlsoWithABoxBehindTheEye) {
  // With the mask, only the mask's square is multisampled, also when a mesh's box reaches behind the eye (a small box
  // behind the camera here: invisible, but it makes the projected bounds unbounded). Truth: the unmasked frame of the
  // same scene, drawn over the whole frame, inside the circle, and black outside. The sphere covers the circle's rim,
  // so a square clipped too tight would show.
  RenderScene scene = base_scene();
  scene.meshes.push_back(sphere({0, 0, 0}, 1.6f, 48, 24, MaterialKind::tissue));
  scene.meshes.push_back(box({-0.2f, -6.2f, 0.8f}, {0.2f, -5.8f, 1.2f}));  // the camera is at (0, -4, 1)
  scene.camera.arthroscope = true;
  scene.camera.mask = true;
  scene.camera.mask_radius = 0.9;
  RenderScene unmasked = scene;
  unmasked.camera.mask = false;
  const Image a = s_renderer->render(scene), b = s_renderer->render(unmasked);
  const double r = 0.9 * 0.5 * kHeight, cx = 0.5 * kWidth, cy = 0.5 * kHeight;
  long inside = 0, sphere_at_rim = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      // GL window y runs up; the image's rows run down: the circle is symmetric, the centre the same.
      const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
      if (std::abs(d - r) < 1e-3) continue;  // on the circle: float rounding decides
      if (d > r) {
        EXPECT_EQ(pixel(a, x, y), (std::array<int, 3>{0, 0, 0})) << x << ", " << y;
      } else {
        ++inside;
        EXPECT_EQ(pixel(a, x, y), pixel(b, x, y)) << x << ", " << y;
        if (d > r - 2.0 && pixel(b, x, y) != std::array<int, 3>{51, 51, 51}) ++sphere_at_rim;
      }
    }
  EXPECT_GT(inside, 8000);
  EXPECT_GT(sphere_at_rim, 100);
}

TEST_F(GoldenTest, DebugOverlays) {
  RenderScene scene = base_scene();
  scene.meshes.push_back(box({-1.0f, -1.0f, -1.0f}, {1.0f, 1.0f, 1.0f}));
  OverlayLines wire;
  wire.color = Eigen::Vector3f(0.0f, 1.0f, 1.0f);
  for (int k = 0; k < 8; ++k)
    for (const int bit : {1, 2, 4})
      if (!(k & bit)) {
        const auto corner = [](int c) {
          return Eigen::Vector3f(c & 1 ? 1.0f : -1.0f, c & 2 ? 1.0f : -1.0f, c & 4 ? 1.0f : -1.0f);
        };
        wire.endpoints.push_back(corner(k));
        wire.endpoints.push_back(corner(k | bit));
      }
  scene.lines.push_back(wire);
  OverlayPoints dofs;
  dofs.color = Eigen::Vector3f(1.0f, 0.8f, 0.2f);  // 255, 204, 51
  dofs.size_px = 6.0f;
  dofs.points = {{-1.0f, -1.0f, 1.0f}, {1.0f, -1.0f, 1.0f}, {0.0f, 0.0f, 1.0f}, {1.0f, 1.0f, -1.0f}};
  scene.points.push_back(dofs);
  scene.camera.position = {2.5, -4.0, 3.0};
  const Image image = render_and_compare("overlays", scene);
  // Points are drawn on top, unlit: the exact colour at each projected point, even the one behind the box.
  for (const Eigen::Vector3f& p : dofs.points)
    EXPECT_EQ(pixel_at(image, scene.camera, p.cast<double>()), (std::array<int, 3>{255, 204, 51})) << p.transpose();
}

// Lines on top (the contact forces) show through the meshes; depth-tested lines (the octree) do not. A magenta segment
// through the middle of a box: hidden unless on top, where the pixels on it are magenta.
TEST_F(GoldenTest, LinesOnTopShowThroughMeshes) {
  RenderScene scene = base_scene();
  scene.meshes.push_back(box({-1.0f, -1.0f, -1.0f}, {1.0f, 1.0f, 1.0f}));
  scene.camera.position = {2.5, -4.0, 3.0};
  OverlayLines line;
  line.color = Eigen::Vector3f(1.0f, 0.0f, 1.0f);
  line.endpoints = {{-0.6f, 0.0f, 0.0f}, {0.6f, 0.0f, 0.0f}};
  // Magenta pixels within a pixel of the segment's projected middle and quarter points.
  const auto magenta_near = [&](const Image& image) {
    int n = 0;
    for (const double s : {-0.3, 0.0, 0.3}) {
      const Eigen::Vector3d p = project_to_pixel(scene.camera, image.width, image.height, {s, 0.0, 0.0});
      bool found = false;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto c = pixel(image, int(std::floor(p.x())) + dx, int(std::floor(p.y())) + dy);
          found |= c[0] > 200 && c[1] < 60 && c[2] > 200;
        }
      n += found;
    }
    return n;
  };
  scene.lines = {line};
  EXPECT_EQ(magenta_near(s_renderer->render(scene)), 0);
  scene.lines[0].on_top = true;
  EXPECT_EQ(magenta_near(s_renderer->render(scene)), 3);
}

}  // namespace
}  // namespace octocut::engine

namespace octocut::engine {
namespace {

TEST_F(GoldenTest, BadScenesAreErrorsNotCrashes) {
  RenderScene scene = base_scene();
  RenderMesh mesh = sphere({0, 0, 0}, 1.0f, 8, 4, MaterialKind::tissue);
  // A triangle index past the vertices.
  RenderMesh bad_index = mesh;
  bad_index.triangles.push_back({0, 1, int(mesh.positions.size())});
  scene.meshes = {bad_index};
  EXPECT_THROW(s_renderer->render(scene), RenderError);
  // Normals and cut flags that do not match the vertices and triangles.
  RenderMesh bad_normals = mesh;
  bad_normals.normals.pop_back();
  scene.meshes = {bad_normals};
  EXPECT_THROW(s_renderer->render(scene), RenderError);
  RenderMesh bad_cut = mesh;
  bad_cut.cut.assign(3, 1);
  scene.meshes = {bad_cut};
  EXPECT_THROW(s_renderer->render(scene), RenderError);
  // An empty image.
  scene.meshes = {mesh};
  scene.width = 0;
  EXPECT_THROW(s_renderer->render(scene), RenderError);
  // The renderer still works afterwards.
  scene.width = kWidth;
  EXPECT_EQ(s_renderer->render(scene).rgb.size(), std::size_t(3) * kWidth * kHeight);
}

}  // namespace
}  // namespace octocut::engine
