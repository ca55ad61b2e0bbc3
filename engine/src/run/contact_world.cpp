// The rigid side of contact: a Bullet world (issue 16). See contact_world.hpp. Bullet's types stay in this file.
#include "run/contact_world.hpp"

#include <BulletCollision/NarrowPhaseCollision/btGjkEpa2.h>
#include <BulletCollision/NarrowPhaseCollision/btRaycastCallback.h>
#include <BulletCollision/NarrowPhaseCollision/btVoronoiSimplexSolver.h>
#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <unordered_map>

#include "octocut/engine/io/mesh_io.hpp"
#include "octocut/engine/run/scene_object.hpp"
#include "octocut/engine/run/tool.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/parallel.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::engine {

namespace {

using sim::Vec3;

constexpr double kMargin = 1e-4;  // Bullet's collision margin of convex shapes (rigid-rigid contact only), m
// The tissue's queries against a triangle mesh run on a second BVH of the same triangles in units of 1 / kQueryScale
// m ("query units"). Bullet pads every triangle's box in its BVH to at least 0.002 units per axis
// (btOptimizedBvh's MIN_AABB_DIMENSION, meant for objects a metre in size): in metres that is 2 mm, larger than the
// bones' and the punch's triangles: a box query of the search depth in meniscus_punch tested 6.7-72 triangles on
// average (per collider), against 0.55-10.6 here. The scale is a power of two, so every coordinate, distance and
// comparison scales exactly, and a query gives the result it gives in metres, bit for bit.
constexpr double kQueryScale = 131072.0;  // 2^17: the pad becomes 15 nm

// Triangles this thread has handed to the nearest-point test (NearestTriangle::processTriangle), for
// ContactProfile::triangles.
thread_local long t_triangles = 0;

btVector3 bt(const Vec3& v) { return {v.x(), v.y(), v.z()}; }
Vec3 from_bt(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

btTransform bt(const sim::Pose& p) {
  const sim::Mat3& r = p.rotation;
  btMatrix3x3 basis(r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1), r(1, 2), r(2, 0), r(2, 1), r(2, 2));
  return btTransform(basis, bt(p.position));
}

sim::Pose from_bt(const btTransform& t) {
  sim::Pose p;
  p.position = from_bt(t.getOrigin());
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) p.rotation(i, j) = t.getBasis()[i][j];
  return p;
}

sim::Pose initial_pose(const std::array<double, 3>& position, const std::array<double, 3>& rotation_deg) {
  sim::Pose p;
  p.position = to_vec3(position);
  p.rotation = sim::euler_xyz_deg(to_vec3(rotation_deg));
  return p;
}

// A collider mesh, loaded and checked as a solid (closed, oriented, free of self-intersections).
sim::TriMesh load_collider(const Scene& scene, const std::string& path, double scale, const std::string& pointer) {
  try {
    return load_mesh(path, MeshLoadOptions{scale, true, true}).mesh;
  } catch (const MeshError& e) {
    throw SceneError(scene.file + ": " + pointer + ": " + e.what());
  }
}

// What a box query of a triangle mesh proved about the triangles near a sample: at the local point `anchor` (query
// units, as all distances here), the `count` triangles `candidates` (in the order the query visited them) were the
// nearest, and every other triangle lay at least `margin` away (the nearest of those found, or the box's half-size
// for the ones it did not visit: a triangle outside the cube lies farther than its half-size). Once the sample has
// moved by delta from the anchor, every other triangle lies at least margin - delta away; while the nearest
// candidate is nearer than that, a box query would find it, with its ties broken the same way (the candidates are
// visited in the query's order), and give the same distance, normal and clearance (the same corners and
// arithmetic): the query can be left out without changing any result. margin < 0: none.
struct NearestCertificate {
  static constexpr int kCandidates = 8;  // a vertex of the bones' meshes has 5-8 triangles around it
  btVector3 anchor{0, 0, 0};             // in the mesh's frame, query units (kQueryScale)
  std::array<int, kCandidates> candidates{};
  int count = 0;
  double margin = -1.0;  // query units
};

// One rigid shape in the Bullet world.
struct Collider {
  ColliderState state;
  std::unique_ptr<btCollisionShape> shape;        // Bullet's shape, which the tissue is queried against when convex
  std::unique_ptr<btCollisionShape> hull;         // a dynamic mesh body's convex hull (Bullet's rigid contact)
  std::unique_ptr<btTriangleIndexVertexArray> mesh_array;
  std::unique_ptr<btTriangleIndexVertexArray> query_array;  // the same triangles, in query units (kQueryScale)
  std::unique_ptr<btBvhTriangleMeshShape> query_bvh;        // the BVH of query_array
  std::vector<btScalar> vertices;                 // 3 |V|, m, kept alive for mesh_array and query_array
  std::vector<int> triangles;                     // 3 |F|
  btBvhTriangleMeshShape* concave = nullptr;      // query_bvh, when the shape is a triangle mesh
  btConvexShape* convex = nullptr;                // shape, when it is convex
  std::unique_ptr<btDefaultMotionState> motion;
  std::unique_ptr<btRigidBody> body;
  bool dynamic = false;
  bool kinematic = false;                         // follows keyframes (tools and kinematic bodies)
  std::vector<sim::PoseKeyframe> keyframes;       // kinematic bodies
  double friction = 0.0;
  Vec3 force = Vec3::Zero();                      // on the collider, this step, N
  Vec3 torque = Vec3::Zero();                     // about its centre of mass, N m
  std::vector<Vec3> cache_local;                  // per sample: local position at its last query, m
  std::vector<double> cache_clearance;            // per sample: distance known free of the surface there, m
  std::vector<double> last_depth;                 // per sample: its penetration at the last query, m (0: none)
  std::vector<NearestCertificate> certificate;    // per sample (triangle meshes): its nearest triangles, see there
  // The mesh's angle-weighted pseudonormals (Baerentzen and Aanaes 2005), in its frame: per triangle edge k (corners
  // k, k + 1) the sum of its two faces' unit normals, per vertex the sum of its faces' unit normals weighted by their
  // angles there (a face's own is its normal). A point lies inside a closed mesh when its offset from its nearest
  // point on the surface points against the pseudonormal of the feature (face, edge or vertex) that point lies on; a
  // face's normal alone misjudges points nearest to a sharp edge or vertex.
  std::vector<btVector3> edge_normals;    // 3 |F|
  std::vector<btVector3> vertex_normals;  // |V|

