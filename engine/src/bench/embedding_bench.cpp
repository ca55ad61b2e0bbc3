#include "octocut/engine/bench/embedding_bench.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "octocut/sim/embedding.hpp"
#include "octocut/sim/naive_embedding.hpp"
#include "octocut/sim/octree.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::engine {

namespace {

using sim::Clock;
using sim::Vec3;

// Largest tree the benchmark builds: a guard against a runaway depth, not a tuning knob.
constexpr std::size_t kMaxBenchLeaves = 8'000'000;

// Milliseconds since t0.
using sim::ms_since;

// Writes and reads a 16 MiB scratch buffer, more than the private L1/L2 caches hold, so that each timed update starts
// with its data in the shared cache or memory whatever the previous run left behind.
void evict_private_caches(std::vector<std::uint64_t>& scratch) {
  scratch.resize((16u << 20) / sizeof(std::uint64_t));
  std::uint64_t acc = 0;
  for (std::size_t i = 0; i < scratch.size(); i += 8) acc += (scratch[i] += i);
  volatile std::uint64_t sink = acc;
  (void)sink;
}

// The octree root of SPEC §2.1: the mesh's bounding box, made cubic about its centre and grown by 5 %.
sim::RootGeometry default_root(const sim::TriMesh& mesh) {
  const sim::Box3 b = sim::bounds(mesh);
  const double edge = 1.05 * (b.max - b.min).maxCoeff();
  return {0.5 * (b.min + b.max) - Vec3::Constant(0.5 * edge), edge};
}

// All non-empty cells of level `depth`, by depth-first subdivision that drops empty cells with their subtree.
sim::Octree uniform_tree(const sim::RootGeometry& root, const sim::MaterialSource& material, int depth) {
  std::vector<sim::Cell> leaves;
  std::vector<sim::Cell> stack{sim::Cell{}};
  while (!stack.empty()) {
    const sim::Cell c = stack.back();
    stack.pop_back();
    if (material.occupancy(root.cell_box(c)) < sim::kEmptyOccupancy) continue;
    if (c.level < depth) {
      for (int k = 7; k >= 0; --k) stack.push_back(c.child(k));
    } else {
      leaves.push_back(c);
      if (leaves.size() > kMaxBenchLeaves)
        throw std::invalid_argument("embedding bench: depth " + std::to_string(depth) + " exceeds " +
                                    std::to_string(kMaxBenchLeaves) + " leaves");
    }
  }
  if (leaves.empty()) throw std::invalid_argument("embedding bench: the material does not meet the octree root");
  return sim::Octree(std::move(leaves));
}

// The simulated cut: vertices within `radius` of `spot` go, `count` points on the ball's inner cap (polar angle up
// to 60 degrees from the inward normal, Fibonacci spiral) come.
struct CutEdit {
  std::vector<int> removed;
  std::vector<Vec3> inserted;
};

CutEdit make_cut(const sim::TriMesh& mesh, int count, double radius) {
  // The spot: the vertex nearest to a fixed point on the top of the bounding box, off-centre (lowest index on ties).
  const sim::Box3 b = sim::bounds(mesh);
  const Vec3 target = b.min + Vec3(0.7, 0.6, 1.0).cwiseProduct(b.max - b.min);
  std::size_t spot = 0;
  for (std::size_t v = 1; v < mesh.vertices.size(); ++v)
    if ((mesh.vertices[v] - target).squaredNorm() < (mesh.vertices[spot] - target).squaredNorm()) spot = v;
  const Vec3 p = mesh.vertices[spot];

  // Removed: every vertex inside the ball.
  CutEdit cut;
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
    if ((mesh.vertices[v] - p).norm() < radius) cut.removed.push_back(int(v));

  // Inserted: the inner cap, around the inward vertex normal.
  Vec3 n = sim::vertex_normals(mesh.vertices, mesh.triangles)[spot];
  if (n.squaredNorm() == 0.0) n = Vec3::UnitZ();
  const Vec3 in = -n;
  const Vec3 t1 = (std::abs(in.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(in).normalized();
  const Vec3 t2 = in.cross(t1);
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < count; ++i) {
    const double c = 1.0 - 0.5 * (i + 0.5) / count;  // cos(theta) from 1 down to cos(60 deg)
    const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
    const double phi = golden * i;
    cut.inserted.push_back(p + radius * (c * in + s * (std::cos(phi) * t1 + std::sin(phi) * t2)));
  }
  return cut;
}

}  // namespace

std::vector<EmbeddingBenchResult> run_embedding_bench(const sim::TriMesh& mesh, const sim::MaterialSource& material,
                                                      const EmbeddingBenchOptions& o) {
  if (mesh.vertices.empty()) throw std::invalid_argument("embedding bench: the mesh has no vertices");
  if (o.min_depth < 0 || o.max_depth > sim::kMaxDepth || o.min_depth > o.max_depth || o.inserted < 0 ||
      !(o.ball_radius > 0.0) || o.runs < 1)
    throw std::invalid_argument("embedding bench: need 0 <= min_depth <= max_depth <= 20, inserted >= 0, "
                                "ball_radius > 0 and runs >= 1");
  const sim::RootGeometry root = default_root(mesh);
  const CutEdit cut = make_cut(mesh, o.inserted, o.ball_radius);

  std::vector<EmbeddingBenchResult> results;
  for (int depth = o.min_depth; depth <= o.max_depth; ++depth) {
    // The uniform tree and both structures in their state before the cut.
    const sim::Octree tree = uniform_tree(root, material, depth);
    const sim::ZCurveList z0(root, mesh.vertices);

    EmbeddingBenchResult r;
    r.depth = depth;
    r.leaves = tree.size();
    r.vertices = int(mesh.vertices.size());
    r.removed = int(cut.removed.size());
    r.inserted = int(cut.inserted.size());
    // Working copies, assigned from the starting state before each run (untimed). Assignment reuses their storage,
    // as a long-lived structure would, so allocator effects stay out of the timings. Each method runs in its own
    // phase, so that the other's memory traffic (the naive tree reaches ~100 MB at depth 8) does not skew it.
    std::vector<std::uint64_t> scratch;
    sim::ZCurveList z;
    std::vector<sim::VertexEmbedding> e_new(cut.inserted.size());
    std::vector<int> map;
    for (int run = 0; run < o.runs; ++run) {
      // Z-curve: delete, renumber and insert in the sorted list (paper §4.5); the list is the correspondence, a
      // leaf's vertices being one code range. The move of per-vertex weight arrays, the same for both methods, is in
      // neither. Both methods start each run with the private caches (L1, L2) flushed; the shared L3 is not (it is
      // 480 MB on the measuring machine), so nothing else may sweep memory between the copy and the timed update.
      z = z0;
      evict_private_caches(scratch);
      const auto t0 = Clock::now();
      z.update(cut.removed, cut.inserted, map);
      r.zcurve_ms.push_back(ms_since(t0));
    }
    // How many new vertices lie in no leaf (M is coarser than S near the surface): counted, not timed.
    for (std::size_t i = 0; i < cut.inserted.size(); ++i) e_new[i] = sim::embed_vertex(tree, root, cut.inserted[i]);
    r.fallback = int(std::count_if(e_new.begin(), e_new.end(), [](const auto& ve) { return ve.fallback; }));

    const sim::NaiveEmbedding naive0(tree, root, mesh.vertices);
    r.naive_nodes = naive0.num_nodes();
    sim::NaiveEmbedding naive = naive0;
    for (int run = 0; run < o.runs; ++run) {
      // Naive: remove on every level, renumber every list of every node, insert on every level (this also finds the
      // leaf of each new vertex).
      naive = naive0;
      evict_private_caches(scratch);
      const auto t0 = Clock::now();
      const std::vector<int> naive_map = naive.update(cut.removed, cut.inserted);
      r.naive_ms.push_back(ms_since(t0));
      // Both must describe the same edit.
      if (naive_map != map) throw std::logic_error("embedding bench: the two structures disagree on the index map");
    }
    results.push_back(std::move(r));
  }
  return results;
}

}  // namespace octocut::engine
