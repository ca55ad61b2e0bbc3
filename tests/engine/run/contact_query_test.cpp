// The distance queries of ContactWorld (a private engine header) against a concave collider mesh, checked against the
// analytic distance to the boundary of an L-shaped prism: collision samples pushed step by step from outside to deep
// inside it (ten times the search depth) keep their contact, and each contact's penetration is the distance to the
// nearest face and its normal points there, on one and on two threads.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "common/temp_dir.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/contact.hpp"
#include "octocut/sim/parallel.hpp"
#include "run/contact_world.hpp"

namespace octocut::engine {
namespace {

using sim::Vec3;

// The L-shaped polygon in the xy plane (cm, counter-clockwise) and the prism's height (cm).
const std::array<std::array<double, 2>, 6> kL = {{{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}}};
constexpr double kHeight = 1.0;

// The prism as an OBJ in cm: bottom and top as two convex quads each, six side quads, outward oriented.
std::string l_prism_obj() {
  std::string s;
  for (const double z : {0.0, kHeight})
    for (const auto& p : kL) s += "v " + std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(z) + "\n";
  // Vertices 1..6 bottom, 7..12 top. Quads (0,1,2,3) and (0,3,4,5) of the polygon.
  s += "f 1 4 3\nf 1 3 2\nf 1 6 5\nf 1 5 4\n";      // bottom, facing -z
  s += "f 7 8 9\nf 7 9 10\nf 7 10 11\nf 7 11 12\n";  // top, facing +z
  for (int i = 0; i < 6; ++i) {
    const int a = 1 + i, b = 1 + (i + 1) % 6;
    s += "f " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(b + 6) + "\n";
    s += "f " + std::to_string(a) + " " + std::to_string(b + 6) + " " + std::to_string(a + 6) + "\n";
  }
  return s;
}

// The nearest point of the 2D segment ab to p.
std::array<double, 2> nearest_on_segment(const std::array<double, 2>& p, const std::array<double, 2>& a,
                                         const std::array<double, 2>& b) {
  const double dx = b[0] - a[0], dy = b[1] - a[1];
  const double t = std::clamp(((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy), 0.0, 1.0);
  return {a[0] + t * dx, a[1] + t * dy};
}

bool in_l(double x, double y) { return x > 0 && y > 0 && ((x < 2 && y < 1) || (x < 1 && y < 2)); }

// For a point inside the prism (cm): the distance to its boundary and the outward direction to the nearest boundary
// point, and the gap to the second-nearest face (to skip points where two faces are about equally near).
struct Truth {
  double distance = 0.0;  // cm
  Vec3 outward = Vec3::Zero();
  double gap = 0.0;  // cm
};
Truth truth(const Vec3& p) {
  std::vector<std::pair<double, Vec3>> faces = {{p.z(), -Vec3::UnitZ()}, {kHeight - p.z(), Vec3::UnitZ()}};
  for (std::size_t i = 0; i < kL.size(); ++i) {
    const auto q = nearest_on_segment({p.x(), p.y()}, kL[i], kL[(i + 1) % kL.size()]);
    const Vec3 d(q[0] - p.x(), q[1] - p.y(), 0.0);
    faces.push_back({d.norm(), d.normalized()});
  }
  std::sort(faces.begin(), faces.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return {faces[0].first, faces[0].second, faces[1].first - faces[0].first};
}

class ContactQuery : public test::TempDirTest {
 protected:
  // A scene whose one rigid body is the fixed mesh `obj` (an OBJ in cm): the L-shaped prism (l_prism_obj) by default.
  Scene fixed_mesh_scene(const std::string& obj = l_prism_obj()) {
    write("body.obj", obj);
    const std::string text = R"({
      "duration": 0.01,
      "object": {"surface": {"box": {"min": [0.05, 0.05, 0.05], "max": [0.06, 0.06, 0.06]}},
                 "octree": {"base_level": 1, "max_level": 1}},
      "rigid_bodies": [{"name": "body", "shape": {"mesh": "body.obj", "scale": 0.01}, "motion": "fixed",
                        "position": [0, 0, 0]}]
    })";
    return load_scene(write("scene.json", text).string());
  }
};

// A sample at p (m) of area `area` (m^2), its own DOF (x: the DOFs' positions, m); samples.begin holds its 0 first.
void add_sample(sim::ContactSamples& samples, std::vector<Vec3>& x, const Vec3& p, double area) {
  if (samples.begin.empty()) samples.begin.push_back(0);
  samples.dofs.push_back({int(x.size()), 1.0});
  samples.begin.push_back(int(samples.dofs.size()));
  samples.rest.push_back(p);
  samples.area.push_back(area);
  samples.face.push_back(-1);
  x.push_back(p);
}

// Samples on a grid over the L's footprint (and a little beyond it, 21 x 21 at 1 mm), 0.2 mm above its top face,
// each its own DOF (x: their positions, m).
void l_grid_samples(sim::ContactSamples& samples, std::vector<Vec3>& x) {
  for (double gx = 0.05; gx < 2.1; gx += 0.1)
    for (double gy = 0.05; gy < 2.1; gy += 0.1)
      add_sample(samples, x, Vec3(0.01 * gx, 0.01 * gy, 0.01 * kHeight + 2e-4), 1e-6);
}

// The contacts `c` of one step against the analytic truth for the grid at positions xs (m): every sample inside the
// L-shaped prism has a contact, at its distance to the prism's boundary and with the outward normal of the nearest
// face, and no other sample has one. Appends the checked contacts' penetrations (m).
void expect_l_contacts(const std::vector<sim::Contact>& c, const std::vector<Vec3>& xs, int step,
                       std::vector<double>& penetrations) {
  std::size_t next = 0;
  for (std::size_t i = 0; i < xs.size(); ++i) {
    const Vec3 cm = 100.0 * xs[i];
    const bool inside = in_l(cm.x(), cm.y()) && cm.z() > 0 && cm.z() < kHeight;
    const bool has = next < c.size() && c[next].dofs[0].dof == int(i);
    const Truth t = inside ? truth(cm) : Truth{};
    // Points within float rounding (Bullet's btScalar) of a face may go either way.
    if (inside && t.distance < 1e-5) {
      if (has) ++next;
      continue;
    }
    ASSERT_EQ(has, inside) << "step " << step << " sample " << i << " at " << cm.transpose() << " cm";
    if (!has) continue;
    const sim::Contact& k = c[next++];
    EXPECT_NEAR(k.penetration, 0.01 * t.distance, 2e-8) << "step " << step << " sample " << i;
    if (t.gap > 1e-3) {
      EXPECT_GT(k.normal.dot(t.outward), 0.9999) << "step " << step << " sample " << i;
    }
    penetrations.push_back(k.penetration);
  }
  EXPECT_EQ(next, c.size());
}

TEST_F(ContactQuery, SamplesPressedDeepIntoAConcaveColliderGetTheirDistanceToItsSurface) {
  const Scene scene = fixed_mesh_scene();
  constexpr double kDepth = 5e-4;  // m, the search depth for samples that were outside
  // Samples on a grid over the L's footprint (and a little beyond it), starting 0.2 mm above the top face and
  // pushed down 0.15 mm per step, 40 steps: to 5.8 mm below the top face (below the prism's middle, where the side
  // walls and the inner corner are the nearest faces).
  sim::ContactSamples samples;
  std::vector<Vec3> x;
  l_grid_samples(samples, x);
  std::vector<std::vector<sim::Contact>> found[2];
  for (const int threads : {1, 2}) {
    ContactWorld world(scene, {}, 1e9, kDepth);
    sim::Executor executor(threads);
    std::vector<Vec3> xs = x;
    for (int step = 0; step < 40; ++step) {
      found[threads - 1].push_back(world.find(samples, xs, 0.001 * step, 0.001, {}, {}, &executor));
      for (Vec3& p : xs) p.z() -= 1.5e-4;
    }
  }
  ASSERT_EQ(found[0].size(), found[1].size());
  std::vector<double> penetrations;  // m, of the contacts checked
  std::vector<Vec3> xs = x;
  for (std::size_t step = 0; step < found[0].size(); ++step) {
    const std::vector<sim::Contact>& c = found[0][step];
    // The same contacts on two threads, in the same order.
    ASSERT_EQ(c.size(), found[1][step].size()) << "step " << step;
    for (std::size_t k = 0; k < c.size(); ++k) {
      ASSERT_EQ(c[k].dofs[0].dof, found[1][step][k].dofs[0].dof);
      ASSERT_EQ(c[k].penetration, found[1][step][k].penetration);
    }
    // Every sample inside the prism has a contact, and no other.
    expect_l_contacts(c, xs, int(step), penetrations);
    if (HasFatalFailure()) return;
    for (Vec3& p : xs) p.z() -= 1.5e-4;
  }
  EXPECT_GT(penetrations.size(), 5000u);
  // Tracked far deeper than the search depth.
  const auto deep = std::count_if(penetrations.begin(), penetrations.end(), [](double d) { return d > 4.0 * kDepth; });
  EXPECT_GT(deep, 1000);
}

// Samples that go through a mesh's surface faster than the search depth per step (a quick stab: 1.5 mm per step
// against a search depth of 0.5 mm) are inside it, deeper than a box of that size finds any triangle: the segment
// since their last query crosses the surface, so they are searched for farther and collide at their distance to the
// surface. Samples over the L's notch fall past it and stay outside.
TEST_F(ContactQuery, SamplesThatGoThroughTheSurfaceFasterThanTheSearchDepthCollide) {
  const Scene scene = fixed_mesh_scene();
  constexpr double kDepth = 5e-4;  // m
  constexpr double kStep = 1.5e-3;  // m per step, three times the search depth
  sim::ContactSamples samples;
  std::vector<Vec3> x;
  l_grid_samples(samples, x);
  ContactWorld world(scene, {}, 1e9, kDepth);
  sim::Executor executor(2);
  std::vector<double> penetrations;  // m, of the contacts checked
  for (int step = 0; step < 6; ++step) {
    const std::vector<sim::Contact> c = world.find(samples, x, 0.001 * step, 0.001, {}, {}, &executor);
    expect_l_contacts(c, x, step, penetrations);
    if (HasFatalFailure()) return;
    for (Vec3& p : x) p.z() -= kStep;
  }
  EXPECT_EQ(penetrations.size(), 5u * 300u);  // the 300 samples over the L, inside it from the second step on
}

// A UV sphere of radius `r` (cm) as an OBJ, outward oriented: `lat` rings of `lon` vertices between the poles.
std::string uv_sphere_obj(double r, int lat, int lon) {
  std::string s = "v 0 0 " + std::to_string(-r) + "\n";  // vertex 1: the south pole
  for (int i = 1; i < lat + 1; ++i) {
    const double th = std::numbers::pi * double(i) / double(lat + 1) - std::numbers::pi / 2;
    for (int j = 0; j < lon; ++j) {
      const double ph = 2.0 * std::numbers::pi * double(j) / double(lon);
      const double x = r * std::cos(th) * std::cos(ph), y = r * std::cos(th) * std::sin(ph), z = r * std::sin(th);
      s += "v " + std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(z) + "\n";
    }
  }
  s += "v 0 0 " + std::to_string(r) + "\n";  // the north pole
  const auto v = [lon](int i, int j) { return 2 + (i - 1) * lon + (j % lon); };  // ring i in 1..lat
  const int north = 2 + lat * lon;
  const auto face = [](int a, int b, int c) {
    return "f " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(c) + "\n";
  };
  for (int j = 0; j < lon; ++j) {
    s += face(1, v(1, j + 1), v(1, j));
    s += face(north, v(lat, j), v(lat, j + 1));
    for (int i = 1; i < lat; ++i)
      s += face(v(i, j), v(i, j + 1), v(i + 1, j + 1)) + face(v(i, j), v(i + 1, j + 1), v(i + 1, j));
  }
  return s;
}

// Numbers in [-1, 1) from a 64-bit linear congruential generator: the same sequence on every platform.
class Uniform {
 public:
  explicit Uniform(std::uint64_t seed) : m_seed(seed) {}
  double operator()() {
    m_seed = m_seed * 6364136223846793005ull + 1442695040888963407ull;
    return double(m_seed >> 11) / double(1ull << 52) - 1.0;
  }