  // Forgets the per-sample caches above (the next query sizes them afresh).
  void forget_samples() {
    cache_local.clear();
    cache_clearance.clear();
    last_depth.clear();
    certificate.clear();
  }

  // Triangle `index`'s corners in the mesh's frame, in query units, as Bullet hands them to a query (its vertex
  // times the query mesh's scaling; btStridingMeshInterface's processing of a double-precision vertex array).
  [[nodiscard]] std::array<btVector3, 3> corners(int index) const {
    const btVector3& s = query_array->getScaling();
    std::array<btVector3, 3> out;
    for (int k = 0; k < 3; ++k) {
      const btScalar* v = &vertices[3 * std::size_t(triangles[3 * std::size_t(index) + std::size_t(k)])];
      out[std::size_t(k)] = btVector3(v[0] * s.getX(), v[1] * s.getY(), v[2] * s.getZ());
    }
    return out;
  }
};

// The nearest triangle of a concave mesh to a local point (query units, as all its distances), through Bullet's BVH
// and Bullet's closed-form closest point on a triangle (btVoronoiSimplexSolver::closestPtPointTriangle, the
// Voronoi-region test GJK's simplex solver uses; a full GJK per triangle cost 3-4 times as much and gave the same
// point). Also keeps the certificate's candidates: the kCandidates nearest triangles visited, and the distance of the
// nearest other one (`outside`).
struct NearestTriangle : btTriangleCallback {
  static constexpr int K = NearestCertificate::kCandidates;
  btVector3 point;
  double best = std::numeric_limits<double>::infinity();
  btVector3 closest{0, 0, 0};
  btVector3 face_normal{0, 0, 1};
  btVoronoiSimplexSolver simplex;
  // The candidates, nearest first: distance, triangle index and visit number.
  std::array<double, K> near_dist{};
  std::array<int, K> near_index{};
  std::array<int, K> near_visit{};
  int kept = 0;
  int visits = 0;
  double outside = std::numeric_limits<double>::infinity();  // m
  const Collider* mesh = nullptr;  // the collider whose triangles these are (its pseudonormals)

  void processTriangle(btVector3* tri, int, int index) override {
    ++t_triangles;
    btSubSimplexClosestResult r;
    simplex.closestPtPointTriangle(point, tri[0], tri[1], tri[2], r);
    const double dist = double((point - r.m_closestPointOnSimplex).length());
    if (dist < best) {
      best = dist;
      closest = dist > 0.0 ? r.m_closestPointOnSimplex : point;
      face_normal = pseudonormal(tri, index, r.m_usedVertices);
    }
    keep(dist, index, visits++);
  }
  // The pseudonormal of the feature of triangle `index` (corners `tri`) that the nearest point lies on: the
  // triangle's face when all three corners span it, the edge of the two, or the corner (see Collider). Without the
  // collider's pseudonormals, the face's normal.
  [[nodiscard]] btVector3 pseudonormal(const btVector3* tri, int index, const btUsageBitfield& used) const {
    const btVector3 face = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    if (mesh == nullptr || mesh->edge_normals.empty()) return face;
    const bool a = used.usedVertexA, b = used.usedVertexB, cc = used.usedVertexC;
    const auto f = std::size_t(index);
    if (a + b + cc == 2) return mesh->edge_normals[3 * f + (a && b ? 0 : b && cc ? 1 : 2)];
    if (a + b + cc == 1) return mesh->vertex_normals[std::size_t(mesh->triangles[3 * f + (a ? 0 : b ? 1 : 2)])];
    return face;
  }
  void keep(double dist, int index, int visit) {
    if (kept == K && !(dist < near_dist[K - 1])) {
      outside = std::min(outside, dist);
      return;
    }
    if (kept == K) outside = std::min(outside, near_dist[K - 1]);
    int at = kept == K ? K - 1 : kept++;
    for (; at > 0 && dist < near_dist[std::size_t(at) - 1]; --at) {
      near_dist[std::size_t(at)] = near_dist[std::size_t(at) - 1];
      near_index[std::size_t(at)] = near_index[std::size_t(at) - 1];
      near_visit[std::size_t(at)] = near_visit[std::size_t(at) - 1];
    }
    near_dist[std::size_t(at)] = dist;
    near_index[std::size_t(at)] = index;
    near_visit[std::size_t(at)] = visit;
  }
  // The certificate of this query of a box of half-size `box` (m).
  [[nodiscard]] NearestCertificate certificate(double box) const {
    NearestCertificate out;
    out.anchor = point;
    out.count = kept;
    std::array<int, K> visit{};  // the candidates in visit order (an insertion sort of at most K)
    for (int k = 0; k < kept; ++k) {
      int at = k;
      for (; at > 0 && near_visit[std::size_t(k)] < visit[std::size_t(at) - 1]; --at) {
        visit[std::size_t(at)] = visit[std::size_t(at) - 1];
        out.candidates[std::size_t(at)] = out.candidates[std::size_t(at) - 1];
      }
      visit[std::size_t(at)] = near_visit[std::size_t(k)];
      out.candidates[std::size_t(at)] = near_index[std::size_t(k)];
    }
    out.margin = std::min(outside, box);
    return out;
  }
};

