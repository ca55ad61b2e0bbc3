// Deterministic binary PLY writer (the format of the committed assets and of surface outputs) and the PLY reader.
#include "io/mesh_ply.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <sstream>

#include "octocut/engine/io/mesh_io.hpp"

namespace octocut::engine {
namespace {

static_assert(std::endian::native == std::endian::little, "binary PLY output assumes a little-endian host");

template <typename T>
void append_raw(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

}  // namespace

std::string encode_ply_binary(const sim::TriMesh& mesh, PlyPrecision precision) {
  const bool single = precision == PlyPrecision::single;
  std::string out;
  out += "ply\nformat binary_little_endian 1.0\ncomment octocut\n";
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += single ? "property float x\nproperty float y\nproperty float z\n"
                : "property double x\nproperty double y\nproperty double z\n";
  out += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + mesh.vertices.size() * (single ? 12 : 24) + mesh.triangles.size() * 13);
  for (const sim::Vec3& p : mesh.vertices) {
    for (int k = 0; k < 3; ++k) {
      if (single)
        append_raw(out, static_cast<float>(p[k]));
      else
        append_raw(out, p[k]);
    }
  }
  for (const auto& t : mesh.triangles) {
    append_raw(out, static_cast<unsigned char>(3));
    for (int k = 0; k < 3; ++k) append_raw(out, static_cast<std::int32_t>(t[k]));
  }
  return out;
}

// ---- reading ------------------------------------------------------------------------------------------------------

namespace {

enum class Scalar { i8, u8, i16, u16, i32, u32, f32, f64 };

struct Property {
  std::string name;
  Scalar type = Scalar::f32;
  bool list = false;
  Scalar count_type = Scalar::u8;
};

struct Element {
  std::string name;
  std::uint64_t count = 0;
  std::vector<Property> properties;
};

enum class Format { ascii, little, big };

[[noreturn]] void fail(const std::string& file, const std::string& what) { throw MeshError(file + ": " + what); }

bool scalar_type(const std::string& s, Scalar& t) {
  static const std::pair<const char*, Scalar> names[] = {
      {"char", Scalar::i8},    {"int8", Scalar::i8},     {"uchar", Scalar::u8},   {"uint8", Scalar::u8},
      {"short", Scalar::i16},  {"int16", Scalar::i16},   {"ushort", Scalar::u16}, {"uint16", Scalar::u16},
      {"int", Scalar::i32},    {"int32", Scalar::i32},   {"uint", Scalar::u32},   {"uint32", Scalar::u32},
      {"float", Scalar::f32},  {"float32", Scalar::f32}, {"double", Scalar::f64}, {"float64", Scalar::f64}};
  for (const auto& [name, type] : names)
    if (s == name) {
      t = type;
      return true;
    }
  return false;
}

std::size_t scalar_size(Scalar t) {
  switch (t) {
    case Scalar::i8: case Scalar::u8: return 1;
    case Scalar::i16: case Scalar::u16: return 2;
    case Scalar::i32: case Scalar::u32: case Scalar::f32: return 4;
    case Scalar::f64: return 8;
  }
  return 1;
}

// The header, up to and including "end_header\n"; `body` is the offset of the first byte after it.
struct Header {
  Format format = Format::ascii;
  std::vector<Element> elements;
  std::size_t body = 0;
  int lines = 0;  // header lines, for the line numbers of ASCII bodies
};

Header parse_header(const std::string& bytes, const std::string& file) {
  Header h;
  std::size_t pos = 0;
  bool have_format = false;
  for (int line_no = 1;; ++line_no) {
    const std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) fail(file, "PLY header has no end_header line");
    std::string line = bytes.substr(pos, end - pos);
    pos = end + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream in(line);
    std::string word;
    in >> word;
    const std::string where = "line " + std::to_string(line_no) + ": ";
    if (line_no == 1) {
      if (word != "ply") fail(file, "cannot read mesh (unknown format or corrupt file): the first line is not 'ply'");
      continue;
    }
    if (word.empty() || word == "comment" || word == "obj_info") continue;
    if (word == "end_header") {
      if (!have_format) fail(file, where + "PLY header has no format line");
      h.body = pos;
      h.lines = line_no;
      return h;
    }
    if (word == "format") {
      std::string f, version;
      in >> f >> version;
      if (f == "ascii") h.format = Format::ascii;
      else if (f == "binary_little_endian") h.format = Format::little;
      else if (f == "binary_big_endian") h.format = Format::big;
      else fail(file, where + "unknown PLY format '" + f + "'");
      if (version != "1.0") fail(file, where + "unsupported PLY version '" + version + "'");
      have_format = true;
    } else if (word == "element") {
      Element e;
      std::string count;
      in >> e.name >> count;
      std::uint64_t n = 0;
      const auto r = std::from_chars(count.data(), count.data() + count.size(), n);
      if (e.name.empty() || r.ec != std::errc() || r.ptr != count.data() + count.size())
        fail(file, where + "bad element line '" + line + "'");
      e.count = n;
      h.elements.push_back(std::move(e));
    } else if (word == "property") {
      if (h.elements.empty()) fail(file, where + "property before any element");
      Property p;
      std::string type;
      in >> type;
      if (type == "list") {
        std::string count_type, item_type;
        in >> count_type >> item_type >> p.name;
        p.list = true;
        if (!scalar_type(count_type, p.count_type) || !scalar_type(item_type, p.type) ||
            p.count_type == Scalar::f32 || p.count_type == Scalar::f64)
          fail(file, where + "bad list property '" + line + "'");
      } else {
        in >> p.name;
        if (!scalar_type(type, p.type)) fail(file, where + "unknown property type '" + type + "'");
      }
      if (p.name.empty()) fail(file, where + "property without a name");
      h.elements.back().properties.push_back(std::move(p));
    } else {
      fail(file, where + "unknown PLY header keyword '" + word + "'");
    }
  }
}

// Reads one value at a time from the body, in either encoding. ASCII values are whitespace-separated tokens, one
// element per line.
class BodyReader {
 public:
  BodyReader(const std::string& bytes, const Header& h, const std::string& file)
      : m_bytes(bytes), m_pos(h.body), m_format(h.format), m_file(file), m_line(h.lines) {}

