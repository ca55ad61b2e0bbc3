#pragma once
// The render scene (rendering issue, SPEC §6): plain data that the world builds from the simulation each rendered
// frame and that a Renderer draws. No GL types: the EGL renderer is a separate target and may be absent.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "octocut/engine/render/camera.hpp"

namespace octocut::engine {

/// How a mesh is shaded.
enum class MaterialKind {
  tissue,  ///< soft tissue: pink Blinn-Phong, cut faces tinted fresh-tissue red
  metal,   ///< instruments: grey, strong narrow highlight
  bone,    ///< the knee context: ivory, dull
  /// clear glass (a rigid body's `"render": "glass"`): what lies behind shows through, faintly blue, with highlights
  /// and a rim that grows opaque at grazing angles (Fresnel); drawn after the opaque meshes, blended, back faces
  /// first, never kept in a renderer's still layer
  glass,
};

/// One triangle mesh to draw. Positions and normals are in the mesh's model space; `model` maps them to world space.
struct RenderMesh {
  std::vector<Eigen::Vector3f> positions;         ///< vertex positions, m (|V|)
  std::vector<Eigen::Vector3f> normals;           ///< unit vertex normals (|V|); empty: computed by the renderer
  std::vector<std::array<std::int32_t, 3>> triangles;  ///< counter-clockwise vertex indices (|F|)
  std::vector<std::uint8_t> cut;                  ///< non-zero for a cut face, tinted (|F|, or empty: none)
  MaterialKind material = MaterialKind::tissue;
  Eigen::Matrix4f model = Eigen::Matrix4f::Identity();  ///< model-to-world transform (rigid, metres)
  /// Skip triangles seen from behind: right for closed, outward-oriented meshes; false for open ones, which are then
  /// lit on both sides.
  bool cull_back_faces = true;
  /// The same in every frame (a prop without keyframes: same vertices, same transform). A renderer may keep what it
  /// drew of such meshes and reuse it while they, the camera, the lights and the image size stay as they were (it
  /// compares them; the flag only says which meshes are worth keeping).
  bool still = false;
};

/// A point light. The first light of an arthroscope camera sits at the lens.
struct RenderLight {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();  ///< world position, m
  Eigen::Vector3f color = Eigen::Vector3f::Ones();     ///< linear RGB intensity, [0, 1] per channel
};

/// Debug line segments (e.g. the octree wireframe), all of one colour.
struct OverlayLines {
  std::vector<Eigen::Vector3f> endpoints;           ///< world positions, m (2 per segment)
  Eigen::Vector3f color = Eigen::Vector3f::Ones();  ///< RGB, [0, 1]
  /// Drawn over the meshes without the depth test (contact forces, which lie inside the tissue or the tool); else
  /// depth-tested against them.
  bool on_top = false;
};

/// Debug points (e.g. DOFs or hanging slots), all of one colour and size.
struct OverlayPoints {
  std::vector<Eigen::Vector3f> points;              ///< world positions, m (|P|)
  Eigen::Vector3f color = Eigen::Vector3f::Ones();  ///< RGB, [0, 1]
  float size_px = 4.0f;                             ///< point diameter, pixels
};

/// Everything one frame shows.
struct RenderScene {
  int width = 1280;   ///< pixels
  int height = 720;   ///< pixels
  int msaa = 4;       ///< samples per pixel; 0 or 1: no multisampling
  Camera camera;
  std::vector<RenderLight> lights;  ///< at most kMaxLights are used; none: a headlight at the camera
  Eigen::Vector3f background = Eigen::Vector3f(0.08f, 0.08f, 0.10f);  ///< clear colour, RGB [0, 1]
  std::vector<RenderMesh> meshes;   ///< tissue first, then tools and context meshes (any number)
  std::vector<OverlayLines> lines;  ///< drawn over the meshes, depth-tested
  std::vector<OverlayPoints> points;  ///< drawn over the meshes, not depth-tested
  /// For each tool of the scene, the index of its mesh in `meshes`, or -1 when it has none (the viewer poses the
  /// tool in the hand itself, at the window's rate). Not used for drawing.
  std::vector<int> tool_meshes;
};

/// Most lights a scene may use.
inline constexpr int kMaxLights = 4;

/// An 8-bit RGB image, rows top to bottom.
struct Image {
  int width = 0;                    ///< pixels
  int height = 0;                   ///< pixels
  std::vector<std::uint8_t> rgb;    ///< 3 * width * height bytes, row-major from the top-left pixel
};

/// Area-weighted unit vertex normals of a mesh (|V|); zero for vertices that only degenerate triangles use.
std::vector<Eigen::Vector3f> mesh_normals(const std::vector<Eigen::Vector3f>& positions,
                                          const std::vector<std::array<std::int32_t, 3>>& triangles);

}  // namespace octocut::engine