// The signed distance, normal (world, unit, out of the collider) and clearance of a box query's nearest triangle
// (cb.best below the box's half-size); see signed_distance.
double nearest_result(const NearestTriangle& cb, const btTransform& pose, Vec3& normal, double& clearance) {
  const btVector3 away = cb.point - cb.closest;
  const bool inside = away.dot(cb.face_normal) < 0;
  const double best = cb.best / kQueryScale;  // m
  clearance = inside ? 0.0 : best;
  btVector3 n = best > 1e-12 ? (inside ? -away : away) : cb.face_normal;
  n.normalize();
  normal = from_bt(pose.getBasis() * n);
  return inside ? -best : best;
}

// The signed distance of a world point to a collider at `pose`: < 0 inside. `normal` (world, unit) points out of
// the collider. `clearance` gets a distance the point may move (in the collider's frame) and stay outside.
double signed_distance(const Collider& c, const btTransform& pose, const Vec3& p, double depth, Vec3& normal,
                       double& clearance, NearestCertificate* certificate = nullptr) {
  if (certificate) certificate->margin = -1.0;
  if (c.convex) {
    btGjkEpaSolver2::sResults r;
    const double d = btGjkEpaSolver2::SignedDistance(bt(p), 0, c.convex, pose, r);
    if (!std::isfinite(d)) {
      clearance = 0.0;
      return 1.0;
    }
    normal = from_bt(r.normal);
    clearance = std::max(0.0, d);
    return d;
  }
  NearestTriangle cb;
  cb.mesh = &c;
  cb.point = kQueryScale * pose.invXform(bt(p));
  const double box = kQueryScale * depth;  // query units
  const btVector3 e(box, box, box);
  c.concave->processAllTriangles(&cb, cb.point - e, cb.point + e);
  if (!(cb.best < box)) {
    clearance = depth;  // nothing within the cube of half-size depth: nothing within depth
    return depth;
  }
  if (certificate) *certificate = cb.certificate(box);
  return nearest_result(cb, pose, normal, clearance);
}

// The crossings of a segment with a mesh collider's surface, in its frame: Bullet's ray test against the BVH, every
// triangle the segment meets counted (the callback keeps the whole segment).
struct SurfaceCrossings : btTriangleRaycastCallback {
  int count = 0;
  SurfaceCrossings(const btVector3& from, const btVector3& to) : btTriangleRaycastCallback(from, to) {}
  btScalar reportHit(const btVector3&, btScalar, int, int) override {
    ++count;
    return m_hitFraction;
  }
};

// signed_distance with no limit on the distance: box queries of half-size `from` (m), each twice the last, until one
// finds a triangle nearer than its half-size or holds the whole mesh. For a sample that went through a mesh's surface
// faster than the search depth per step.
double nearest_anywhere(const Collider& c, const btTransform& pose, const Vec3& p, double from, Vec3& normal,
                        double& clearance, NearestCertificate* certificate) {
  btVector3 lo, hi;
  c.concave->getAabb(btTransform::getIdentity(), lo, hi);
  const btVector3 point = kQueryScale * pose.invXform(bt(p));
  double reach = 0.0;  // a cube of this half-size around the point holds the mesh (query units, then m)
  for (int k = 0; k < 3; ++k) reach = std::max({reach, double(point[k] - lo[k]), double(hi[k] - point[k])});
  reach /= kQueryScale;
  if (!std::isfinite(reach) || !(from > 0.0)) return signed_distance(c, pose, p, from, normal, clearance, certificate);
  for (double box = from;; box *= 2.0) {
    const double d = signed_distance(c, pose, p, std::min(box, reach), normal, clearance, certificate);
    if (d < std::min(box, reach) || box >= reach) return d;
  }
}

// signed_distance for a sample whose penetration at its last query was `last` (m; 0: it was outside), searched
// within `depth` (m) when it was outside. A sample inside a triangle mesh is followed deeper, so that a tool pressing
// on keeps it: first within 1.25 `last` (the nearest triangle found there is the nearest within any larger cube, the
// same triangle and the same tie-break, since the box query visits a subset in the same order), and only when
// nothing is that near within 2 `last`.
double tracked_distance(const Collider& c, const btTransform& pose, const Vec3& p, double depth, double last,
                        Vec3& normal, double& clearance, NearestCertificate* certificate, bool& certified) {
  certified = false;
  const double deep = std::max(depth, 2.0 * last);  // m
  const double near = std::max(depth, 1.25 * last);  // m
  if (c.convex == nullptr && certificate && certificate->margin > 0.0) {
    // The box queries below would find the certificate's nearest candidate (see NearestCertificate): it is nearer
    // than any other triangle and than `deep`, so either the first query finds it (nearer than `near`) or the first
    // finds nothing nearer than `near` and the second finds it.
    NearestTriangle cb;
    cb.mesh = &c;
    cb.point = kQueryScale * pose.invXform(bt(p));
    const double moved = double((cb.point - certificate->anchor).length());  // query units
    for (int k = 0; k < certificate->count; ++k) {
      const int index = certificate->candidates[std::size_t(k)];
      std::array<btVector3, 3> corners = c.corners(index);
      cb.processTriangle(corners.data(), 0, index);
    }
    // The slack covers the rounding of the distances (about 1e-16 of the coordinates, here 1e-18 m).
    constexpr double kSlack = 1e-12 * kQueryScale;  // query units
    if (cb.best + moved + kSlack < certificate->margin && cb.best < kQueryScale * deep) {
      certified = true;
      return nearest_result(cb, pose, normal, clearance);
    }
  }
  if (c.convex == nullptr && near < deep) {
    const double d = signed_distance(c, pose, p, near, normal, clearance, certificate);
    if (d < near) return d;
  }
  return signed_distance(c, pose, p, deep, normal, clearance, certificate);
}

}  // namespace

