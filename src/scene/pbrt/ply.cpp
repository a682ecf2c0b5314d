// The PLY reader (ASCII, binary little and big endian).
// The whole file is already in memory; binary data is decoded straight from the buffer
// with bounds checks on every read, so a truncated or lying header throws instead of
// reading past the end. Nothing is allocated per vertex or face.
#include "ply.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace tuile::pbrt {
namespace {

enum class Type : uint8_t { i8, u8, i16, u16, i32, u32, f32, f64 };

bool parse_type(std::string_view s, Type& t) {
  static const struct {
    const char* name;
    Type type;
  } names[] = {{"char", Type::i8},    {"int8", Type::i8},     {"uchar", Type::u8},    {"uint8", Type::u8},
               {"short", Type::i16},  {"int16", Type::i16},   {"ushort", Type::u16},  {"uint16", Type::u16},
               {"int", Type::i32},    {"int32", Type::i32},   {"uint", Type::u32},    {"uint32", Type::u32},
               {"float", Type::f32},  {"float32", Type::f32}, {"double", Type::f64},  {"float64", Type::f64}};
  for (const auto& n : names)
    if (s == n.name) {
      t = n.type;
      return true;
    }
  return false;
}

size_t type_size(Type t) {
  switch (t) {
    case Type::i8: case Type::u8: return 1;
    case Type::i16: case Type::u16: return 2;
    case Type::i32: case Type::u32: case Type::f32: return 4;
    case Type::f64: return 8;
  }
  return 1;
}

struct Prop {
  std::string name;
  Type type = Type::f32;
  bool list = false;
  Type count_type = Type::u8;
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Prop> props;
};

[[noreturn]] void bad(const std::string& msg, const std::string& expected = "a valid PLY file") {
  throw PlyError(msg, expected);
}

template <class T> inline T load_raw(const char* p, bool swap) {
  T v;
  if (!swap) {
    std::memcpy(&v, p, sizeof(T));
    return v;
  }
  char b[sizeof(T)];
  for (size_t i = 0; i < sizeof(T); ++i) b[i] = p[sizeof(T) - 1 - i];
  std::memcpy(&v, b, sizeof(T));
  return v;
}

inline double load_num(const char* p, Type t, bool swap) {
  switch (t) {
    case Type::i8: return double(int8_t(*p));
    case Type::u8: return double(uint8_t(*p));
    case Type::i16: return double(load_raw<int16_t>(p, swap));
    case Type::u16: return double(load_raw<uint16_t>(p, swap));
    case Type::i32: return double(load_raw<int32_t>(p, swap));
    case Type::u32: return double(load_raw<uint32_t>(p, swap));
    case Type::f32: return double(load_raw<float>(p, swap));
    case Type::f64: return load_raw<double>(p, swap);
  }
  return 0;
}

inline int64_t load_int(const char* p, Type t, bool swap) {
  switch (t) {
    case Type::i8: return int8_t(*p);
    case Type::u8: return uint8_t(*p);
    case Type::i16: return load_raw<int16_t>(p, swap);
    case Type::u16: return load_raw<uint16_t>(p, swap);
    case Type::i32: return load_raw<int32_t>(p, swap);
    case Type::u32: return load_raw<uint32_t>(p, swap);
    case Type::f32: case Type::f64: {
      const double d = load_num(p, t, swap);
      return std::isfinite(d) && std::abs(d) < 9e18 ? int64_t(d) : -1;
    }
  }
  return -1;
}

// What a vertex property is used for.
enum Slot : int8_t { none = -1, px, py, pz, pu, pv, nx, ny, nz, slot_count };

Slot vertex_slot(const std::string& n, bool want_normals) {
  if (n == "x") return px;
  if (n == "y") return py;
  if (n == "z") return pz;
  if (n == "u" || n == "s" || n == "texture_u" || n == "texture_s") return pu;
  if (n == "v" || n == "t" || n == "texture_v" || n == "texture_t") return pv;
  if (want_normals) {
    if (n == "nx") return nx;
    if (n == "ny") return ny;
    if (n == "nz") return nz;
  }
  return none;
}

// Adds one face's triangles (quads split along 0-2, larger polygons as a fan).
struct FaceSink {
  PlyMesh& mesh;
  uint64_t vertex_count;
  uint64_t face = 0;
  int64_t idx[64] = {};

