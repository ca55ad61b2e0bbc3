#include "octocut/engine/io/material_graph_cache.hpp"

#include <bit>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "octocut/cutting/material_mesher.hpp"
#include "octocut/engine/io/io.hpp"
#include "octocut/sim/timing.hpp"

#ifndef OCTOCUT_DEFAULT_CACHE_DIR
#define OCTOCUT_DEFAULT_CACHE_DIR "cache"
#endif

namespace octocut::engine {
namespace {

static_assert(std::endian::native == std::endian::little, "the cache format is little-endian");

constexpr char kMagic[8] = {'O', 'C', 'T', 'O', 'M', 'G', 'R', 'F'};
constexpr std::uint32_t kFormatVersion = 1;

// A 64-bit hash of a byte string (multiply–xorshift over 8-byte words, finalised like splitmix64). Not
// cryptographic; two independent seeds give the 128-bit content key.
std::uint64_t hash64(std::string_view bytes, std::uint64_t seed) {
  auto mix = [](std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  };
  std::uint64_t h = mix(seed ^ (bytes.size() * 0x9e3779b97f4a7c15ULL));
  std::size_t i = 0;
  for (; i + 8 <= bytes.size(); i += 8) {
    std::uint64_t w;
    std::memcpy(&w, bytes.data() + i, 8);
    h = mix(h ^ mix(w + 0x9e3779b97f4a7c15ULL));
  }
  std::uint64_t tail = 0;
  std::memcpy(&tail, bytes.data() + i, bytes.size() - i);
  return mix(h ^ mix(tail ^ 0xff51afd7ed558ccdULL));
}

template <typename T>
void put(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof(T));
}

// Reads from a byte buffer with bounds checks.
struct Reader {
  std::string_view data;
  std::size_t pos = 0;
  template <typename T>
  bool get(T& v) {
    if (data.size() - pos < sizeof(T)) return false;
    std::memcpy(&v, data.data() + pos, sizeof(T));
    pos += sizeof(T);
    return true;
  }
};

std::string encode_entry(const sim::TetMesh& mesh, const std::string& key, double cell_size) {
  std::string out;
  out.append(kMagic, sizeof(kMagic));
  put(out, kFormatVersion);
  put(out, std::uint32_t(cutting::kMesherVersion));
  out.append(key);
  put(out, cell_size);
  put(out, std::uint64_t(mesh.vertices.size()));
  put(out, std::uint64_t(mesh.tets.size()));
  for (const sim::Vec3& p : mesh.vertices)
    for (int k = 0; k < 3; ++k) put(out, p[k]);
  for (const auto& t : mesh.tets) put(out, t);
  put(out, hash64(out, 1));
  return out;
}

// Decodes an entry; returns an empty string on success, otherwise why the entry is unusable.
std::string decode_entry(std::string_view bytes, const std::string& key, double cell_size, sim::TetMesh& mesh) {
  if (bytes.size() < sizeof(kMagic) + 8 + key.size() + 8 + 16 + 8) return "truncated";
  std::uint64_t stored_sum = 0;
  std::memcpy(&stored_sum, bytes.data() + bytes.size() - 8, 8);
  if (hash64(bytes.substr(0, bytes.size() - 8), 1) != stored_sum) return "checksum mismatch";
  if (std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) return "not a material graph cache entry";
  Reader r{bytes.substr(0, bytes.size() - 8), sizeof(kMagic)};
  std::uint32_t format = 0, mesher = 0;
  r.get(format);
  r.get(mesher);
  if (format != kFormatVersion || mesher != std::uint32_t(cutting::kMesherVersion)) return "written by another version";
  if (r.data.substr(r.pos, key.size()) != key) return "written for other content";
  r.pos += key.size();
  double h = 0.0;
  std::uint64_t nv = 0, nt = 0;
  r.get(h);
  r.get(nv);
  r.get(nt);
  if (h != cell_size) return "written for another cell size";
  if (nv > (r.data.size() - r.pos) / 24 || nt > (r.data.size() - r.pos) / 16 ||
      r.data.size() - r.pos != nv * 24 + nt * 16)
    return "size does not match its counts";
  mesh.vertices.resize(nv);
  mesh.tets.resize(nt);
  for (auto& p : mesh.vertices)
    for (int k = 0; k < 3; ++k) r.get(p[k]);
  for (auto& t : mesh.tets) {
    r.get(t);
    for (std::int32_t i : t)
      if (i < 0 || std::uint64_t(i) >= nv) return "tet index out of range";
  }
  return {};
}

}  // namespace

std::filesystem::path cache_directory() {
  if (const char* d = std::getenv("OCTOCUT_CACHE_DIR"); d && *d) return d;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::filesystem::path(x) / "octocut";
  // The build tree's cache/ while that tree exists; an installed octocut elsewhere uses ~/.cache/octocut.
  const std::filesystem::path build_cache = OCTOCUT_DEFAULT_CACHE_DIR;
  std::error_code ec;
  if (std::filesystem::is_directory(build_cache.parent_path(), ec)) return build_cache;
  if (const char* h = std::getenv("HOME"); h && *h) return std::filesystem::path(h) / ".cache" / "octocut";
  return build_cache;
}

std::string material_graph_key(const sim::TriMesh& surface, double cell_size) {
  std::string bytes;
  bytes.reserve(surface.vertices.size() * 24 + surface.triangles.size() * 12 + 64);
  put(bytes, std::uint64_t(surface.vertices.size()));
  put(bytes, std::uint64_t(surface.triangles.size()));
  for (const sim::Vec3& p : surface.vertices)
    for (int k = 0; k < 3; ++k) put(bytes, p[k]);
  for (const auto& t : surface.triangles) put(bytes, t);
  put(bytes, cell_size);
  put(bytes, std::int32_t(cutting::kMesherVersion));
  char hex[33];
  std::snprintf(hex, sizeof(hex), "%016llx%016llx", static_cast<unsigned long long>(hash64(bytes, 0x5eed)),
                static_cast<unsigned long long>(hash64(bytes, 0xc0ffee)));
  return hex;
}

MaterialGraphResult material_graph_for(const sim::TriMesh& surface, double cell_size, bool use_cache) {
  const auto start = sim::Clock::now();
  MaterialGraphResult result;
  auto finish = [&]() {
    result.ms = sim::ms_since(start);
    return result;
  };
  const std::string key = use_cache ? material_graph_key(surface, cell_size) : std::string();

  // A valid cache entry wins.
  if (use_cache) {
    result.entry = cache_directory() / "material_graph" / (key + ".mgraph");
    std::error_code ec;
    if (std::filesystem::is_regular_file(result.entry, ec)) {
      try {
        const std::string bytes = read_file(result.entry);
        const std::string why = decode_entry(bytes, key, cell_size, result.mesh);
        if (why.empty()) {
          result.from_cache = true;
          return finish();
        }
        result.warning = "material graph cache entry " + result.entry.string() + " is unusable (" + why + "); rebuilt";
      } catch (const std::exception& e) {
        result.warning = std::string("material graph cache entry unreadable (") + e.what() + "); rebuilt";
      }
    }
  }

  // Mesh, then store the entry for next time.
  result.mesh = cutting::mesh_interior(surface, cell_size);
  if (use_cache) {
    try {
      std::filesystem::create_directories(result.entry.parent_path());
      write_file_atomic(result.entry, encode_entry(result.mesh, key, cell_size));
    } catch (const std::exception& e) {
      if (!result.warning.empty()) result.warning += "; ";
      result.warning += std::string("material graph cache not written: ") + e.what();
    }
  }
  return finish();
}

}  // namespace octocut::engine