bool scene_collides(const Scene& scene) {
  if (!scene.rigid_bodies.empty()) return true;
  for (const ToolSettings& t : scene.tools)
    if (t.collide) return true;
  for (const RenderProp& p : scene.render.props)
    if (p.collide) return true;
  return false;
}

double default_contact_stiffness(double young_modulus, double finest_leaf) { return 10.0 * young_modulus / finest_leaf; }

struct ContactWorld::Impl {
  const Scene& scene;
  double stiffness = 0.0;  // Pa/m
  double depth = 0.0;      // m
  std::vector<Collider> colliders;
  std::vector<ColliderState> states;
  ContactProfile profile;
  double max_penetration = 0.0;
  std::size_t samples = 0;

  // This step's contacts: which collider and world point each has.
  struct ContactRef {
    std::size_t collider;
    Vec3 point;
  };
  std::vector<ContactRef> refs;

  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher{&config};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world{&dispatcher, &broadphase, &solver, &config};

  Impl(const Scene& s, double k, double d) : scene(s), stiffness(k), depth(d) {}
  ~Impl() {
    for (Collider& c : colliders)
      if (c.body) world.removeRigidBody(c.body.get());
  }
  void set_mesh(Collider& c, const sim::TriMesh& mesh);
  static void set_pseudonormals(Collider& c);
  void add(Collider c, double mass, const sim::Pose& pose);
  [[nodiscard]] sim::Pose pose_at(const Collider& c, double t, const std::vector<sim::Pose>& tools) const;

  // One collider's frame for this step's queries (ContactWorld::find).
  struct QueryFrame {
    sim::Pose pose, pose_next;  // at t and t + dt
    btTransform tr;             // pose, Bullet's
    btVector3 lo, hi;           // Bullet's bounding box of the shape at pose, m
    Vec3 near_lo, near_hi;      // that box grown by what a sample can cover relative to the shape in a step, m
    btVector3 com;              // a dynamic body's centre of mass, m
  };
  // What one chunk of queries found.
  struct Found {
    std::vector<sim::Contact> contacts;
    std::vector<ContactRef> refs;
    double max_penetration = 0.0;  // m
    long searched = 0, certified = 0, triangles = 0;
  };
  // The frame of collider ci for n samples at t (sizes its caches for them).
  QueryFrame frame_of(std::size_t ci, int n, double t, double dt, const std::vector<sim::Pose>& now,
                      const std::vector<sim::Pose>& next);
  // Appends to `out` the samples of [b, e) that collider ci must query (ascending); remembers those just outside its
  // box as outside.
  void scan(std::size_t ci, const QueryFrame& f, const std::vector<Vec3>& positions, int b, int e,
            std::vector<int>& out);
  // Queries sample i against collider ci: updates its cache entries and adds its contact, if any, to `found`.
  void query_sample(std::size_t ci, const QueryFrame& f, const sim::ContactSamples& samples,
                    const std::vector<Vec3>& positions, int i, double dt, Found& found);
};

void ContactWorld::Impl::set_mesh(Collider& c, const sim::TriMesh& mesh) {
  for (const Vec3& p : mesh.vertices)
    for (int k = 0; k < 3; ++k) c.vertices.push_back(p[k]);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) c.triangles.push_back(t[std::size_t(k)]);
  c.mesh_array = std::make_unique<btTriangleIndexVertexArray>(int(mesh.triangles.size()), c.triangles.data(),
                                                              3 * int(sizeof(int)), int(mesh.vertices.size()),
                                                              c.vertices.data(), 3 * int(sizeof(btScalar)));
  auto bvh = std::make_unique<btBvhTriangleMeshShape>(c.mesh_array.get(), true);
  bvh->setMargin(kMargin);
  c.shape = std::move(bvh);
  c.query_array = std::make_unique<btTriangleIndexVertexArray>(int(mesh.triangles.size()), c.triangles.data(),
                                                               3 * int(sizeof(int)), int(mesh.vertices.size()),
                                                               c.vertices.data(), 3 * int(sizeof(btScalar)));
  c.query_array->setScaling(btVector3(kQueryScale, kQueryScale, kQueryScale));
  c.query_bvh = std::make_unique<btBvhTriangleMeshShape>(c.query_array.get(), true);
  c.query_bvh->setMargin(kQueryScale * kMargin);  // getAabb's margin, as the world's shape has it
  c.concave = c.query_bvh.get();
  set_pseudonormals(c);
}

void ContactWorld::Impl::set_pseudonormals(Collider& c) {
  const std::size_t nf = c.triangles.size() / 3;
  c.edge_normals.assign(3 * nf, btVector3(0, 0, 0));
  c.vertex_normals.assign(c.vertices.size() / 3, btVector3(0, 0, 0));
  std::unordered_map<std::uint64_t, btVector3> edges;  // (lower vertex, higher vertex) -> sum of its faces' normals
  const auto key = [&](std::size_t f, int k) {
    const auto a = std::uint32_t(c.triangles[3 * f + std::size_t(k)]);
    const auto b = std::uint32_t(c.triangles[3 * f + std::size_t((k + 1) % 3)]);
    return (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
  };
  for (std::size_t f = 0; f < nf; ++f) {
    const std::array<btVector3, 3> x = c.corners(int(f));
    btVector3 n = (x[1] - x[0]).cross(x[2] - x[0]);
    if (!(n.length2() > 0.0)) continue;  // a degenerate face has no side
    n.normalize();
    for (int k = 0; k < 3; ++k) {
      edges.try_emplace(key(f, k), 0, 0, 0).first->second += n;
      const btVector3 u = x[std::size_t((k + 1) % 3)] - x[std::size_t(k)];
      const btVector3 w = x[std::size_t((k + 2) % 3)] - x[std::size_t(k)];
      const double angle = std::atan2(double(u.cross(w).length()), double(u.dot(w)));
      c.vertex_normals[std::size_t(c.triangles[3 * f + std::size_t(k)])] += btScalar(angle) * n;
    }
  }
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k)
      if (const auto e = edges.find(key(f, k)); e != edges.end()) c.edge_normals[3 * f + std::size_t(k)] = e->second;
}