  // Starts the next element instance (ASCII: the next line that is not blank).
  void begin_element(const std::string& what) {
    m_what = what;
    if (m_format != Format::ascii) return;
    for (;;) {
      if (m_pos >= m_bytes.size()) fail(m_file, "line " + std::to_string(m_line + 1) + ": file ends before " + what);
      std::size_t end = m_bytes.find('\n', m_pos);
      if (end == std::string::npos) end = m_bytes.size();
      std::string line = m_bytes.substr(m_pos, end - m_pos);
      m_pos = end + 1;
      ++m_line;
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      m_tokens.clear();
      m_tokens.str(line);
      m_line_size = line.size();
      return;
    }
  }

  double value(Scalar t) {
    if (m_format == Format::ascii) {
      std::string token;
      if (!(m_tokens >> token)) fail(m_file, "line " + std::to_string(m_line) + ": too few values in " + m_what);
      double v = 0.0;
      const char* b = token.data();
      const char* e = b + token.size();
      if (*b == '+') ++b;
      const auto r = std::from_chars(b, e, v);
      if (r.ec != std::errc() || r.ptr != e)
        fail(m_file, "line " + std::to_string(m_line) + ": '" + token + "' is not a number in " + m_what);
      if (t != Scalar::f32 && t != Scalar::f64 && (v != std::floor(v) || v < -2147483648.0 || v > 4294967295.0))
        fail(m_file, "line " + std::to_string(m_line) + ": '" + token + "' is not a 32-bit integer in " + m_what);
      return v;
    }
    const std::size_t n = scalar_size(t);
    if (m_pos + n > m_bytes.size()) fail(m_file, "file ends inside " + m_what);
    unsigned char raw[8];
    std::memcpy(raw, m_bytes.data() + m_pos, n);
    m_pos += n;
    if (m_format == Format::big) std::reverse(raw, raw + n);
    switch (t) {
      case Scalar::i8: { std::int8_t v; std::memcpy(&v, raw, 1); return v; }
      case Scalar::u8: return raw[0];
      case Scalar::i16: { std::int16_t v; std::memcpy(&v, raw, 2); return v; }
      case Scalar::u16: { std::uint16_t v; std::memcpy(&v, raw, 2); return v; }
      case Scalar::i32: { std::int32_t v; std::memcpy(&v, raw, 4); return v; }
      case Scalar::u32: { std::uint32_t v; std::memcpy(&v, raw, 4); return v; }
      case Scalar::f32: { float v; std::memcpy(&v, raw, 4); return v; }
      case Scalar::f64: { double v; std::memcpy(&v, raw, 8); return v; }
    }
    return 0.0;
  }

  // Bytes (binary) or characters (ASCII) left: no element count may promise more instances than this.
  [[nodiscard]] std::size_t remaining() const {
    return (m_pos < m_bytes.size() ? m_bytes.size() - m_pos : 0) + (m_format == Format::ascii ? m_line_size : 0);
  }