  void add_triangle(int64_t a, int64_t b, int64_t c) {
    if (a == b || b == c || a == c) {
      ++mesh.degenerate;
      return;
    }
    mesh.indices.push_back(uint32_t(a));
    mesh.indices.push_back(uint32_t(b));
    mesh.indices.push_back(uint32_t(c));
  }
  void finish(int64_t n) {
    for (int64_t i = 0; i < n; ++i)
      if (idx[i] < 0 || uint64_t(idx[i]) >= vertex_count)
        bad("face " + std::to_string(face) + " has vertex index " + std::to_string(idx[i]) +
            " out of range",
            "an index below the vertex count " + std::to_string(vertex_count));
    if (n < 3) {
      ++mesh.degenerate;
    } else if (n == 3) {
      add_triangle(idx[0], idx[1], idx[2]);
    } else if (n == 4) {
      add_triangle(idx[0], idx[1], idx[2]);
      add_triangle(idx[0], idx[2], idx[3]);
    } else {
      ++mesh.polygons;
      for (int64_t i = 1; i + 1 < n; ++i) add_triangle(idx[0], idx[i], idx[i + 1]);
    }
    ++face;
  }
};

constexpr int64_t max_face_vertices = 64;

struct Header {
  std::vector<Element> elements;
  int format = 0;  // 0 ascii, 1 binary little endian, 2 binary big endian
  size_t body = 0;
};

Header parse_header(std::string_view data) {
  Header h;
  size_t pos = 0;
  auto next_line = [&](std::string_view& line) {
    if (pos >= data.size()) return false;
    size_t e = data.find('\n', pos);
    if (e == std::string_view::npos) e = data.size();
    line = data.substr(pos, e - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = std::min(e + 1, data.size());
    return true;
  };
  auto words = [](std::string_view line) {
    std::vector<std::string_view> w;
    size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      size_t s = i;
      while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
      if (i > s) w.push_back(line.substr(s, i - s));
    }
    return w;
  };
  std::string_view line;
  if (!next_line(line) || line != "ply") bad("not a PLY file: the first line is not 'ply'");
  bool have_format = false;
  for (;;) {
    if (!next_line(line)) bad("PLY header has no end_header line");
    const auto w = words(line);
    if (w.empty() || w[0] == "comment" || w[0] == "obj_info") continue;
    if (w[0] == "end_header") break;
    if (w[0] == "format") {
      if (w.size() < 2) bad("PLY format line is incomplete");
      if (w[1] == "ascii") h.format = 0;
      else if (w[1] == "binary_little_endian") h.format = 1;
      else if (w[1] == "binary_big_endian") h.format = 2;
      else bad("unknown PLY format '" + std::string(w[1]) + "'");
      have_format = true;
    } else if (w[0] == "element") {
      if (w.size() != 3) bad("PLY element line must be 'element NAME COUNT'");
      Element e;
      e.name = std::string(w[1]);
      auto r = std::from_chars(w[2].data(), w[2].data() + w[2].size(), e.count);
      if (r.ec != std::errc() || r.ptr != w[2].data() + w[2].size())
        bad("PLY element '" + e.name + "' has an invalid count");
      h.elements.push_back(std::move(e));
    } else if (w[0] == "property") {
      if (h.elements.empty()) bad("PLY property before any element");
      Prop p;
      if (w.size() == 5 && w[1] == "list") {
        p.list = true;
        if (!parse_type(w[2], p.count_type) || !parse_type(w[3], p.type))
          bad("PLY list property has an unknown type");
        if (p.count_type == Type::f32 || p.count_type == Type::f64) bad("PLY list count must be an integer type");
        p.name = std::string(w[4]);
      } else if (w.size() == 3) {
        if (!parse_type(w[1], p.type)) bad("PLY property has unknown type '" + std::string(w[1]) + "'");
        p.name = std::string(w[2]);
      } else {
        bad("PLY property line is malformed");
      }
      h.elements.back().props.push_back(std::move(p));
    } else {
      bad("unknown PLY header line '" + std::string(line.substr(0, 40)) + "'");
    }
  }
  if (!have_format) bad("PLY header has no format line");
  h.body = pos;
  return h;
}

bool is_face_list(const Prop& p) { return p.list && (p.name == "vertex_indices" || p.name == "vertex_index"); }

void prepare(PlyMesh& m, const Element& e, bool is_vertex, bool has_uv, bool has_n) {
  if (is_vertex) {
    m.positions.reserve(3 * e.count + 1);  // (+1: the padding finalize_scene adds for Embree, without a copy)
    m.positions.resize(3 * e.count);
    if (has_uv) m.uvs.resize(2 * e.count);
    if (has_n) m.normals.resize(3 * e.count);
  }
}

void store_vertex(PlyMesh& m, uint64_t i, Slot s, double v) {
  switch (s) {
    case px: case py: case pz: m.positions[3 * i + (s - px)] = float(v); break;
    case pu: case pv: m.uvs[2 * i + (s - pu)] = float(v); break;
    case nx: case ny: case nz: m.normals[3 * i + (s - nx)] = float(v); break;
    default: break;
  }
}

// A face element that is one list of exactly 3 indices per face (the usual triangle mesh):
// fixed records, decoded in parallel blocks of `chunk` faces. Returns false (nothing
// consumed, indices cleared) where some face is not a triangle or the data is short: the
// sequential reader then takes the element. Repeated indices drop the face, as the
// sequential reader does; an index out of range is its error for the first such face.
bool parse_triangles(const char* p, const char* end, const Element& e, bool swap, uint64_t chunk, PlyMesh& m,
                     uint64_t vcount, uint64_t face0) {
  const Prop& pr = e.props[0];
  const size_t csz = type_size(pr.count_type), isz = type_size(pr.type), rec = csz + 3 * isz;
  if (e.count > size_t(end - p) / rec) return false;
  m.indices.resize(3 * e.count);
  std::atomic<bool> not_triangles{false};
  std::atomic<uint64_t> first_bad{UINT64_MAX};
  constexpr uint32_t dropped = 0xffffffffu;
  tbb::parallel_for(tbb::blocked_range<uint64_t>(0, e.count, chunk), [&](const tbb::blocked_range<uint64_t>& r) {
    for (uint64_t i = r.begin(); i < r.end(); ++i) {
      const char* q = p + i * rec;
      if (load_int(q, pr.count_type, swap) != 3) {
        not_triangles = true;
        return;
      }
      int64_t v[3];
      for (int j = 0; j < 3; ++j) v[j] = load_int(q + csz + j * isz, pr.type, swap);
      bool in_range = true;
      for (int64_t x : v) in_range = in_range && x >= 0 && uint64_t(x) < vcount;
      if (!in_range) {
        uint64_t cur = first_bad.load();
        while (i < cur && !first_bad.compare_exchange_weak(cur, i)) {
        }
        return;
      }
      const bool degenerate = v[0] == v[1] || v[1] == v[2] || v[0] == v[2];
      for (int j = 0; j < 3; ++j) m.indices[3 * i + j] = degenerate ? dropped : uint32_t(v[j]);
    }
  });
  if (not_triangles) {
    m.indices.clear();
    return false;
  }
  if (first_bad.load() != UINT64_MAX) {
    const uint64_t i = first_bad.load();
    const char* q = p + i * rec + csz;
    for (int j = 0; j < 3; ++j) {
      const int64_t x = load_int(q + j * isz, pr.type, swap);
      if (x < 0 || uint64_t(x) >= vcount)
        bad("face " + std::to_string(face0 + i) + " has vertex index " + std::to_string(x) + " out of range",
            "an index below the vertex count " + std::to_string(vcount));
    }
  }
  size_t out = 0;
  for (size_t t = 0; t < m.indices.size(); t += 3) {
    if (m.indices[t] == dropped) {
      ++m.degenerate;
      continue;
    }
    if (out != t) std::copy_n(m.indices.begin() + std::ptrdiff_t(t), 3, m.indices.begin() + std::ptrdiff_t(out));
    out += 3;
  }
  m.indices.resize(out);
  return true;
}

void parse_binary(std::string_view data, const Header& h, PlyMesh& m, bool want_normals, uint64_t vcount,
                  uint64_t chunk) {
  const bool swap = (h.format == 2) != (std::endian::native == std::endian::big);
  const char* p = data.data() + h.body;
  const char* end = data.data() + data.size();
  FaceSink sink{m, vcount};
  for (const Element& e : h.elements) {
    const bool is_vertex = e.name == "vertex";
    const bool is_face = e.name == "face";
    std::vector<Slot> slots(e.props.size(), none);
    bool has_uv = false, has_n = false, fixed = true;
    size_t stride = 0;
    for (size_t k = 0; k < e.props.size(); ++k) {
      const Prop& pr = e.props[k];
      if (pr.list) fixed = false;
      else stride += type_size(pr.type);
      if (is_vertex && !pr.list) {
        slots[k] = vertex_slot(pr.name, want_normals);
        has_uv |= slots[k] == pu || slots[k] == pv;
        has_n |= slots[k] >= nx;
      }
    }
    const size_t left = size_t(end - p);
    if (fixed && stride > 0 && e.count > left / stride)
      bad("PLY file is truncated: element '" + e.name + "' needs more data than the file holds");
    if (!fixed && e.count > left) bad("PLY file is truncated in element '" + e.name + "'");
    prepare(m, e, is_vertex, has_uv, has_n);
    if (is_face) m.indices.reserve(std::min<uint64_t>(e.count, left / 4) * 3);
    if (fixed && !is_vertex) {  // nothing to read: skip the block
      p += e.count * stride;
      continue;
    }
    // large elements in parallel blocks (oneTBB): fixed-size vertices, and faces that are all
    // triangles (one list property); the records are independent
    if (fixed && is_vertex && stride > 0 && e.count >= chunk) {
      tbb::parallel_for(tbb::blocked_range<uint64_t>(0, e.count, chunk), [&](const tbb::blocked_range<uint64_t>& r) {
        for (uint64_t i = r.begin(); i < r.end(); ++i) {
          const char* q = p + i * stride;
          for (size_t k = 0; k < e.props.size(); ++k) {
            if (slots[k] != none) store_vertex(m, i, slots[k], load_num(q, e.props[k].type, swap));
            q += type_size(e.props[k].type);
          }
        }
      });
      p += e.count * stride;
      continue;
    }
    if (is_face && e.count >= chunk && e.props.size() == 1 && is_face_list(e.props[0]) &&
        m.indices.empty() && parse_triangles(p, end, e, swap, chunk, m, vcount, sink.face)) {
      p += e.count * (type_size(e.props[0].count_type) + 3 * type_size(e.props[0].type));
      sink.face += e.count;
      continue;
    }
    for (uint64_t i = 0; i < e.count; ++i) {
      for (size_t k = 0; k < e.props.size(); ++k) {
        const Prop& pr = e.props[k];
        if (!pr.list) {
          const size_t sz = type_size(pr.type);
          if (size_t(end - p) < sz) bad("PLY file is truncated in element '" + e.name + "'");
          if (slots[k] != none) store_vertex(m, i, slots[k], load_num(p, pr.type, swap));
          p += sz;
          continue;
        }
        const size_t csz = type_size(pr.count_type), isz = type_size(pr.type);
        if (size_t(end - p) < csz) bad("PLY file is truncated in element '" + e.name + "'");
        const int64_t n = load_int(p, pr.count_type, swap);
        p += csz;
        if (n < 0 || uint64_t(n) > size_t(end - p) / isz)
          bad("PLY file is truncated or has a bad list length in element '" + e.name + "'");
        if (is_face && is_face_list(pr)) {
          if (n > max_face_vertices)
            bad("face " + std::to_string(sink.face) + " has " + std::to_string(n) +
                " vertices",
                "at most " + std::to_string(max_face_vertices) + " vertices per face");
          for (int64_t j = 0; j < n; ++j) sink.idx[j] = load_int(p + j * isz, pr.type, swap);
          sink.finish(n);
        }
        p += n * isz;
      }
    }
  }
}

// ASCII: whitespace-separated numbers, read in header order.
struct AsciiCursor {
  const char* p;
  const char* end;
  double next(const std::string& elem) {
    while (p < end && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r')) ++p;
    if (p >= end) bad("PLY file is truncated in element '" + elem + "'");
    double v = 0;
    auto r = std::from_chars(p, end, v);
    if (r.ec == std::errc::result_out_of_range) bad("PLY number out of range in element '" + elem + "'");
    if (r.ec != std::errc() || (r.ptr < end && !(*r.ptr == ' ' || *r.ptr == '\t' || *r.ptr == '\n' || *r.ptr == '\r')))
      bad("PLY file has an invalid number in element '" + elem + "'");
    p = r.ptr;
    return v;
  }
};

void parse_ascii(std::string_view data, const Header& h, PlyMesh& m, bool want_normals, uint64_t vcount) {
  AsciiCursor c{data.data() + h.body, data.data() + data.size()};
  FaceSink sink{m, vcount};
  for (const Element& e : h.elements) {
    const bool is_vertex = e.name == "vertex";
    const bool is_face = e.name == "face";
    std::vector<Slot> slots(e.props.size(), none);
    bool has_uv = false, has_n = false;
    for (size_t k = 0; k < e.props.size(); ++k)
      if (is_vertex && !e.props[k].list) {
        slots[k] = vertex_slot(e.props[k].name, want_normals);
        has_uv |= slots[k] == pu || slots[k] == pv;
        has_n |= slots[k] >= nx;
      }
    // Each value takes at least two characters: a digit and a separator.
    if (!e.props.empty() && e.count > size_t(c.end - c.p) / 2)
      bad("PLY file is truncated: element '" + e.name + "' needs more data than the file holds");
    prepare(m, e, is_vertex, has_uv, has_n);
    for (uint64_t i = 0; i < e.count; ++i)
      for (size_t k = 0; k < e.props.size(); ++k) {
        const Prop& pr = e.props[k];
        if (!pr.list) {
          const double v = c.next(e.name);
          if (slots[k] != none) store_vertex(m, i, slots[k], v);
          continue;
        }
        const double nd = c.next(e.name);
        if (!(nd >= 0 && nd <= 1e9) || nd != std::floor(nd)) bad("PLY list has a bad length in element '" + e.name + "'");
        const int64_t n = int64_t(nd);
        const bool face_list = is_face && is_face_list(pr);
        if (face_list && n > max_face_vertices)
          bad("face " + std::to_string(sink.face) + " has " + std::to_string(n) + " vertices",
              "at most " + std::to_string(max_face_vertices) + " vertices per face");
        for (int64_t j = 0; j < n; ++j) {
          const double v = c.next(e.name);
          if (face_list) sink.idx[j] = std::isfinite(v) && v == std::floor(v) && std::abs(v) < 9e18 ? int64_t(v) : -1;
        }
        if (face_list) sink.finish(n);
      }
  }
}

}  // namespace

PlyMesh parse_ply(std::string_view data, bool want_normals, uint64_t chunk) {
  const Header h = parse_header(data);
  uint64_t vcount = 0;
  bool have_vertex = false, have_xyz = false;
  for (const Element& e : h.elements)
    if (e.name == "vertex") {
      have_vertex = true;
      vcount = e.count;
      int found = 0;
      for (const Prop& p : e.props) found += !p.list && (p.name == "x" || p.name == "y" || p.name == "z");
      have_xyz = found == 3;
    }
  if (!have_vertex) bad("PLY file has no vertex element");
  if (!have_xyz) bad("PLY vertex element lacks x, y and z properties");
  if (vcount > 0xffffffffull) bad("PLY file has more than 2^32 vertices");
  PlyMesh m;
  if (h.format == 0) parse_ascii(data, h, m, want_normals, vcount);
  else parse_binary(data, h, m, want_normals, vcount, std::max<uint64_t>(chunk, 1));
  // Drop triangles of exactly zero area (collinear or coincident vertices).
  const float* P = m.positions.data();
  size_t out = 0;
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    const uint32_t a = m.indices[t], b = m.indices[t + 1], c = m.indices[t + 2];
    const double e1[3] = {double(P[3 * b]) - P[3 * a], double(P[3 * b + 1]) - P[3 * a + 1], double(P[3 * b + 2]) - P[3 * a + 2]};
    const double e2[3] = {double(P[3 * c]) - P[3 * a], double(P[3 * c + 1]) - P[3 * a + 1], double(P[3 * c + 2]) - P[3 * a + 2]};
    const double cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2], cz = e1[0] * e2[1] - e1[1] * e2[0];
    if (cx == 0 && cy == 0 && cz == 0) {
      ++m.degenerate;
      continue;
    }
    m.indices[out++] = a;
    m.indices[out++] = b;
    m.indices[out++] = c;
  }
  m.indices.resize(out);
  return m;
}

}  // namespace tuile::pbrt