void ContactWorld::Impl::add(Collider c, double mass, const sim::Pose& pose) {
  btCollisionShape* rigid_shape = c.hull ? c.hull.get() : c.shape.get();
  btVector3 inertia(0, 0, 0);
  if (c.dynamic) rigid_shape->calculateLocalInertia(mass, inertia);
  c.motion = std::make_unique<btDefaultMotionState>(bt(pose));
  btRigidBody::btRigidBodyConstructionInfo info(c.dynamic ? mass : 0.0, c.motion.get(), rigid_shape, inertia);
  info.m_friction = c.friction;
  c.body = std::make_unique<btRigidBody>(info);
  if (c.kinematic) c.body->setCollisionFlags(c.body->getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  c.body->setActivationState(DISABLE_DEACTIVATION);
  world.addRigidBody(c.body.get());
  c.state.pose = pose;
  colliders.push_back(std::move(c));
}

sim::Pose ContactWorld::Impl::pose_at(const Collider& c, double t, const std::vector<sim::Pose>& tools) const {
  if (c.state.kind == ColliderState::Kind::tool) return tools.at(c.state.index);
  if (c.kinematic) return sim::interpolate_pose(c.keyframes, t);
  if (c.dynamic) return from_bt(c.body->getWorldTransform());
  btTransform tr;
  c.motion->getWorldTransform(tr);
  return from_bt(tr);
}

// function-length: the three kinds of collider, each a few lines
ContactWorld::ContactWorld(const Scene& scene, const std::vector<sim::TriMesh>& tool_shapes, double stiffness,
                           double search_depth)
    : m(std::make_unique<Impl>(scene, stiffness, search_depth)) {
  const sim::Vec3 g = to_vec3(scene.solver.gravity);
  m->world.setGravity(bt(g));
  // Kinematic tools: their mesh (or blade mesh), or their cylinder blade.
  for (std::size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSettings& t = scene.tools[i];
    if (!t.collide) continue;
    Collider c;
    c.state.name = t.name;
    c.state.kind = ColliderState::Kind::tool;
    c.state.index = i;
    c.kinematic = true;
    c.friction = t.friction;
    if (!tool_shapes.at(i).triangles.empty()) {
      m->set_mesh(c, tool_shapes[i]);
    } else {
      auto cyl = std::make_unique<btCylinderShapeZ>(btVector3(t.cylinder.radius, t.cylinder.radius, 0.5 * t.cylinder.height));
      cyl->setMargin(std::min(kMargin, 0.1 * t.cylinder.radius));
      c.convex = cyl.get();
      c.shape = std::move(cyl);
    }
    m->add(std::move(c), 0.0, tool_pose(t, 0.0));
  }
  // Static colliders: props with `collide`, at their pose at t = 0.
  for (std::size_t i = 0; i < scene.render.props.size(); ++i) {
    const RenderProp& p = scene.render.props[i];
    if (!p.collide) continue;
    Collider c;
    c.state.name = p.name;
    c.state.kind = ColliderState::Kind::prop;
    c.state.index = i;
    c.friction = scene.contact.friction;
    m->set_mesh(c, load_collider(scene, p.mesh_path, p.scale, "/render/props/" + std::to_string(i) + "/mesh"));
    m->add(std::move(c), 0.0, sim::interpolate_pose(pose_keyframes(p.keyframes), 0.0));
  }
  // Rigid bodies.
  for (std::size_t i = 0; i < scene.rigid_bodies.size(); ++i) {
    const RigidBodySettings& b = scene.rigid_bodies[i];
    Collider c;
    c.state.name = b.name;
    c.state.kind = ColliderState::Kind::body;
    c.state.index = i;
    c.dynamic = b.motion == "dynamic";
    c.kinematic = b.motion == "kinematic";
    c.keyframes = pose_keyframes(b.keyframes);
    c.friction = b.friction;
    const RigidShape& s = b.shape;
    std::unique_ptr<btConvexShape> convex;
    if (s.kind == "sphere") convex = std::make_unique<btSphereShape>(s.radius);
    if (s.kind == "box") convex = std::make_unique<btBoxShape>(0.5 * btVector3(s.size[0], s.size[1], s.size[2]));
    if (s.kind == "cylinder") convex = std::make_unique<btCylinderShapeZ>(btVector3(s.radius, s.radius, 0.5 * s.height));
    if (convex) {
      if (s.kind != "sphere") convex->setMargin(kMargin);
      c.convex = convex.get();
      c.shape = std::move(convex);
    } else {
      const sim::TriMesh mesh =
          load_collider(scene, s.mesh_path, s.scale, "/rigid_bodies/" + std::to_string(i) + "/shape/mesh");
      m->set_mesh(c, mesh);
      if (c.dynamic) {
        auto hull = std::make_unique<btConvexHullShape>();
        for (const Vec3& p : mesh.vertices) hull->addPoint(bt(p), false);
        hull->recalcLocalAabb();
        hull->setMargin(kMargin);
        c.hull = std::move(hull);
      }
    }
    const sim::Pose pose = c.kinematic ? sim::interpolate_pose(c.keyframes, 0.0) : initial_pose(b.position, b.rotation_deg);
    m->add(std::move(c), b.mass, pose);
  }
  for (const Collider& c : m->colliders) m->states.push_back(c.state);
}

ContactWorld::~ContactWorld() = default;

ContactWorld::Impl::QueryFrame ContactWorld::Impl::frame_of(std::size_t ci, int n, double t, double dt,
                                                           const std::vector<sim::Pose>& now,
                                                           const std::vector<sim::Pose>& next) {
  Collider& c = colliders[ci];
  QueryFrame f;
  f.pose = pose_at(c, t, now);
  f.pose_next = c.kinematic ? pose_at(c, t + dt, next) : f.pose;
  f.tr = bt(f.pose);
  c.shape->getAabb(f.tr, f.lo, f.hi);
  // The box grown by what a sample can cover relative to the shape in a step: the search depth several times over
  // and twice the shape's own step (m).
  const double grow = 4.0 * depth + 2.0 * (f.pose_next.position - f.pose.position).norm();
  f.near_lo = from_bt(f.lo) - Vec3::Constant(grow);
  f.near_hi = from_bt(f.hi) + Vec3::Constant(grow);
  if (c.cache_local.size() != std::size_t(n)) {
    c.cache_local.assign(std::size_t(n), Vec3::Zero());
    c.cache_clearance.assign(std::size_t(n), -1.0);
    c.last_depth.assign(std::size_t(n), 0.0);
    c.certificate.assign(c.concave ? std::size_t(n) : 0, NearestCertificate{});
  }
  f.com = c.dynamic ? c.body->getCenterOfMassPosition() : btVector3(0, 0, 0);
  return f;
}

void ContactWorld::Impl::scan(std::size_t ci, const QueryFrame& f, const std::vector<Vec3>& positions, int b, int e,
                              std::vector<int>& out) {
  Collider& c = colliders[ci];
  const btVector3 &lo = f.lo, &hi = f.hi;
  for (int i = b; i < e; ++i) {
    const Vec3& p = positions[std::size_t(i)];
    if (p.x() < lo.x() || p.y() < lo.y() || p.z() < lo.z() || p.x() > hi.x() || p.y() > hi.y() || p.z() > hi.z()) {
      // Outside the shape's box but near it, and not seen yet: remembered as outside there (in the collider's
      // frame), at least its distance from the box away from the surface, so that a sample that enters the mesh
      // deeper than the search depth within one step is found (see query_sample).
      if (c.concave && c.cache_clearance[std::size_t(i)] < 0.0 && p.x() >= f.near_lo.x() && p.y() >= f.near_lo.y() &&
          p.z() >= f.near_lo.z() && p.x() <= f.near_hi.x() && p.y() <= f.near_hi.y() && p.z() <= f.near_hi.z()) {
        const Vec3 gap = (from_bt(lo) - p).cwiseMax(p - from_bt(hi)).cwiseMax(0.0);
        c.cache_local[std::size_t(i)] = f.pose.rotation.transpose() * (p - f.pose.position);
        c.cache_clearance[std::size_t(i)] = gap.norm();
        c.last_depth[std::size_t(i)] = 0.0;
      }
      continue;
    }
    const Vec3 local = f.pose.rotation.transpose() * (p - f.pose.position);
    const double clearance = c.cache_clearance[std::size_t(i)];
    if (clearance > 0.0 && (local - c.cache_local[std::size_t(i)]).norm() < clearance) continue;
    out.push_back(i);
  }
}

void ContactWorld::Impl::query_sample(std::size_t ci, const QueryFrame& f, const sim::ContactSamples& samples,
                                      const std::vector<Vec3>& positions, int i, double dt, Found& found) {
  Collider& c = colliders[ci];
  const Vec3& p = positions[std::size_t(i)];
  const Vec3 local = f.pose.rotation.transpose() * (p - f.pose.position);
  Vec3 normal = Vec3::UnitZ();
  double& last = c.last_depth[std::size_t(i)];
  bool certified = false;
  NearestCertificate* certificate = c.concave ? &c.certificate[std::size_t(i)] : nullptr;
  double& clearance = c.cache_clearance[std::size_t(i)];
  const bool was_outside = last == 0.0 && clearance >= 0.0;  // at its last query, at cache_local
  const double was_clear = clearance;                          // m, free of the surface around cache_local
  const long tested = t_triangles;
  double d = tracked_distance(c, f.tr, p, depth, last, normal, clearance, certificate, certified);
  ++(certified ? found.certified : found.searched);
  const double searched = std::max(depth, 2.0 * last);  // m, the largest box tracked_distance searched
  if (c.concave && d >= searched && (last > 0.0 || was_outside)) {
    // Nothing within the box searched, for a sample that was inside (it went deeper than twice its depth in a
    // step), or that was outside and went through the surface since (then it may be inside, deeper than the
    // search looks): its nearest triangle, wherever it is, decides, by the side of its face the sample is on,
    // as for every sample (not the crossings' parity, which a segment through an edge miscounts). A segment
    // that starts was_clear away from the surface and ends `depth` away from it can reach the surface only if
    // it is at least as long as both together.
    bool through = last > 0.0;
    if (!through && (local - c.cache_local[std::size_t(i)]).norm() >= was_clear + depth) {
      SurfaceCrossings crossings(bt(kQueryScale * c.cache_local[std::size_t(i)]), bt(kQueryScale * local));
      c.concave->performRaycast(&crossings, crossings.m_from, crossings.m_to);
      through = crossings.count > 0;
    }
    if (through) d = nearest_anywhere(c, f.tr, p, 2.0 * searched, normal, clearance, certificate);
  }
  found.triangles += t_triangles - tested;
  c.cache_local[std::size_t(i)] = local;
  last = d < 0.0 ? -d : 0.0;
  if (!(d < 0.0)) return;
  sim::Contact k;
  k.dofs.assign(samples.dofs.begin() + samples.begin[std::size_t(i)],
                samples.dofs.begin() + samples.begin[std::size_t(i) + 1]);
  k.normal = normal;
  k.penetration = -d;
  k.stiffness = stiffness * samples.area[std::size_t(i)];
  k.damping = scene.contact.damping * k.stiffness;
  k.friction = c.friction;
  if (c.dynamic) k.rigid_velocity = from_bt(c.body->getVelocityInLocalPoint(bt(p) - f.com));
  else if (c.kinematic && dt > 0.0) k.rigid_velocity = (f.pose_next.apply(local) - p) / dt;
  found.max_penetration = std::max(found.max_penetration, -d);
  found.contacts.push_back(std::move(k));
  found.refs.push_back({ci, p});
}

// Two passes over the samples for all colliders at once, each on the executor's threads when given (two fork-joins
// per step, not two per collider and one for the positions; meniscus_punch has four colliders), each chunk handed to
// whichever thread is free (Executor::parallel_for_each: in equal shares one thread waited for the other's costly
// chunks, and the chunks near a collider cost far more than the others):
//  1. in chunks of kScan samples: their positions, then for each collider the ones that need a query (inside
//     Bullet's bounding box of the shape and not within the clearance known from their last query, in the collider's
//     frame: cheap tests);
//  2. the queries, in small chunks of kChunk samples of one collider (the samples near a tool are few and close
//     together in S's order, and each query can cost tens of microseconds).
// Each (collider, sample) pair's cache entries are read and written by one chunk only, and Bullet's queries on a
// shape are read-only. The chunks' contacts are joined in collider order, then sample order, so the result does not
// depend on the threads.
std::vector<sim::Contact> ContactWorld::find(const sim::ContactSamples& samples, const std::vector<Vec3>& x,
                                             double t, double dt,
                                             const std::vector<sim::Pose>& tool_now,
                                             const std::vector<sim::Pose>& tool_next, sim::Executor* executor) {
  const auto t0 = sim::Clock::now();
  if (std::size_t(samples.size()) != m->samples) reset_samples();
  m->samples = std::size_t(samples.size());
  const int n = samples.size();
  const std::size_t nc = m->colliders.size();
  const bool parallel = executor != nullptr && executor->threads() > 1;
  std::vector<Impl::QueryFrame> frames;
  frames.reserve(nc);
  for (std::size_t ci = 0; ci < nc; ++ci) frames.push_back(m->frame_of(ci, n, t, dt, tool_now, tool_next));

  constexpr int kScan = 1024;
  const int scans = (n + kScan - 1) / kScan;
  std::vector<Vec3> positions(std::size_t(n), Vec3::Zero());
  std::vector<std::vector<int>> scanned(nc * std::size_t(scans));  // [collider * scans + scan]: samples to query
  const auto place_and_scan = [&](int sb, int se) {
    for (int s = sb; s < se; ++s) {
      const int b = s * kScan, e = std::min(n, b + kScan);
      for (int i = b; i < e; ++i) positions[std::size_t(i)] = samples.position(i, x);
      for (std::size_t ci = 0; ci < nc; ++ci)
        m->scan(ci, frames[ci], positions, b, e, scanned[ci * std::size_t(scans) + std::size_t(s)]);
    }
  };
  if (parallel && scans > 1)
    executor->parallel_for_each(scans, place_and_scan);
  else
    place_and_scan(0, scans);

  // The queries: task k is chunk k - first[ci] of collider ci's samples to query (ascending).
  constexpr int kChunk = 8;
  std::vector<std::vector<int>> queried(nc);
  std::vector<int> first(nc + 1, 0);
  for (std::size_t ci = 0; ci < nc; ++ci) {
    for (int s = 0; s < scans; ++s) {
      const std::vector<int>& part = scanned[ci * std::size_t(scans) + std::size_t(s)];
      queried[ci].insert(queried[ci].end(), part.begin(), part.end());
    }
    first[ci + 1] = first[ci] + (int(queried[ci].size()) + kChunk - 1) / kChunk;
  }
  std::vector<Impl::Found> found(static_cast<std::size_t>(first[nc]));
  const auto run = [&](int kb, int ke) {
    for (int k = kb; k < ke; ++k) {
      const auto ci = std::size_t(std::upper_bound(first.begin(), first.end(), k) - first.begin() - 1);
      const std::vector<int>& q = queried[ci];
      const int b = (k - first[ci]) * kChunk, e = std::min(int(q.size()), b + kChunk);
      for (int j = b; j < e; ++j)
        m->query_sample(ci, frames[ci], samples, positions, q[std::size_t(j)], dt, found[std::size_t(k)]);
    }
  };
  if (parallel && first[nc] > 1)
    executor->parallel_for_each(first[nc], run);
  else
    run(0, first[nc]);

  std::vector<sim::Contact> out;
  m->refs.clear();
  m->profile.searched = m->profile.certified = m->profile.triangles = 0;
  for (std::size_t ci = 0; ci < nc; ++ci) {
    Collider& c = m->colliders[ci];
    c.state.max_penetration = 0.0;
    for (int k = first[ci]; k < first[ci + 1]; ++k) {
      Impl::Found& f = found[std::size_t(k)];
      m->profile.searched += f.searched;
      m->profile.certified += f.certified;
      m->profile.triangles += f.triangles;
      c.state.max_penetration = std::max(c.state.max_penetration, f.max_penetration);
      std::move(f.contacts.begin(), f.contacts.end(), std::back_inserter(out));
      m->refs.insert(m->refs.end(), f.refs.begin(), f.refs.end());
    }
    m->max_penetration = std::max(m->max_penetration, c.state.max_penetration);
  }
  m->profile.queries = sim::ms_since(t0);
  return out;
}

void ContactWorld::finish(const std::vector<sim::ContactOutcome>& outcomes, double t, double dt,
                          const std::vector<sim::Pose>& tool_next) {
  const auto t0 = sim::Clock::now();
  for (Collider& c : m->colliders) c.force = c.torque = Vec3::Zero();
  // Outcomes are missing when the step failed at the smallest dt: no force then.
  const std::size_t n = outcomes.size() == m->refs.size() ? outcomes.size() : 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Impl::ContactRef& r = m->refs[i];
    Collider& c = m->colliders[r.collider];
    const sim::ContactOutcome& o = outcomes[i];
    c.force -= o.force;
    if (c.dynamic) c.torque += (r.point - from_bt(c.body->getCenterOfMassPosition())).cross(-o.force);
  }
  // Two-way coupling: the dynamic bodies get the tissue's force; kinematic ones move to their pose at t + dt.
  for (Collider& c : m->colliders) {
    if (c.dynamic) {
      c.body->applyCentralForce(bt(c.force));
      c.body->applyTorque(bt(c.torque));
    } else if (c.kinematic) {
      c.motion->setWorldTransform(bt(m->pose_at(c, t + dt, tool_next)));
    }
  }
  m->world.stepSimulation(btScalar(dt), 0);
  for (std::size_t i = 0; i < m->colliders.size(); ++i) {
    Collider& c = m->colliders[i];
    ColliderState& s = m->states[i];
    s = c.state;
    s.force = {c.force.x(), c.force.y(), c.force.z()};
    s.max_force = std::max(c.state.max_force, c.force.norm());
    c.state.max_force = s.max_force;
    s.pose = m->pose_at(c, t + dt, tool_next);
    const Vec3 vel = c.dynamic ? from_bt(c.body->getLinearVelocity()) : Vec3::Zero();
    s.velocity = {vel.x(), vel.y(), vel.z()};
  }
  m->refs.clear();
  m->profile.rigid = sim::ms_since(t0);
}