 private:
  std::uint64_t m_seed;
};

// A sample whose nearest triangle of a mesh collider its last box query certified (every other triangle farther than
// the nearest candidate by more than the sample has moved since) is not queried again: its contact must be the one a
// full query gives, bit for bit. Samples 0.05-0.45 mm inside and outside a 1 cm sphere of 0.65 mm triangles slide
// along it, each step by 2 um (most get certified) or, one step in three, by 0.4 mm (farther than the candidates
// reach): a world that keeps its caches against one whose caches are dropped before every step (a box query for
// every sample in the collider's box), on two threads.
TEST_F(ContactQuery, CertifiedNearestTrianglesGiveTheContactsOfFullQueries) {
  const Scene scene = fixed_mesh_scene(uv_sphere_obj(1.0, 48, 96));
  constexpr double kDepth = 1e-3;  // m: the samples stay within half of it of the surface, where a full query (the
                                   // search depth alone) and a tracked one (up to twice the last depth) agree
  constexpr double kRadius = 0.01;  // m
  Uniform uniform(12345);
  sim::ContactSamples samples;
  std::vector<Vec3> x;
  std::vector<double> radius;  // m, each sample's distance from the centre, kept as it slides
  for (int k = 0; k < 2000; ++k) {
    const Vec3 dir = Vec3(uniform(), uniform(), uniform()).normalized();
    radius.push_back(kRadius + 4.5e-4 * uniform());
    if (std::abs(radius.back() - kRadius) < 5e-5) radius.back() = kRadius + 5e-5;
    add_sample(samples, x, radius.back() * dir, 1e-8);
  }
  ContactWorld kept(scene, {}, 1e9, kDepth), fresh(scene, {}, 1e9, kDepth);
  sim::Executor executor(2);
  long certified = 0, searched = 0, contacts = 0;
  for (int step = 0; step < 30; ++step) {
    const double t = 0.001 * step;
    const std::vector<sim::Contact> a = kept.find(samples, x, t, 0.001, {}, {}, &executor);
    certified += kept.profile().certified;
    searched += kept.profile().searched;
    fresh.reset_samples();
    const std::vector<sim::Contact> b = fresh.find(samples, x, t, 0.001, {}, {}, &executor);
    EXPECT_EQ(fresh.profile().certified, 0);
    ASSERT_EQ(a.size(), b.size()) << "step " << step;
    for (std::size_t k = 0; k < a.size(); ++k) {
      ASSERT_EQ(a[k].dofs[0].dof, b[k].dofs[0].dof) << "step " << step;
      EXPECT_EQ(a[k].penetration, b[k].penetration) << "step " << step << " sample " << a[k].dofs[0].dof;
      EXPECT_EQ(a[k].normal, b[k].normal) << "step " << step << " sample " << a[k].dofs[0].dof;
    }
    contacts += long(a.size());
    const double slide = step % 3 == 2 ? 4e-4 : 2e-6;  // m
    for (std::size_t k = 0; k < x.size(); ++k) {
      const Vec3 n = x[k].normalized();
      Vec3 d(uniform(), uniform(), uniform());
      d -= d.dot(n) * n;
      x[k] = radius[k] * (x[k] + slide * d.normalized()).normalized();
    }
  }
  EXPECT_GT(contacts, 10000);
  // Most queries of samples that slid by 2 um are certified; none of those that slid by 0.4 mm.
  EXPECT_GT(certified, searched / 2);
  EXPECT_LT(certified, 2 * searched);
}

// The triangles of an OBJ written in cm (vertices and 1-based faces only), in m, as a box of each: min and max corner.
std::vector<std::array<Vec3, 2>> triangle_boxes(const std::string& obj) {
  std::vector<Vec3> v;
  std::vector<std::array<Vec3, 2>> out;
  std::istringstream in(obj);
  std::string tag;
  while (in >> tag) {
    if (tag == "v") {
      double x = 0, y = 0, z = 0;
      in >> x >> y >> z;
      v.push_back(0.01 * Vec3(x, y, z));
    } else if (tag == "f") {
      int a = 0, b = 0, c = 0;
      in >> a >> b >> c;
      const Vec3 &pa = v[std::size_t(a - 1)], &pb = v[std::size_t(b - 1)], &pc = v[std::size_t(c - 1)];
      out.push_back({pa.cwiseMin(pb).cwiseMin(pc), pa.cwiseMax(pb).cwiseMax(pc)});
    }
  }
  return out;
}

// Bullet pads every triangle's box in its BVH to at least 0.002 units per axis (btOptimizedBvh's MIN_AABB_DIMENSION),
// which is 2 mm for a mesh in metres: a box query of a sub-millimetre search depth then met every triangle within
// about a millimetre of the sample. The queries run on a BVH in finer units: 3,000 samples within 0.3 mm below the
// surface of a 1 cm sphere of 0.65 mm triangles, each queried once (a fresh world) with a cube of half-size 0.3 mm,
// hand the nearest-point test every triangle whose box meets that cube (counted here over all triangles) and at most
// a few more (the BVH's quantisation rounds boxes outward by a fraction of a micrometre): 27,702 against 27,630
// counted, about 9 per sample. With the BVH in metres it was 283,537.
TEST_F(ContactQuery, BoxQueriesTestOnlyTheTrianglesWhoseBoxesMeetTheirCube) {
  const std::string obj = uv_sphere_obj(1.0, 48, 96);
  const Scene scene = fixed_mesh_scene(obj);
  const std::vector<std::array<Vec3, 2>> boxes = triangle_boxes(obj);
  constexpr double kDepth = 3e-4;  // m
  Uniform uniform(2468);
  sim::ContactSamples samples;
  std::vector<Vec3> x;
  long expected = 0;  // triangle boxes that meet the samples' cubes
  for (int k = 0; k < 3000; ++k) {
    const Vec3 p = (0.01 - 1.5e-4 * (1.0 + uniform())) * Vec3(uniform(), uniform(), uniform()).normalized();
    add_sample(samples, x, p, 1e-8);
    for (const auto& b : boxes)
      if ((b[0].array() <= (p.array() + kDepth)).all() && (b[1].array() >= (p.array() - kDepth)).all()) ++expected;
  }
  ContactWorld world(scene, {}, 1e9, kDepth);
  sim::Executor executor(2);
  const std::vector<sim::Contact> contacts = world.find(samples, x, 0.0, 0.001, {}, {}, &executor);
  EXPECT_EQ(world.profile().searched, 3000);  // every sample lies in the sphere's box
  EXPECT_GT(contacts.size(), 2900u);          // all but those just outside a facet (the sphere's sagitta, 5 um)
  EXPECT_GE(world.profile().triangles, expected);
  EXPECT_LE(world.profile().triangles, expected + expected / 50 + 10);
  EXPECT_LT(world.profile().triangles, 15 * 3000);
}

// A regular tetrahedron of 1 cm edges (its dihedral angles 70.5 deg): points 0.2 mm outside it, nearest to an edge or
// a corner, in the directions between the faces there (an edge's or a corner's Voronoi region), are outside and get
// no contact, and points 0.2 mm inside below each face get that face's distance and normal. The side of a point is
// decided by the pseudonormal of the feature nearest to it: a face's normal alone puts a point near a sharp edge
// inside when its nearest triangle is the face it does not lie in front of.
TEST_F(ContactQuery, PointsNearASharpEdgeOrCornerAreOnTheSideItsPseudonormalGives) {
  const std::array<Vec3, 4> v = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, std::sqrt(3.0) / 2, 0),
                                 Vec3(0.5, std::sqrt(3.0) / 6, std::sqrt(2.0 / 3.0))};  // cm
  const std::array<std::array<int, 3>, 4> faces = {{{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {2, 0, 3}}};  // outward
  std::string obj;
  for (const Vec3& p : v)
    obj += "v " + std::to_string(p.x()) + " " + std::to_string(p.y()) + " " + std::to_string(p.z()) + "\n";
  std::array<Vec3, 4> normal;
  for (std::size_t f = 0; f < 4; ++f) {
    const auto& t = faces[f];
    obj += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
    const Vec3 &a = v[std::size_t(t[0])], &b = v[std::size_t(t[1])], &c = v[std::size_t(t[2])];
    normal[f] = (b - a).cross(c - a).normalized();
  }
  const Scene scene = fixed_mesh_scene(obj);
  const auto has = [&](std::size_t f, int a) { return faces[f][0] == a || faces[f][1] == a || faces[f][2] == a; };
  constexpr double kOffset = 2e-4;  // m
  sim::ContactSamples samples;
  std::vector<Vec3> x;
  std::vector<int> inside_face;  // per sample: the face it lies below, or -1 (outside)
  const auto add = [&](const Vec3& p, int face) {
    add_sample(samples, x, p, 1e-8);
    inside_face.push_back(face);
  };
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) {
      std::vector<Vec3> n;  // the normals of the two faces along edge ab
      for (std::size_t f = 0; f < 4; ++f)
        if (has(f, a) && has(f, b)) n.push_back(normal[f]);
      for (const double t : {0.3, 0.5, 0.7})
        for (const double w : {0.1, 0.9}) {
          const Vec3 on = 0.01 * (v[std::size_t(a)] + t * (v[std::size_t(b)] - v[std::size_t(a)]));
          add(on + kOffset * (w * n[0] + (1.0 - w) * n[1]).normalized(), -1);
        }
    }
  for (int a = 0; a < 4; ++a) {
    std::vector<Vec3> n;  // the normals of the three faces at corner a
    for (std::size_t f = 0; f < 4; ++f)
      if (has(f, a)) n.push_back(normal[f]);
    for (int k = 0; k < 3; ++k)
      add(0.01 * v[std::size_t(a)] + kOffset * (0.8 * n[std::size_t(k)] + 0.1 * n[std::size_t((k + 1) % 3)] +
                                                 0.1 * n[std::size_t((k + 2) % 3)]).normalized(), -1);
  }
  for (std::size_t f = 0; f < 4; ++f)
    for (const std::array<double, 3>& w : {std::array<double, 3>{1.0 / 3, 1.0 / 3, 1.0 / 3}, {0.5, 0.3, 0.2}}) {
      const Vec3 on = 0.01 * (w[0] * v[std::size_t(faces[f][0])] + w[1] * v[std::size_t(faces[f][1])] +
                              w[2] * v[std::size_t(faces[f][2])]);
      add(on - kOffset * normal[f], int(f));
    }
  ContactWorld world(scene, {}, 1e9, 5e-4);
  sim::Executor executor(1);
  const std::vector<sim::Contact> c = world.find(samples, x, 0.0, 0.001, {}, {}, &executor);
  std::size_t next = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const bool found = next < c.size() && c[next].dofs[0].dof == int(i);
    EXPECT_EQ(found, inside_face[i] >= 0) << "sample " << i << " at " << (100.0 * x[i]).transpose() << " cm";
    if (!found) continue;
    const sim::Contact& k = c[next++];
    EXPECT_NEAR(k.penetration, kOffset, 1e-9) << "sample " << i;
    EXPECT_GT(k.normal.dot(normal[std::size_t(inside_face[i])]), 0.9999) << "sample " << i;
  }
  EXPECT_EQ(next, c.size());
  EXPECT_EQ(c.size(), 8u);
}

