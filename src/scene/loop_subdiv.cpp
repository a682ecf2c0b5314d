// Loop subdivision (loop_subdiv.h): the mesh as arrays (triangles, the neighbour across
// each edge), its topology rebuilt at every level from the new triangles.
#include "scene/loop_subdiv.h"

#include <array>
#include <cmath>
#include <numbers>
#include <unordered_map>

namespace tuile {

namespace {

using P3 = std::array<double, 3>;

P3 operator+(P3 a, P3 b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
P3 operator-(P3 a, P3 b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
P3 operator*(double s, P3 a) { return {s * a[0], s * a[1], s * a[2]}; }

constexpr int next3(int k) { return k == 2 ? 0 : k + 1; }
constexpr int prev3(int k) { return k == 0 ? 2 : k - 1; }

// Loop's weight of each one-ring neighbour of an interior vertex of valence n, and the
// weight of the limit position's.
double loop_beta(int n) { return n == 3 ? 3.0 / 16.0 : 3.0 / (8.0 * n); }
double loop_gamma(int n) { return 1.0 / (n + 3.0 / (8.0 * loop_beta(n))); }

// Triangles with the neighbour across each edge and, per vertex, its fan.
struct Topology {
  const std::vector<uint32_t>* tri = nullptr;
  std::vector<int64_t> nb;        // 3 per triangle: across edge k = (v[k], v[k+1]); -1 on a boundary
  std::vector<int64_t> start;     // per vertex: a triangle of its fan (for a boundary vertex the
                                  // one at the end reached by next_face); -1 when unused
  std::vector<uint8_t> boundary;  // per vertex
  std::vector<int32_t> valence;   // per vertex: its neighbours (triangles, +1 on a boundary)

  uint32_t v(int64_t f, int k) const { return (*tri)[static_cast<size_t>(3 * f + k)]; }
  int vnum(int64_t f, uint32_t vert) const { return v(f, 0) == vert ? 0 : v(f, 1) == vert ? 1 : 2; }
  // pbrt-v4's traversal: the next triangle around `vert` is across the edge (vert, the
  // vertex after it), the previous one across the edge (the vertex before it, vert).
  int64_t next_face(int64_t f, uint32_t vert) const { return nb[static_cast<size_t>(3 * f + vnum(f, vert))]; }
  int64_t prev_face(int64_t f, uint32_t vert) const { return nb[static_cast<size_t>(3 * f + prev3(vnum(f, vert)))]; }
  uint32_t next_vert(int64_t f, uint32_t vert) const { return v(f, next3(vnum(f, vert))); }
  uint32_t prev_vert(int64_t f, uint32_t vert) const { return v(f, prev3(vnum(f, vert))); }

  // The one ring in pbrt-v4's order: interior, the vertices after `vert` in each triangle
  // walking next_face; boundary, from the last triangle's next vertex back along prev_face.
  void ring(uint32_t vert, std::vector<uint32_t>& out) const {
    out.clear();
    int64_t f = start[vert];
    if (f < 0) return;
    if (!boundary[vert]) {
      do {
        out.push_back(next_vert(f, vert));
        f = next_face(f, vert);
      } while (f != start[vert]);
      return;
    }
    out.push_back(next_vert(f, vert));
    do {
      out.push_back(prev_vert(f, vert));
      f = prev_face(f, vert);
    } while (f >= 0);
  }
};

bool build(const std::vector<uint32_t>& tri, size_t nv, Topology& t, std::string& why) {
  t.tri = &tri;
  const size_t nf = tri.size() / 3;
  t.nb.assign(tri.size(), -1);
  t.start.assign(nv, -1);
  t.boundary.assign(nv, 0);
  t.valence.assign(nv, 0);
  std::vector<int32_t> fan(nv, 0);
  std::unordered_map<uint64_t, int64_t> directed;  // (a, b) -> 3 f + k
  directed.reserve(tri.size() * 2);
  for (size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = tri[3 * f + k], b = tri[3 * f + next3(k)];
      if (a == b) {
        why = "triangle " + std::to_string(f) + " repeats vertex " + std::to_string(a);
        return false;
      }
      const uint64_t key = (uint64_t(a) << 32) | b;
      if (!directed.emplace(key, static_cast<int64_t>(3 * f + k)).second) {
        why = "the edge " + std::to_string(a) + "-" + std::to_string(b) +
              " belongs to two triangles in the same direction (more than two triangles share it, or their winding "
              "is inconsistent)";
        return false;
      }
      ++fan[a];
      t.start[a] = static_cast<int64_t>(f);
    }
  for (size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = tri[3 * f + k], b = tri[3 * f + next3(k)];
      const auto it = directed.find((uint64_t(b) << 32) | a);
      if (it != directed.end()) t.nb[3 * f + k] = it->second / 3;
    }
  for (uint32_t v = 0; v < nv; ++v) {
    if (t.start[v] < 0) continue;  // unused: no ring, left where it is
    int64_t f = t.start[v];
    int count = 0;
    do {  // round the fan, or to its end
      f = t.next_face(f, v);
      ++count;
    } while (f >= 0 && f != t.start[v] && count <= fan[v]);
    if (f < 0) {
      t.boundary[v] = 1;
      f = t.start[v];
      for (int64_t g; (g = t.next_face(f, v)) >= 0;) f = g;
      t.start[v] = f;
      count = 0;
      for (int64_t g = f; g >= 0; g = t.prev_face(g, v)) ++count;
    }
    if (count != fan[v]) {
      why = "vertex " + std::to_string(v) + "'s triangles form more than one fan (a non-manifold vertex)";
      return false;
    }
    t.valence[v] = fan[v] + t.boundary[v];
  }
  return true;
}

P3 at(const std::vector<P3>& p, uint32_t i) { return p[i]; }

// (1 - n w) p + w (sum of the ring), and on a boundary (1 - 2 w) p + w (its two boundary neighbours).
P3 weigh(const Topology& t, const std::vector<P3>& p, uint32_t v, double w, std::vector<uint32_t>& ring) {
  t.ring(v, ring);
  if (ring.empty()) return p[v];
  if (t.boundary[v]) return (1 - 2 * w) * p[v] + w * (at(p, ring.front()) + at(p, ring.back()));
  P3 s = (1 - static_cast<double>(ring.size()) * w) * p[v];
  for (uint32_t r : ring) s = s + w * p[r];
  return s;
}

P3 cross(P3 a, P3 b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }

}  // namespace

bool loop_subdivide(const std::vector<float>& positions, const std::vector<uint32_t>& indices, int levels, LoopMesh& out,
                    std::string& why, size_t max_triangles) {
  if (levels < 0) {
    why = "levels " + std::to_string(levels) + " is negative";
    return false;
  }
  if (indices.size() % 3 != 0 || positions.size() % 3 != 0) {
    why = "the indices or positions are not whole triangles or points";
    return false;
  }
  const size_t nv0 = positions.size() / 3;
  for (uint32_t i : indices)
    if (i >= nv0) {
      why = "index " + std::to_string(i) + " is out of range";
      return false;
    }
  double tris = static_cast<double>(indices.size() / 3);
  for (int l = 0; l < levels; ++l) tris *= 4;
  if (tris > static_cast<double>(max_triangles)) {
    why = "levels " + std::to_string(levels) + " would make " + std::to_string(static_cast<double>(tris)) +
          " triangles (at most " + std::to_string(max_triangles) + ")";
    return false;
  }
  std::vector<P3> p(nv0);
  for (size_t i = 0; i < nv0; ++i) p[i] = {positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
  std::vector<uint32_t> tri = indices;
  std::vector<uint32_t> ring;
  Topology t;
  if (!build(tri, p.size(), t, why)) return false;

  for (int l = 0; l < levels; ++l) {
    const size_t nv = p.size(), nf = tri.size() / 3;
    // the edges, numbered once each (a shared edge takes its first triangle's number)
    std::vector<int64_t> edge(tri.size(), -1);
    size_t ne = 0;
    for (size_t f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) {
        if (edge[3 * f + k] >= 0) continue;
        edge[3 * f + k] = static_cast<int64_t>(ne);
        const int64_t g = t.nb[3 * f + k];
        if (g >= 0) edge[static_cast<size_t>(3 * g + t.vnum(g, tri[3 * f + next3(k)]))] = static_cast<int64_t>(ne);
        ++ne;
      }
    std::vector<P3> q(nv + ne);
    // even vertices: the one-ring rule (the regular valence 6 gives 1/16), boundaries 3/4, 1/8, 1/8
    for (uint32_t v = 0; v < nv; ++v)
      q[v] = t.boundary[v] ? weigh(t, p, v, 1.0 / 8.0, ring) : weigh(t, p, v, loop_beta(t.valence[v]), ring);
    // odd vertices: 3/8 the edge's ends and 1/8 the opposite vertices, 1/2 and 1/2 on a boundary
    std::vector<uint8_t> done(ne, 0);
    for (size_t f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) {
        const size_t e = static_cast<size_t>(edge[3 * f + k]);
        if (done[e]) continue;
        done[e] = 1;
        const uint32_t a = tri[3 * f + k], b = tri[3 * f + next3(k)];
        const int64_t g = t.nb[3 * f + k];
        if (g < 0) {
          q[nv + e] = 0.5 * (p[a] + p[b]);
        } else {
          const uint32_t c = tri[3 * f + prev3(k)];
          const uint32_t d = tri[static_cast<size_t>(3 * g + prev3(t.vnum(g, b)))];
          q[nv + e] = (3.0 / 8.0) * (p[a] + p[b]) + (1.0 / 8.0) * (p[c] + p[d]);
        }
      }
    // each triangle into four, the winding kept: (v0 e0 e2), (e0 v1 e1), (e2 e1 v2), (e0 e1 e2)
    std::vector<uint32_t> next(tri.size() * 4);
    for (size_t f = 0; f < nf; ++f) {
      const uint32_t v0 = tri[3 * f], v1 = tri[3 * f + 1], v2 = tri[3 * f + 2];
      const uint32_t e0 = static_cast<uint32_t>(nv + edge[3 * f]), e1 = static_cast<uint32_t>(nv + edge[3 * f + 1]),
                     e2 = static_cast<uint32_t>(nv + edge[3 * f + 2]);
      const uint32_t four[12] = {v0, e0, e2, e0, v1, e1, e2, e1, v2, e0, e1, e2};
      std::copy(four, four + 12, next.begin() + static_cast<std::ptrdiff_t>(12 * f));
    }
    p = std::move(q);
    tri = std::move(next);
    if (!build(tri, p.size(), t, why)) return false;  // cannot fail on a manifold's subdivision
  }

  // the limit positions, then the limit normals from the rings of limit positions
  const size_t nv = p.size();
  std::vector<P3> lim(nv);
  for (uint32_t v = 0; v < nv; ++v)
    lim[v] = t.boundary[v] ? weigh(t, p, v, 1.0 / 5.0, ring) : weigh(t, p, v, loop_gamma(t.valence[v]), ring);
  out.positions.resize(3 * nv);
  out.normals.assign(3 * nv, 0.f);
  std::vector<P3> r;
  for (uint32_t v = 0; v < nv; ++v) {
    for (int c = 0; c < 3; ++c) out.positions[3 * v + c] = static_cast<float>(lim[v][c]);
    t.ring(v, ring);
    if (ring.empty()) continue;
    r.clear();
    for (uint32_t i : ring) r.push_back(lim[i]);
    const int n = static_cast<int>(r.size());
    P3 s{0, 0, 0}, u{0, 0, 0};
    if (!t.boundary[v]) {
      for (int j = 0; j < n; ++j) {
        const double phi = 2 * std::numbers::pi * j / n;
        s = s + std::cos(phi) * r[static_cast<size_t>(j)];
        u = u + std::sin(phi) * r[static_cast<size_t>(j)];
      }
    } else {
      // the tangent along the boundary, and one across it (Hoppe et al. 1994's boundary masks)
      s = r.back() - r.front();
      if (n == 2) {
        u = r[0] + r[1] - 2.0 * lim[v];
      } else if (n == 3) {
        u = r[1] - lim[v];
      } else if (n == 4) {
        u = -1.0 * r[0] + 2.0 * r[1] + 2.0 * r[2] - 1.0 * r[3] - 2.0 * lim[v];
      } else {
        const double theta = std::numbers::pi / (n - 1);
        u = std::sin(theta) * (r.front() + r.back());
        for (int k = 1; k < n - 1; ++k) u = u + ((2 * std::cos(theta) - 2) * std::sin(k * theta)) * r[static_cast<size_t>(k)];
        u = -1.0 * u;
      }
    }
    const P3 nrm = cross(s, u);
    const double len = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    if (len > 0 && std::isfinite(len))
      for (int c = 0; c < 3; ++c) out.normals[3 * v + c] = static_cast<float>(nrm[c] / len);
  }
  out.indices = std::move(tri);
  return true;
}

}  // namespace tuile