void ContactWorld::reset_samples() {
  for (Collider& c : m->colliders) c.forget_samples();
}

void ContactWorld::remap_samples(const std::vector<int>& old_of_new) {
  const std::size_t n = old_of_new.size();
  for (Collider& c : m->colliders) {
    if (m->samples == 0 || c.cache_local.size() != m->samples) {  // not queried with the old samples: nothing kept
      c.forget_samples();
      continue;
    }
    // A new sample starts as a first query does (no clearance, not inside, no certificate).
    std::vector<Vec3> local(n, Vec3::Zero());
    std::vector<double> clearance(n, -1.0), depth(n, 0.0);
    std::vector<NearestCertificate> certificate(c.concave ? n : 0);
    for (std::size_t i = 0; i < n; ++i) {
      const int o = old_of_new[i];
      if (o < 0 || std::size_t(o) >= m->samples) continue;
      local[i] = c.cache_local[std::size_t(o)];
      clearance[i] = c.cache_clearance[std::size_t(o)];
      depth[i] = c.last_depth[std::size_t(o)];
      if (c.concave) certificate[i] = c.certificate[std::size_t(o)];
    }
    c.cache_local = std::move(local);
    c.cache_clearance = std::move(clearance);
    c.last_depth = std::move(depth);
    c.certificate = std::move(certificate);
  }
  m->samples = n;
}