 private:
  const std::string& m_bytes;
  std::size_t m_pos;
  Format m_format;
  const std::string& m_file;
  int m_line;
  std::string m_what;
  std::istringstream m_tokens;
  std::size_t m_line_size = 0;  // ASCII: characters of the current element's line
};

// The face list property: vertex_indices (or vertex_index).
bool is_face_list(const Property& p) { return p.list && (p.name == "vertex_indices" || p.name == "vertex_index"); }

void read_vertices(BodyReader& body, const Element& e, const std::string& file, PlyContents& out) {
  int axis[3] = {-1, -1, -1};
  for (std::size_t k = 0; k < e.properties.size(); ++k)
    for (int a = 0; a < 3; ++a)
      if (!e.properties[k].list && e.properties[k].name == std::string(1, char('x' + a))) axis[a] = int(k);
  if (axis[0] < 0 || axis[1] < 0 || axis[2] < 0) fail(file, "PLY vertex element lacks x, y or z");
  out.positions.reserve(std::size_t(std::min<std::uint64_t>(e.count, body.remaining())));
  for (std::uint64_t i = 0; i < e.count; ++i) {
    body.begin_element("vertex " + std::to_string(i));
    sim::Vec3 p = sim::Vec3::Zero();
    for (std::size_t k = 0; k < e.properties.size(); ++k) {
      const Property& prop = e.properties[k];
      if (prop.list) {
        const double n = body.value(prop.count_type);
        if (n < 0 || n > double(body.remaining())) fail(file, "vertex " + std::to_string(i) + ": bad list length");
        for (long j = 0; j < long(n); ++j) body.value(prop.type);
        continue;
      }
      const double v = body.value(prop.type);
      for (int a = 0; a < 3; ++a)
        if (axis[a] == int(k)) p[a] = v;
    }
    out.positions.push_back(p);
  }
}

void read_faces(BodyReader& body, const Element& e, const std::string& file, PlyContents& out) {
  const auto list = std::find_if(e.properties.begin(), e.properties.end(), is_face_list);
  if (list == e.properties.end()) fail(file, "PLY face element has no vertex_indices list");
  std::vector<std::int64_t> corners;
  for (std::uint64_t i = 0; i < e.count; ++i) {
    const std::string what = "face " + std::to_string(i);
    body.begin_element(what);
    for (const Property& prop : e.properties) {
      if (!prop.list) {
        body.value(prop.type);
        continue;
      }
      const double n = body.value(prop.count_type);
      if (n < 0 || n > double(body.remaining())) fail(file, what + ": bad list length " + std::to_string(long(n)));
      corners.clear();
      for (long j = 0; j < long(n); ++j) {
        const double v = body.value(prop.type);
        if (!(v >= -1.0 && v <= 4294967295.0)) fail(file, what + ": vertex index " + std::to_string(v) + " is out of range");
        corners.push_back(std::int64_t(v));
      }
      if (&prop != &*list) continue;
      if (corners.size() < 3) fail(file, what + " has " + std::to_string(corners.size()) + " vertices");
      for (std::size_t c = 1; c + 1 < corners.size(); ++c) out.triangles.push_back({corners[0], corners[c], corners[c + 1]});
    }
  }
}

}  // namespace

PlyContents decode_ply(const std::string& bytes, const std::string& file) {
  const Header h = parse_header(bytes, file);
  BodyReader body(bytes, h, file);
  PlyContents out;
  bool have_vertices = false;
  for (const Element& e : h.elements) {
    // Each instance takes at least one byte (binary) or one line (ASCII): a count beyond the file is corrupt.
    std::size_t min_size = 0;
    // (ASCII: each value at least one character and a separator.)
    for (const Property& p : e.properties)
      min_size += h.format == Format::ascii ? 2 : p.list ? scalar_size(p.count_type) : scalar_size(p.type);
    if (e.count > 0 && e.count > body.remaining() / std::max<std::size_t>(1, min_size) + 1)
      fail(file, "element '" + e.name + "' claims " + std::to_string(e.count) + " entries, more than the file holds");
    if (e.name == "vertex") {
      read_vertices(body, e, file, out);
      have_vertices = true;
    } else if (e.name == "face") {
      read_faces(body, e, file, out);
    } else {
      // Any other element (edges, materials) is read past.
      for (std::uint64_t i = 0; i < e.count; ++i) {
        body.begin_element(e.name + " " + std::to_string(i));
        for (const Property& p : e.properties) {
          const double n = p.list ? body.value(p.count_type) : 1.0;
          if (n < 0 || n > double(body.remaining()) + 1) fail(file, e.name + " " + std::to_string(i) + ": bad list length");
          for (long j = 0; j < long(n); ++j) body.value(p.type);
        }
      }
    }
  }
  if (!have_vertices) fail(file, "PLY file has no vertex element");
  const auto nv = std::int64_t(out.positions.size());
  for (std::size_t f = 0; f < out.triangles.size(); ++f)
    for (std::int64_t v : out.triangles[f])
      if (v < 0 || v >= nv)
        fail(file, "triangle " + std::to_string(f) + " refers to vertex " + std::to_string(v) + ", but the file has " +
                       std::to_string(nv) + " vertices");
  return out;
}

}  // namespace octocut::engine