// A cut rebuilds S's collision samples: the samples it leaves keep what the colliders' queries knew of them
// (remap_samples through same_rest_positions). Samples pressed 3 mm into the L-shaped prism (six times the search
// depth, so that a first query would find no triangle and call them outside), then reordered, every seventh
// dropped and new ones added above the prism, go on colliding at their analytic distance to its surface; the new
// ones stay outside. With the caches forgotten (reset_samples, as a cut did before) the pressed samples lose their
// contacts.
TEST_F(ContactQuery, SamplesACutLeavesKeepTheirContactsDeepInsideAMesh) {
  const Scene scene = fixed_mesh_scene();
  constexpr double kDepth = 5e-4;  // m
  sim::ContactSamples samples;
  std::vector<Vec3> x;
  l_grid_samples(samples, x);
  std::size_t kept_contacts = 0;
  for (const bool remap : {true, false}) {
    ContactWorld world(scene, {}, 1e9, kDepth);
    sim::Executor executor(2);
    std::vector<Vec3> xs = x;
    std::vector<double> penetrations;  // m
    for (int step = 0; step < 22; ++step) {
      expect_l_contacts(world.find(samples, xs, 0.001 * step, 0.001, {}, {}, &executor), xs, step, penetrations);
      if (HasFatalFailure()) return;
      for (Vec3& p : xs) p.z() -= 1.5e-4;
    }
    // The cut: the samples in reverse order without every seventh, then 20 new ones 0.2 mm above the top face.
    sim::ContactSamples after;
    std::vector<Vec3> xa;
    for (int i = samples.size() - 1; i >= 0; --i)
      if (i % 7 != 3) {
        add_sample(after, xa, samples.rest[std::size_t(i)], 1e-6);
        xa.back() = xs[std::size_t(i)];
      }
    for (int k = 0; k < 20; ++k) add_sample(after, xa, Vec3(0.0005 + 0.001 * k, 0.0005, 0.01 * kHeight + 2e-4), 1e-6);
    if (remap)
      world.remap_samples(same_rest_positions(samples.rest, after.rest));
    else
      world.reset_samples();
    const std::vector<sim::Contact> c = world.find(after, xa, 0.022, 0.001, {}, {}, &executor);
    if (!remap) {
      // Deeper than the search depth without a history: outside, wrongly, but for those near a side wall.
      EXPECT_LT(5 * c.size(), kept_contacts);
      continue;
    }
    std::vector<double> deep;
    expect_l_contacts(c, xa, 22, deep);
    kept_contacts = deep.size();
    EXPECT_GT(kept_contacts, 250u);
    EXPECT_GT(*std::max_element(deep.begin(), deep.end()), 5.0 * kDepth);
  }
}

}  // namespace
}  // namespace octocut::engine