std::vector<int> same_rest_positions(const std::vector<Vec3>& before, const std::vector<Vec3>& after) {
  // Keyed by the coordinates' bits: a sample a cut left keeps its rest position exactly (S's vertices do not move,
  // and a face point of a face the cut did not touch is computed from the same corners).
  struct Key {
    std::array<double, 3> p;
    bool operator==(const Key& k) const { return p == k.p; }
  };
  struct Hash {
    std::size_t operator()(const Key& k) const {
      std::size_t h = 0;
      for (const double v : k.p) h = h * 1000003u ^ std::hash<double>{}(v);
      return h;
    }
  };
  std::unordered_map<Key, int, Hash> index;
  index.reserve(before.size());
  for (std::size_t i = 0; i < before.size(); ++i)
    index.try_emplace(Key{{before[i].x(), before[i].y(), before[i].z()}}, int(i));
  std::vector<int> out(after.size(), -1);
  for (std::size_t i = 0; i < after.size(); ++i)
    if (const auto it = index.find(Key{{after[i].x(), after[i].y(), after[i].z()}}); it != index.end())
      out[i] = it->second;
  return out;
}

const std::vector<ColliderState>& ContactWorld::colliders() const { return m->states; }
const ContactProfile& ContactWorld::profile() const { return m->profile; }
double ContactWorld::max_penetration() const { return m->max_penetration; }

double ContactWorld::rigid_energy() const {
  double e = 0.0;
  const btVector3 g = m->world.getGravity();
  for (const Collider& c : m->colliders) {
    if (!c.dynamic) continue;
    const btRigidBody& b = *c.body;
    const double mass = 1.0 / b.getInvMass();
    const btVector3 w = b.getAngularVelocity();
    const btVector3 iw = b.getInvInertiaTensorWorld().inverse() * w;
    e += 0.5 * mass * b.getLinearVelocity().length2() + 0.5 * w.dot(iw) - mass * g.dot(b.getCenterOfMassPosition());
  }
  return e;
}

}  // namespace octocut::engine
