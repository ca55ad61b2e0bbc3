#pragma once
// The embedding benchmark of paper Fig. 6 (SPEC §7 `embedding/depth<N>`, §10): after a cut-like surface edit, the
// time to update the vertex-element correspondences with the Z-curve list against a naive octree that keeps a vertex
// list in every node of every level. `octocut bench embedding` runs it on the 10k meniscus and its material graph.
#include <vector>

#include "octocut/sim/material.hpp"
#include "octocut/sim/surface.hpp"

namespace octocut::engine {

/// Settings of the embedding benchmark.
struct EmbeddingBenchOptions {
  int min_depth = 3;            ///< first uniform octree depth
  int max_depth = 8;            ///< last uniform octree depth
  int inserted = 100;           ///< new surface vertices per cut
  double ball_radius = 0.002;   ///< radius of the cut ball, m; surface vertices inside it are removed
  int runs = 101;               ///< timed repetitions per depth (each from the same starting state)
};

/// Result for one octree depth; times in ms.
struct EmbeddingBenchResult {
  int depth = 0;
  int leaves = 0;                 ///< non-empty leaves of the uniform tree
  int naive_nodes = 0;            ///< nodes of the naive tree (leaves and all their ancestors)
  int vertices = 0;               ///< surface vertices before the cut
  int removed = 0;                ///< vertices inside the cut ball
  int inserted = 0;               ///< vertices added by the cut
  int fallback = 0;               ///< inserted vertices that lie in no leaf
  std::vector<double> zcurve_ms;       ///< per run: Z-curve list update (delete, renumber, insert), paper §4.5
  std::vector<double> naive_ms;   ///< per run: removal, renumbering and insertion on every level of the naive tree
};

/// Runs the benchmark on `mesh` (m) inside `material` for each depth in [min_depth, max_depth]: the octree root is
/// the mesh's bounding box made cubic and grown by 5 %, refined uniformly to the depth with empty cells dropped. The
/// cut removes the vertices within ball_radius of a fixed surface vertex and inserts `inserted` points on the inner
/// cap of that ball. Throws std::invalid_argument for an empty mesh or bad options.
std::vector<EmbeddingBenchResult> run_embedding_bench(const sim::TriMesh& mesh, const sim::MaterialSource& material,
                                                      const EmbeddingBenchOptions& options);

}  // namespace octocut::engine
