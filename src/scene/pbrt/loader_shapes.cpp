// The pbrt-v4 reader's shapes: trianglemesh, bilinearmesh (patches split into triangle
// pairs), loopsubdiv (Loop subdivision: scene/loop_subdiv.h), plymesh (recorded, read by loader_files.cpp),
// sphere, disk (a 64-gon of the same area, a sector for phimax) and cylinder (a band of 128
// quads of the same area, radial shading normals), emitting when the graphics state has an
// area light (triangles oriented by their shading normals, as pbrt-v4 does). At the end,
// flatten applies area-light powers and places object instances (place_instances: real
// instances, or world-space copies of objects that bound media).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

#include "lexer.h"
#include "loader_state.h"
#include "scene/loop_subdiv.h"
#include "params.h"
#include "util.h"

namespace tuile::pbrt {
namespace {

constexpr int disk_segments = 64;
constexpr size_t max_triangles = size_t(1) << 31;

}  // namespace

double phimax_of(Lexer& lx, const Token& t, Params& ps);  // a quadric's phimax in radians, checked

size_t Loader::new_mesh(Lexer& lx, const Token& t) {
  OwnedMesh om;
  om.object = object_;
  om.mesh.name = loc_str(lx, t);
  om.mesh.material = gs_.material;
  om.media = {gs_.medium_in, gs_.medium_out, gs_.medium_where};
  om.mesh.reverse_orientation = gs_.reverse != gs_.ctm.swaps_handedness();
  set_emission(om, lx, t);
  meshes_.push_back(std::move(om));
  return meshes_.size() - 1;
}

void Loader::set_emission(OwnedMesh& om, Lexer& lx, const Token& t) {
  if (!gs_.has_area) return;
  if (object_ >= 0) {
    warn("instarea", loc_str(lx, t) + ": area lights inside object definitions are not supported: the shape does not emit");
    return;
  }
  om.mesh.emission = gs_.area.L;
  om.mesh.two_sided = gs_.area.two_sided;
  om.power = gs_.area.power;
  om.power_where = loc_str(lx, t);
}

void Loader::set_shading_normals(Mesh& m, const std::vector<float>& n_obj, const Mat4& ctm, bool ro) {
  if (n_obj.empty() || n_obj.size() != m.positions.size() - m.positions.size() % 3) return;
  Mat4 inv;
  if (!invert(ctm, inv)) return;
  m.normals.resize(n_obj.size());
  for (size_t i = 0; i + 2 < n_obj.size(); i += 3) {
    const Vec3d nw = apply_normal_inv(inv, {n_obj[i], n_obj[i + 1], n_obj[i + 2]});
    const double l = std::sqrt(nw.x * nw.x + nw.y * nw.y + nw.z * nw.z);
    const double s = l > 0 && std::isfinite(l) ? (ro ? -1 : 1) / l : 0;
    m.normals[i] = static_cast<float>(nw.x * s);
    m.normals[i + 1] = static_cast<float>(nw.y * s);
    m.normals[i + 2] = static_cast<float>(nw.z * s);
  }
}

// pbrt-v4 turns a triangle's geometric normal towards its shading normal when the mesh
// has normals (N, flipped by ReverseOrientation): emission follows N, not the winding.
void Loader::orient_by_normals(Mesh& m, const std::vector<float>& n_obj, const Mat4& ctm, bool ro) {
  if (!m.emissive() || n_obj.size() != m.positions.size()) return;
  Mat4 inv;
  if (!invert(ctm, inv)) return;
  const float* P = m.positions.data();
  const size_t nt = m.triangle_count();
  std::vector<char> flip(nt, 0);
  size_t flips = 0;
  for (size_t i = 0; i < nt; ++i) {
    const uint32_t* v = &m.indices[3 * i];
    auto pos = [&](uint32_t k) { return Vec3d{P[3 * k], P[3 * k + 1], P[3 * k + 2]}; };
    const Vec3d w = cross(sub(pos(v[1]), pos(v[0])), sub(pos(v[2]), pos(v[0])));
    Vec3d ns;
    for (int k = 0; k < 3; ++k) {
      const float* n = &n_obj[3 * v[k]];
      const Vec3d nw = apply_normal_inv(inv, {n[0], n[1], n[2]});
      ns = {ns.x + nw.x, ns.y + nw.y, ns.z + nw.z};
    }
    double dd = dot(w, ns);
    if (ro) dd = -dd;
    flip[i] = dd < 0;
    flips += flip[i];
  }
  m.reverse_orientation = false;
  if (flips == 0) return;
  if (flips == nt) {
    m.reverse_orientation = true;
    return;
  }
  for (size_t i = 0; i < nt; ++i)
    if (flip[i]) std::swap(m.indices[3 * i + 1], m.indices[3 * i + 2]);
}

// trianglemesh, bilinearmesh (each patch two triangles: a parallelogram pair) and
// loopsubdiv (subdivided `levels` times, 3 by default, with the limit surface's positions
// and normals: scene/loop_subdiv.h; a control mesh Loop's rules do not apply to is
// rendered as it is, with a warning): vertices, indices, uv and normals checked against
// each other, positions transformed to world space.
void Loader::mesh_shape(Lexer& lx, const Token& t, const std::string& type, Params& ps, const std::string& where) {
  const bool bilinear = type == "bilinearmesh";
  const size_t per = bilinear ? 4 : 3;
  const Param* P = ps.get("P", "point3");
  if (!P) lx.fail(t, type + " without \"point3 P\"", "a \"point3 P\" parameter");
  const size_t nv = P->nums.size() / 3;
  const Param* I = ps.get("indices", "integer");
  if (!I && nv != per)
    lx.fail(t, type + " without \"integer indices\"", "indices, or exactly " + std::to_string(per) + " vertices");
  if (I && I->nums.size() % per != 0)
    I->fail("\"integer indices\" has " + std::to_string(I->nums.size()) + " values", "a multiple of " + std::to_string(per));
  if (I)
    for (double v : I->nums)
      if (v < 0 || v >= double(nv))
        I->fail("index " + std::to_string(int64_t(v)) + " out of range", "an index below the vertex count " + std::to_string(nv));
  const Param* uv = ps.get("uv", "point2|float");
  if (uv && uv->nums.size() != 2 * nv)
    uv->fail("\"uv\" has " + std::to_string(uv->nums.size() / 2) + " pairs for " + std::to_string(nv) + " vertices", "one uv pair per vertex");
  const Param* N = ps.get("N", "normal3");
  if (N && N->nums.size() != 3 * nv)
    N->fail("\"N\" has " + std::to_string(N->nums.size() / 3) + " normals for " + std::to_string(nv) + " vertices", "one normal per vertex");
  // tangents and face indices are not used, but a wrong count means a broken mesh, as for uv
  // and N (pbrt-v4 discards them with an error)
  const Param* S = ps.get("S", "vector3");
  if (S && S->nums.size() != 3 * nv)
    S->fail("\"S\" has " + std::to_string(S->nums.size() / 3) + " tangents for " + std::to_string(nv) + " vertices", "one tangent per vertex");
  const Param* F = ps.get("faceIndices", "integer");
  const size_t faces = I ? I->nums.size() / per : 1;
  if (F && F->nums.size() != faces)
    F->fail("\"faceIndices\" has " + std::to_string(F->nums.size()) + " values for " + std::to_string(faces) + " faces", "one face index per face");
  std::vector<uint32_t> idx;
  if (I) idx.assign(I->nums.begin(), I->nums.end());
  else
    for (uint32_t i = 0; i < per; ++i) idx.push_back(i);
  std::vector<float> pos(P->nums.begin(), P->nums.end());
  std::vector<float> n_obj;
  if (N) n_obj.assign(N->nums.begin(), N->nums.end());
  bool keep_uv = uv != nullptr;
  if (type == "loopsubdiv") {
    // subdivided in object space as pbrt-v4 does: limit positions and normals, no uv
    const Param* L = ps.get("levels", "integer");
    const int levels = ps.one_int("levels", 3);
    if (levels < 0 || levels > 12) {
      if (L) L->fail("\"levels\" " + std::to_string(levels) + " out of range", "0..12 (each level makes 4 times the triangles)");
      lx.fail(t, "levels out of range", "0..12");
    }
    // its memory before it starts: a render of a subdivided mesh peaks at about 250 bytes a
    // triangle (measured, levels 8 to 10), which must fit in the machine's memory
    const double tris = double(idx.size() / 3) * std::pow(4.0, levels), bytes = 250 * tris;
    const double phys = double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
    const auto gb = [](double b) { return std::to_string(int64_t(std::ceil(b / 1e9))) + " GB"; };
    if (phys > 0 && bytes > phys)
      lx.fail(t, "loopsubdiv: levels " + std::to_string(levels) + " makes " + std::to_string(int64_t(tris)) + " triangles, about " +
                     gb(bytes) + " of memory to subdivide and render, more than this machine's " + gb(phys),
              "fewer levels (each makes 4 times the triangles)");
    if (bytes > 2e9)
      note("loopsubdiv:" + where, where + ": loopsubdiv at levels " + std::to_string(levels) + " makes " + std::to_string(int64_t(tris)) +
                                      " triangles: about " + gb(bytes) + " of memory");
    LoopMesh lm;
    std::string why;
    if (loop_subdivide(pos, idx, levels, lm, why)) {
      pos = std::move(lm.positions);
      idx = std::move(lm.indices);
      n_obj = std::move(lm.normals);
      keep_uv = false;
    } else if (why.rfind("levels", 0) == 0) {
      lx.fail(t, "loopsubdiv: " + why, "fewer levels");
    } else {
      warn("loopsubdiv", where + ": loopsubdiv is not subdivided (" + why + "): its control mesh is rendered");
    }
  }
  const size_t mi = new_mesh(lx, t);
  Mesh& m = meshes_[mi].mesh;
  m.positions = std::move(pos);
  transform_positions(gs_.ctm, m.positions.data(), m.positions.size() / 3);
  if (keep_uv) m.uvs.assign(uv->nums.begin(), uv->nums.end());
  if (bilinear) {
    // patch (p00, p10, p01, p11) -> triangles (p00 p10 p11), (p00 p11 p01): one parallelogram pair
    for (size_t q = 0; q < idx.size(); q += 4) {
      const uint32_t a = idx[q], b = idx[q + 1], c = idx[q + 2], e = idx[q + 3];
      m.indices.insert(m.indices.end(), {a, b, e, a, e, c});
    }
  } else {
    m.indices = std::move(idx);
  }
  if (!n_obj.empty()) {
    orient_by_normals(m, n_obj, gs_.ctm, gs_.reverse);
    set_shading_normals(m, n_obj, gs_.ctm, gs_.reverse);
  }
}

// plymesh: the file is read (in parallel with the others) when the scene ends.
void Loader::ply_shape(Lexer& lx, const Token& t, Params& ps) {
  const Param* fp = ps.get("filename", "string");
  if (!fp || fp->strs.size() != 1) lx.fail(t, "plymesh without a filename", "a \"string filename\" parameter");
  PlyJob j;
  j.path = resolve_path(lx.dir(), fp->strs[0]);
  j.where_file = lx.file();
  j.line = t.line;
  j.col = t.col;
  j.ctm = gs_.ctm;
  j.ro = gs_.reverse;
  j.mesh = new_mesh(lx, t);
  scene.inputs.push_back(j.path);
  plys_.push_back(std::move(j));
}

// sphere: a full sphere (partial ones with a warning), its radius scaled by the transform
// (a sphere of the same volume under a non-uniform scale), emitting if an area light is on.
void Loader::sphere_shape(Lexer& lx, const Token& t, Params& ps, const std::string& where) {
  const float r = ps.one_float("radius", 1);
  if (!(r > 0)) lx.fail(t, "sphere radius " + std::to_string(r), "a positive radius");
  const float z0 = ps.one_float("zmin", -r), z1 = ps.one_float("zmax", r);
  const double phimax = phimax_of(lx, t, ps);
  const float zmin = std::clamp(std::min(z0, z1), -r, r), zmax = std::clamp(std::max(z0, z1), -r, r);
  if (!(zmin < zmax)) lx.fail(t, "sphere zmin and zmax leave nothing", "zmin < zmax within [-radius, radius]");
  if (zmin > -r || zmax < r || phimax < 2 * M_PI - 1e-9) {
    partial_sphere(lx, t, r, zmin, zmax, phimax);
    return;
  }
  // A sphere that emits inwards (a dome round the scene: ReverseOrientation, or a mirroring
  // transform) or from both sides: the analytic sphere's light is sampled from outside only,
  // so it is tessellated as a partial sphere is, and its triangles emit as any mesh's do
  // (one-sided inwards, or two-sided; the same area, so the same power).
  if (gs_.has_area && object_ < 0 && (gs_.area.two_sided || gs_.reverse != gs_.ctm.swaps_handedness())) {
    warn("spheredome", where + ": a sphere emitting " + (gs_.area.two_sided ? "from both sides" : "inwards") +
                           " is rendered as a mesh of about 4,000 triangles of the same area (its light sampled as a mesh's)");
    partial_sphere(lx, t, r, -r, r, 2 * M_PI);
    return;
  }
  OwnedSphere os;
  os.object = object_;
  const Vec3d c = apply_point(gs_.ctm, {0, 0, 0});
  const double sx = length(apply_vector(gs_.ctm, {1, 0, 0})), sy = length(apply_vector(gs_.ctm, {0, 1, 0})),
               sz = length(apply_vector(gs_.ctm, {0, 0, 1}));
  if (std::abs(sx - sy) > 1e-4 * sx || std::abs(sx - sz) > 1e-4 * sx)
    warn("sphereellipsoid", where + ": a sphere under a non-uniform scale is rendered as a sphere of the same volume");
  os.sphere.center = vec3f(float(c.x), float(c.y), float(c.z));
  os.sphere.radius = float(r * std::cbrt(std::abs(gs_.ctm.det3())));
  if (!(os.sphere.radius > 0) || !std::isfinite(os.sphere.radius))
    lx.fail(t, "sphere with a degenerate transform", "a transform that keeps the sphere's size finite and non-zero");
  if (!std::isfinite(os.sphere.center.x) || !std::isfinite(os.sphere.center.y) || !std::isfinite(os.sphere.center.z))
    lx.fail(t, "sphere whose centre the transform moves beyond a float's range", "a transform that keeps the centre finite");
  os.sphere.material = gs_.material;
  os.media = {gs_.medium_in, gs_.medium_out, gs_.medium_where};
  os.sphere.reverse_orientation = gs_.reverse != gs_.ctm.swaps_handedness();
  if (gs_.has_area) {
    if (object_ >= 0) {
      warn("instarea", where + ": area lights inside object definitions are not supported: the shape does not emit");
    } else {
      Rgb L = gs_.area.L;
      if (gs_.area.power > 0 && luminance(L) > 0) {
        const double area = 4 * M_PI * double(os.sphere.radius) * os.sphere.radius;
        L = mul(L, float(gs_.area.power / ((gs_.area.two_sided ? 2 : 1) * M_PI * area * luminance(L))));
      }
      os.sphere.emission = L;
    }
  }
  spheres_.push_back(os);
}

// The segments of a quadric's tessellation over phimax degrees (64 for a full turn,
// proportionally fewer, at least 4, for a part), and the factor on the radius that gives the
// polygon the quadric's area (the emitted power is kept): k^2 for a fan of triangles from
// the axis (disks), k for a band of chords (cylinders).
struct Segments {
  int n;
  double dphi, fan_k, chord_k;
};
Segments segments(double phimax_rad, int full) {
  Segments s;
  s.n = std::max(4, static_cast<int>(std::ceil(full * phimax_rad / (2 * M_PI) - 1e-9)));
  s.dphi = phimax_rad / s.n;
  s.fan_k = std::sqrt(s.dphi / std::sin(s.dphi));
  s.chord_k = (s.dphi / 2) / std::sin(s.dphi / 2);
  return s;
}

double phimax_of(Lexer& lx, const Token& t, Params& ps) {
  const Param* pp = ps.get("phimax", "float");
  const float phimax = ps.one_float("phimax", 360);
  if (!(phimax > 0 && phimax <= 360)) {
    if (pp) pp->fail("\"phimax\" " + std::to_string(phimax) + " out of range", "0 < phimax <= 360 (degrees)");
    lx.fail(t, "phimax out of range", "0 < phimax <= 360");
  }
  return phimax * M_PI / 180;
}

// A partial sphere (pbrt-v4's zmin, zmax, phimax): a mesh of quads between rings of constant
// theta and meridians of constant phi (64 a turn, 32 rings from pole to pole, proportionally
// fewer for a part), scaled about the centre so its area is the surface's, shading normals
// radial, uv as pbrt-v4's (u = phi / phimax, v from theta(zmin) to theta(zmax)); facing out
// as pbrt-v4's sphere (ReverseOrientation XOR a mirroring transform turns it in). A whole
// sphere stays Embree's analytic sphere.
void Loader::partial_sphere(Lexer& lx, const Token& t, float r, float zmin, float zmax, double phimax) {
  const double th_lo = std::acos(std::clamp(double(zmax) / r, -1.0, 1.0));  // the top ring: smallest theta
  const double th_hi = std::acos(std::clamp(double(zmin) / r, -1.0, 1.0));
  const bool full = phimax >= 2 * M_PI - 1e-9;
  const Segments sg = segments(phimax, disk_segments);
  const int rings = std::max(2, static_cast<int>(std::ceil(32 * (th_hi - th_lo) / M_PI - 1e-9)));
  const int cols = full ? sg.n : sg.n + 1;
  const size_t mi = new_mesh(lx, t);
  Mesh& m = meshes_[mi].mesh;
  m.reverse_orientation = gs_.reverse;  // as the cylinder: turned in object space
  std::vector<Vec3d> p;
  std::vector<float> n_obj;
  for (int i = 0; i <= rings; ++i) {
    const double th = th_lo + (th_hi - th_lo) * i / rings;
    for (int j = 0; j < cols; ++j) {
      const double phi = sg.dphi * j;
      const Vec3d d{std::sin(th) * std::cos(phi), std::sin(th) * std::sin(phi), std::cos(th)};
      p.push_back({r * d.x, r * d.y, r * d.z});
      n_obj.insert(n_obj.end(), {float(d.x), float(d.y), float(d.z)});
      m.uvs.insert(m.uvs.end(), {float(phi / phimax), float((th - th_hi) / (th_lo - th_hi))});
    }
  }
  auto at = [&](int i, int j) { return uint32_t(i * cols + j % cols); };
  double area = 0;
  auto tri = [&](uint32_t a, uint32_t b, uint32_t c) {  // rings grow in theta, columns in phi: faces out
    const double ta = 0.5 * length(cross(sub(p[b], p[a]), sub(p[c], p[a])));
    if (!(ta > 1e-12 * r * r)) return;  // the poles' collapsed edges
    area += ta;
    m.indices.insert(m.indices.end(), {a, b, c});
  };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sg.n; ++j) {
      tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
      tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
    }
  const double exact = phimax * r * (double(zmax) - zmin);
  const double k = area > 0 ? std::sqrt(exact / area) : 1;
  for (const Vec3d& q : p) m.positions.insert(m.positions.end(), {float(k * q.x), float(k * q.y), float(k * q.z)});
  transform_positions(gs_.ctm, m.positions.data(), m.positions.size() / 3);
  quadric_normals(m, n_obj);
}

void Loader::quadric_normals(Mesh& m, const std::vector<float>& n_obj) {
  set_shading_normals(m, n_obj, gs_.ctm, gs_.reverse != gs_.ctm.swaps_handedness());
}

// disk: a polygon (or a ring) of the disk's area in its plane z = height, over phimax
// degrees (a sector for phimax < 360); uv as pbrt-v4's (u = phi / phimax, v = (r - radius)
// / (innerradius - radius)).
void Loader::disk_shape(Lexer& lx, const Token& t, Params& ps) {
  const float h = ps.one_float("height", 0), r = ps.one_float("radius", 1), ri = ps.one_float("innerradius", 0);
  if (!(r > 0) || !(ri >= 0) || !(ri < r)) lx.fail(t, "disk radii out of range", "radius > innerradius >= 0");
  const double phimax = phimax_of(lx, t, ps);
  const bool full = phimax >= 2 * M_PI - 1e-9;
  const Segments sg = segments(phimax, disk_segments);
  const size_t mi = new_mesh(lx, t);
  Mesh& m = meshes_[mi].mesh;
  // pbrt's disk faces +z in object space and its orientation ignores the handedness of
  // the transform (the normal is turned in object space), hence only ReverseOrientation.
  m.reverse_orientation = gs_.reverse;
  const bool ring = ri > 0;
  const int ends = full ? sg.n : sg.n + 1;  // a sector's last edge has its own vertices
  const double k = sg.fan_k;
  for (int i = 0; i < ends; ++i) {
    const double phi = sg.dphi * i, cx = std::cos(phi), sy = std::sin(phi);
    m.positions.insert(m.positions.end(), {float(r * k * cx), float(r * k * sy), h});
    m.uvs.insert(m.uvs.end(), {float(phi / phimax), 0.f});
    if (ring) {
      m.positions.insert(m.positions.end(), {float(ri * k * cx), float(ri * k * sy), h});
      m.uvs.insert(m.uvs.end(), {float(phi / phimax), 1.f});
    }
  }
  const uint32_t centre = uint32_t(ends);
  if (!ring) {
    m.positions.insert(m.positions.end(), {0.f, 0.f, h});
    m.uvs.insert(m.uvs.end(), {0.f, 1.f});
  }
  for (uint32_t i = 0; i < uint32_t(sg.n); ++i) {
    const uint32_t j = (i + 1) % uint32_t(ends);
    if (ring) m.indices.insert(m.indices.end(), {2 * i + 1, 2 * i, 2 * j, 2 * i + 1, 2 * j, 2 * j + 1});
    else m.indices.insert(m.indices.end(), {centre, i, j});
  }
  transform_positions(gs_.ctm, m.positions.data(), m.positions.size() / 3);
}

// cylinder: pbrt-v4's (radius, zmin, zmax, phimax about the z axis, its normal facing out):
// a band of quads around the axis, 128 for a full turn, its radius grown so the band has
// the cylinder's area, shading normals radial (the analytic surface's), uv as pbrt-v4's
// (u = phi / phimax, v = (z - zmin) / (zmax - zmin)).
void Loader::cylinder_shape(Lexer& lx, const Token& t, Params& ps) {
  const float r = ps.one_float("radius", 1), z0 = ps.one_float("zmin", -1), z1 = ps.one_float("zmax", 1);
  if (!(r > 0) || !std::isfinite(r)) lx.fail(t, "cylinder radius out of range", "radius > 0");
  if (!(std::isfinite(z0) && std::isfinite(z1)) || z0 == z1) lx.fail(t, "cylinder zmin and zmax out of range", "finite zmin != zmax");
  const float zmin = std::min(z0, z1), zmax = std::max(z0, z1);
  const double phimax = phimax_of(lx, t, ps);
  const bool full = phimax >= 2 * M_PI - 1e-9;
  const Segments sg = segments(phimax, 2 * disk_segments);
  const size_t mi = new_mesh(lx, t);
  Mesh& m = meshes_[mi].mesh;
  m.reverse_orientation = gs_.reverse;  // as the disk: turned in object space
  const int ends = full ? sg.n : sg.n + 1;
  std::vector<float> n_obj;
  for (int i = 0; i < ends; ++i) {
    const double phi = sg.dphi * i, cx = std::cos(phi), sy = std::sin(phi);
    const float x = float(r * sg.chord_k * cx), y = float(r * sg.chord_k * sy);
    m.positions.insert(m.positions.end(), {x, y, zmin, x, y, zmax});
    m.uvs.insert(m.uvs.end(), {float(phi / phimax), 0.f, float(phi / phimax), 1.f});
    n_obj.insert(n_obj.end(), {float(cx), float(sy), 0.f, float(cx), float(sy), 0.f});
  }
  for (uint32_t i = 0; i < uint32_t(sg.n); ++i) {
    const uint32_t j = (i + 1) % uint32_t(ends);
    // (bottom i, bottom j, top j), (bottom i, top j, top i): the winding faces out
    m.indices.insert(m.indices.end(), {2 * i, 2 * j, 2 * j + 1, 2 * i, 2 * j + 1, 2 * i + 1});
  }
  transform_positions(gs_.ctm, m.positions.data(), m.positions.size() / 3);
  quadric_normals(m, n_obj);
}

// curve: pbrt-v4's parameters (P, basis bezier|bspline, degree 2|3, type flat|ribbon|cylinder,
// width or width0/width1 along the whole curve, N for ribbons: one normal per segment end),
// each segment converted to a cubic Bezier as pbrt-v4 converts them (degree elevation, the
// B-spline to Bezier rules), widths linear along the curve (exact in the Bezier basis),
// ribbon normals spherically interpolated at the control points. "splitdepth" is read and
// not needed: Embree intersects the curve itself.
void Loader::curve_shape(Lexer& lx, const Token& t, Params& ps, const std::string& where) {
  const Param* P = ps.get("P", "point3");
  if (!P) lx.fail(t, "curve without \"point3 P\"", "a \"point3 P\" parameter with the control points");
  const std::string basis = ps.one_string("basis", "bezier"), type = ps.one_string("type", "flat");
  const int degree = ps.one_int("degree", 3);
  const float width = ps.one_float("width", 1);
  const float w0 = ps.one_float("width0", width), w1 = ps.one_float("width1", width);
  ps.one_int("splitdepth", 3);
  const Param* N = ps.get("N", "normal3");
  if (basis != "bezier" && basis != "bspline") lx.fail(t, "curve basis \"" + basis + "\"", "\"bezier\" or \"bspline\"");
  if (degree != 2 && degree != 3) lx.fail(t, "curve degree " + std::to_string(degree), "degree 2 or 3");
  if (type != "flat" && type != "ribbon" && type != "cylinder")
    lx.fail(t, "curve type \"" + type + "\"", "\"flat\", \"ribbon\" or \"cylinder\"");
  if (!(w0 >= 0 && w1 >= 0) || !std::isfinite(w0) || !std::isfinite(w1))
    lx.fail(t, "curve width out of range", "finite widths >= 0");
  const size_t ncp = P->nums.size() / 3;
  size_t nseg = 0;
  if (basis == "bezier") {
    if (ncp < size_t(degree) + 1 || (ncp - 1) % size_t(degree) != 0)
      P->fail("a degree " + std::to_string(degree) + " Bezier curve with " + std::to_string(ncp) + " control points",
              std::to_string(degree) + " k + 1 control points");
    nseg = (ncp - 1) / size_t(degree);
  } else {
    if (ncp < size_t(degree) + 1)
      P->fail("a degree " + std::to_string(degree) + " B-spline with " + std::to_string(ncp) + " control points",
              "at least " + std::to_string(degree + 1) + " control points");
    nseg = ncp - size_t(degree);
  }
  const bool ribbon = type == "ribbon";
  if (ribbon && (!N || N->nums.size() / 3 != nseg + 1))
    lx.fail(t, "ribbon curve with " + std::to_string(N ? N->nums.size() / 3 : 0) + " normals for " + std::to_string(nseg) + " segments",
            "\"normal N\" with one normal per segment end (" + std::to_string(nseg + 1) + ")");
  if (!ribbon && N) warn("curveN", where + ": \"N\" is only used by ribbon curves");
  if (gs_.has_area) warn("curvearea", where + ": area lights on curves are not supported: the curve does not emit");
  OwnedCurves oc;
  oc.object = object_;
  Curves& c = oc.curves;
  c.name = "curve at " + where;
  c.type = type == "flat" ? CurveType::flat : ribbon ? CurveType::ribbon : CurveType::cylinder;
  c.material = gs_.material;
  oc.media = {gs_.medium_in, gs_.medium_out, gs_.medium_where};
  const double wscale = std::cbrt(std::abs(gs_.ctm.det3()));
  if (!(wscale > 0) || !std::isfinite(wscale))
    lx.fail(t, "curve with a degenerate transform", "a transform that keeps the curve's width finite and non-zero");
  Mat4 inv;
  if (ribbon && !invert(gs_.ctm, inv)) lx.fail(t, "ribbon curve under a singular transform", "an invertible transform");
  auto cp = [&](size_t i) { return Vec3d{P->nums[3 * i], P->nums[3 * i + 1], P->nums[3 * i + 2]}; };
  auto lerp = [](double s, Vec3d a, Vec3d b) { return Vec3d{(1 - s) * a.x + s * b.x, (1 - s) * a.y + s * b.y, (1 - s) * a.z + s * b.z}; };
  for (size_t seg = 0; seg < nseg; ++seg) {
    Vec3d b[4];
    if (basis == "bezier") {
      const size_t i = seg * size_t(degree);
      if (degree == 3) {
        for (int k = 0; k < 4; ++k) b[k] = cp(i + size_t(k));
      } else {  // degree elevation
        b[0] = cp(i);
        b[1] = lerp(2.0 / 3, cp(i), cp(i + 1));
        b[2] = lerp(1.0 / 3, cp(i + 1), cp(i + 2));
        b[3] = cp(i + 2);
      }
    } else if (degree == 3) {  // uniform cubic B-spline to Bezier
      const Vec3d p012 = cp(seg), p123 = cp(seg + 1), p234 = cp(seg + 2), p345 = cp(seg + 3);
      const Vec3d p122 = lerp(2.0 / 3, p012, p123), p223 = lerp(1.0 / 3, p123, p234);
      const Vec3d p233 = lerp(2.0 / 3, p123, p234), p334 = lerp(1.0 / 3, p234, p345);
      b[0] = lerp(0.5, p122, p223);
      b[1] = p223;
      b[2] = p233;
      b[3] = lerp(0.5, p233, p334);
    } else {  // quadratic B-spline to quadratic Bezier, then elevated
      const Vec3d p01 = cp(seg), p12 = cp(seg + 1), p23 = cp(seg + 2);
      const Vec3d p11 = lerp(0.5, p01, p12), p22 = lerp(0.5, p12, p23);
      b[0] = p11;
      b[1] = lerp(2.0 / 3, p11, p12);
      b[2] = lerp(1.0 / 3, p12, p22);
      b[3] = p22;
    }
    const double ws = double(w0) + (double(w1) - w0) * double(seg) / double(nseg);
    const double we = double(w0) + (double(w1) - w0) * double(seg + 1) / double(nseg);
    for (int k = 0; k < 4; ++k) {
      const Vec3d w = apply_point(gs_.ctm, b[k]);
      const double r = 0.5 * wscale * (ws + (we - ws) * k / 3.0);
      c.points.insert(c.points.end(), {float(w.x), float(w.y), float(w.z), float(r)});
    }
    if (ribbon) {
      const Vec3d n0 = normalized(apply_normal_inv(inv, {N->nums[3 * seg], N->nums[3 * seg + 1], N->nums[3 * seg + 2]}));
      const Vec3d n1 = normalized(apply_normal_inv(inv, {N->nums[3 * seg + 3], N->nums[3 * seg + 4], N->nums[3 * seg + 5]}));
      const double cos_t = std::clamp(dot(n0, n1), -1.0, 1.0), theta = std::acos(cos_t), sin_t = std::sin(theta);
      for (int k = 0; k < 4; ++k) {  // slerp at u = k / 3 (pbrt-v4 interpolates the normal so)
        const double u = k / 3.0;
        const double a = sin_t > 1e-6 ? std::sin((1 - u) * theta) / sin_t : 1 - u;
        const double bb = sin_t > 1e-6 ? std::sin(u * theta) / sin_t : u;
        const Vec3d n = normalized({a * n0.x + bb * n1.x, a * n0.y + bb * n1.y, a * n0.z + bb * n1.z});
        c.normals.insert(c.normals.end(), {float(n.x), float(n.y), float(n.z)});
      }
    }
  }
  curves_.push_back(std::move(oc));
}

void Loader::shape(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  const std::string where = loc_str(lx, t);
  for (Param& p : ps.items)
    if (p.name == "displacement" || p.name == "edgelength") {
      p.used = true;
      warn("shape:" + p.name, where + ": shape parameter \"" + p.name + "\" is not supported and was ignored");
    }
  const Param* alpha = ps.get("alpha", "float|texture");
  const size_t meshes0 = meshes_.size(), spheres0 = spheres_.size();
  if (type == "trianglemesh" || type == "bilinearmesh" || type == "loopsubdiv") {
    mesh_shape(lx, t, type, ps, where);
  } else if (type == "plymesh") {
    ply_shape(lx, t, ps);
  } else if (type == "sphere") {
    sphere_shape(lx, t, ps, where);
  } else if (type == "disk") {
    disk_shape(lx, t, ps);
  } else if (type == "cylinder") {
    cylinder_shape(lx, t, ps);
  } else if (type == "curve") {
    curve_shape(lx, t, ps, where);
  } else if (type == "cone" || type == "paraboloid" || type == "hyperboloid") {
    ps.mark_all_used();
    warn("shape:" + type, where + ": shape \"" + type + "\" is not supported and was skipped");
    return;
  } else {
    lx.fail(t, "unknown shape \"" + type + "\"", "trianglemesh, plymesh, bilinearmesh, loopsubdiv, sphere, disk, cylinder or curve");
  }
  if (alpha && type == "curve") warn("curvealpha", where + ": \"alpha\" on curves is not supported and was ignored");
  else if (alpha) shape_alpha(*alpha, meshes0, spheres0);
  warn_unused(ps, "Shape \"" + type + "\"", lx, t);
}

// A shape's "alpha" (wave/alpha.h): a float is set on the shape's meshes and sphere now, a
// float texture when textures are resolved (set_shape_alpha).
void Loader::shape_alpha(const Param& p, size_t meshes0, size_t spheres0) {
  if (p.type == "float") {
    if (p.nums.size() != 1) p.fail("parameter \"float alpha\" has " + std::to_string(p.nums.size()) + " values", "1 value");
    const double a = p.nums[0];
    if (!std::isfinite(a)) p.fail("alpha is not a finite number", "an alpha in [0, 1]");
    for (size_t i = meshes0; i < meshes_.size(); ++i) meshes_[i].mesh.alpha = {float(a), -1};
    for (size_t i = spheres0; i < spheres_.size(); ++i) spheres_[i].sphere.alpha = float(a);
    return;
  }
  FloatFix f;
  f.field = FloatFix::shape_alpha;
  f.def = float_texture_ref(p);
  f.file = p.file;
  f.name = "alpha";
  f.line = p.line;
  f.col = p.col;
  f.mesh = int(meshes0);
  f.mesh_end = int(meshes_.size());
  f.sphere = int(spheres0);
  f.sphere_end = int(spheres_.size());
  float_fixes_.push_back(f);
}

// A shape's alpha texture, resolved: meshes look it up at their uv; a sphere (no uv here)
// takes the texture's mean as its constant alpha, with a warning.
void Loader::set_shape_alpha(const FloatFix& f, const ResolvedFloat& r) {
  for (int i = f.mesh; i < f.mesh_end; ++i)
    meshes_[size_t(i)].mesh.alpha = r.image ? FloatParam{1, r.texture} : FloatParam{r.value, -1};
  for (int i = f.sphere; i < f.sphere_end; ++i) {
    float a = r.value;
    if (r.image) {
      a = average(scene.float_textures[size_t(r.texture)]);
      warn("spherealpha", f.file + ":" + std::to_string(f.line) +
                              ": an alpha texture on a sphere is not looked up per hit: its mean alpha used");
    }
    spheres_[size_t(i)].sphere.alpha = a;
  }
  if (!std::isfinite(r.value)) fail(f.file, f.line, f.col, "alpha is not a finite number", "an alpha in [0, 1]");
}

static double mesh_area(const Mesh& m) {
  double a = 0;
  const float* P = m.positions.data();
  for (size_t i = 0; i + 2 < m.indices.size(); i += 3) {
    auto pos = [&](uint32_t k) { return Vec3d{P[3 * k], P[3 * k + 1], P[3 * k + 2]}; };
    const Vec3d p0 = pos(m.indices[i]);
    a += 0.5 * length(cross(sub(pos(m.indices[i + 1]), p0), sub(pos(m.indices[i + 2]), p0)));
  }
  return a;
}

void Loader::resolve_media(const MediumNames& n, int& inside, int& outside) {
  auto find = [&](const std::string& name) {
    if (name.empty()) return -1;
    const auto it = named_media_.find(name);
    if (it == named_media_.end())
      throw SceneError(n.where + ": error: medium \"" + name + "\" is not defined (expected a name given to MakeNamedMedium)");
    return it->second;
  };
  inside = find(n.in);
  outside = find(n.out);
  if (inside >= 0) ++scene.media[size_t(inside)].bounding_shapes;
  if (outside >= 0 && outside != inside) ++scene.media[size_t(outside)].bounding_shapes;
}

// Object instances. An object whose shapes are all plain surfaces becomes a real instance:
// its shapes join the scene once, in object space (their `object` set), and each
// ObjectInstance adds a placement (Scene::instances), which Embree traces as an instance of
// the object's own BVH. An object with a shape that bounds a rendered medium (or is an
// interface) is flattened into world-space copies as before (the medium stages follow
// rays through world-space interfaces), with a note. Objects never placed are left out;
// an object without shapes renders nothing (a warning).
template <class IsInterface> void Loader::place_instances(IsInterface&& is_interface, size_t& total) {
  if (instances_.empty()) return;
  const size_t nobj = object_names_.size();
  std::vector<int> shapes(nobj, 0), placed(nobj, 0);
  std::vector<char> flat(nobj, 0);
  auto rendered = [&](int m) { return m >= 0 && scene.media[size_t(m)].supported; };
  auto bounds_media = [&](int material, int in, int out) {
    return rendered(in) || rendered(out) || (material >= 0 && scene.materials[size_t(material)].interface);
  };
  for (const OwnedMesh& om : meshes_)
    if (om.object >= 0 && !om.mesh.indices.empty()) {
      ++shapes[size_t(om.object)];
      if (bounds_media(om.mesh.material, om.mesh.medium_inside, om.mesh.medium_outside)) flat[size_t(om.object)] = 1;
    }
  for (const OwnedSphere& os : spheres_)
    if (os.object >= 0) {
      ++shapes[size_t(os.object)];
      if (bounds_media(os.sphere.material, os.sphere.medium_inside, os.sphere.medium_outside)) flat[size_t(os.object)] = 1;
    }
  for (const OwnedCurves& oc : curves_)
    if (oc.object >= 0) {
      ++shapes[size_t(oc.object)];
      if (bounds_media(oc.curves.material, oc.curves.medium_inside, oc.curves.medium_outside)) flat[size_t(oc.object)] = 1;
    }
  for (const Instance& in : instances_) ++placed[size_t(in.object)];
  // the real objects' shapes, once each, under the scene's object index
  std::vector<int> index(nobj, -1);
  for (size_t o = 0; o < nobj; ++o) {
    if (!placed[o]) continue;
    if (!shapes[o]) {
      warn("emptyobject:" + object_names_[o], "object \"" + object_names_[o] + "\" has no shapes: its " +
                                                  std::to_string(placed[o]) + " instance(s) render nothing");
      continue;
    }
    if (flat[o]) {
      note("flatobject:" + object_names_[o], "object \"" + object_names_[o] + "\" bounds a participating medium: its " +
                                                std::to_string(placed[o]) + " instance(s) are flattened into world-space copies");
      continue;
    }
    index[o] = static_cast<int>(scene.objects.size());
    scene.objects.push_back(object_names_[o]);
  }
  for (OwnedMesh& om : meshes_)
    if (om.object >= 0 && index[size_t(om.object)] >= 0 && !om.mesh.indices.empty()) {
      om.mesh.object = index[size_t(om.object)];
      scene.meshes.push_back(std::move(om.mesh));  // (only flattened objects' meshes are read again)
    }
  for (const OwnedSphere& os : spheres_)
    if (os.object >= 0 && index[size_t(os.object)] >= 0) {
      scene.spheres.push_back(os.sphere);
      scene.spheres.back().object = index[size_t(os.object)];
    }
  for (const OwnedCurves& oc : curves_)
    if (oc.object >= 0 && index[size_t(oc.object)] >= 0) {
      scene.curves.push_back(oc.curves);
      scene.curves.back().object = index[size_t(oc.object)];
    }
  for (const Instance& in : instances_) {
    const int o = index[size_t(in.object)];
    if (o < 0) continue;
    tuile::Instance placed_in;
    placed_in.object = o;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) placed_in.world_from_object[r][c] = static_cast<float>(in.ctm.m[r][c]);
    placed_in.where = in.where;
    scene.instances.push_back(std::move(placed_in));
  }
  // the flattened objects' copies
  for (const Instance& in : instances_) {
    if (!flat[size_t(in.object)] || !placed[size_t(in.object)]) continue;
    const bool swaps = in.ctm.swaps_handedness();
    for (const OwnedMesh& om : meshes_) {
      if (om.object != in.object || om.mesh.indices.empty() || is_interface(om.mesh.material, false, om.mesh.medium_inside, om.mesh.medium_outside)) continue;
      total += om.mesh.triangle_count();
      if (total >= max_triangles)
        throw SceneError(om.mesh.name + ": error: too many triangles after flattening object instances (expected fewer than 2^31)");
      Mesh m = om.mesh;
      transform_positions(in.ctm, m.positions.data(), m.positions.size() / 3);
      m.reverse_orientation = m.reverse_orientation != swaps;
      // shading normals by the inverse transpose (they stay on the side they were, which
      // decides the outside); zero ones stay zero
      Mat4 inv;
      if (!m.normals.empty() && invert(in.ctm, inv))
        for (size_t i = 0; i + 2 < m.normals.size(); i += 3) {
          if (m.normals[i] == 0 && m.normals[i + 1] == 0 && m.normals[i + 2] == 0) continue;
          const Vec3d n = normalized(apply_normal_inv(inv, {m.normals[i], m.normals[i + 1], m.normals[i + 2]}));
          m.normals[i] = float(n.x);
          m.normals[i + 1] = float(n.y);
          m.normals[i + 2] = float(n.z);
        }
      scene.meshes.push_back(std::move(m));
    }
    for (const OwnedSphere& os : spheres_) {
      if (os.object != in.object || is_interface(os.sphere.material, false, os.sphere.medium_inside, os.sphere.medium_outside)) continue;
      Sphere s = os.sphere;
      const Vec3d c = apply_point(in.ctm, {s.center.x, s.center.y, s.center.z});
      s.center = vec3f(float(c.x), float(c.y), float(c.z));
      s.radius = float(s.radius * std::cbrt(std::abs(in.ctm.det3())));
      if (!std::isfinite(s.center.x) || !std::isfinite(s.center.y) || !std::isfinite(s.center.z) || !std::isfinite(s.radius) ||
          !(s.radius > 0))
        throw SceneError(in.where + ": error: the instance's transform moves a sphere beyond a float's range or shrinks it to nothing "
                                    "(expected a transform that keeps the sphere finite)");
      s.reverse_orientation = s.reverse_orientation != swaps;
      scene.spheres.push_back(s);
    }
    for (const OwnedCurves& oc : curves_) {
      if (oc.object != in.object || is_interface(oc.curves.material, false, oc.curves.medium_inside, oc.curves.medium_outside)) continue;
      Curves c = oc.curves;
      const float ws = float(std::cbrt(std::abs(in.ctm.det3())));
      for (size_t i = 0; i + 3 < c.points.size(); i += 4) {
        const Vec3d p = apply_point(in.ctm, {c.points[i], c.points[i + 1], c.points[i + 2]});
        c.points[i] = float(p.x);
        c.points[i + 1] = float(p.y);
        c.points[i + 2] = float(p.z);
        c.points[i + 3] *= ws;
      }
      Mat4 inv;
      if (!c.normals.empty() && invert(in.ctm, inv))
        for (size_t i = 0; i + 2 < c.normals.size(); i += 3) {
          const Vec3d n = normalized(apply_normal_inv(inv, {c.normals[i], c.normals[i + 1], c.normals[i + 2]}));
          c.normals[i] = float(n.x);
          c.normals[i + 1] = float(n.y);
          c.normals[i + 2] = float(n.z);
        }
      scene.curves.push_back(std::move(c));
    }
  }
}

void Loader::flatten() {
  size_t total = 0;
  for (OwnedMesh& om : meshes_) resolve_media(om.media, om.mesh.medium_inside, om.mesh.medium_outside);
  for (OwnedSphere& os : spheres_) resolve_media(os.media, os.sphere.medium_inside, os.sphere.medium_outside);
  for (OwnedCurves& oc : curves_) resolve_media(oc.media, oc.curves.medium_inside, oc.curves.medium_outside);
  {  // the camera's medium (not a shape: not counted as bounding it)
    int in = -1;
    resolve_media(camera_medium_, in, scene.camera_medium);
    if (scene.camera_medium >= 0) --scene.media[size_t(scene.camera_medium)].bounding_shapes;
  }
  for (const auto& [i, names] : light_media_) {  // point and spot sources' media (not shapes either)
    int in = -1;
    int& out = scene.lights[i].medium;
    resolve_media(names, in, out);
    if (out >= 0) --scene.media[size_t(out)].bounding_shapes;
  }
  // "interface" shapes bound media and do not scatter light: pbrt-v4's rays pass through
  // them. One that changes the medium (a rendered medium on either side, different sides)
  // stays in the geometry, where the medium stages pass rays through it (wave/media.h);
  // one that changes nothing is left out (an emissive one stays, a diffuse emitter: pbrt-v4
  // counts its emission and passes the ray on).
  size_t interfaces = 0;
  auto rendered = [&](int m) { return m >= 0 && scene.media[size_t(m)].supported ? m : -1; };
  auto is_interface = [&](int material, bool emits, int in, int out) {
    const bool interface = material >= 0 && scene.materials[size_t(material)].interface;
    if (interface && emits)
      warn("interfaceemit", "an emissive shape with the \"interface\" material is rendered as a diffuse emitter (grey 0.5), "
                            "where pbrt-v4's rays pass through it");
    const bool skip = interface && !emits && rendered(in) == rendered(out);
    interfaces += skip;
    return skip;
  };
  for (OwnedMesh& om : meshes_) {
    if (om.object >= 0) continue;
    if (is_interface(om.mesh.material, om.mesh.emissive(), om.mesh.medium_inside, om.mesh.medium_outside)) continue;
    if (om.mesh.indices.empty()) {
      warn("emptymesh", om.mesh.name + ": a mesh without triangles was skipped");
      continue;
    }
    if (om.power > 0 && luminance(om.mesh.emission) > 0) {
      const double area = mesh_area(om.mesh);
      if (area > 0)
        om.mesh.emission = mul(om.mesh.emission, float(om.power / ((om.mesh.two_sided ? 2 : 1) * M_PI * area *
                                                                    luminance(om.mesh.emission))));
      else warn("zeroarea:" + om.power_where, om.power_where + ": area light of zero area: power ignored");
    }
    total += om.mesh.triangle_count();
    scene.meshes.push_back(std::move(om.mesh));
  }
  for (OwnedSphere& os : spheres_)
    if (os.object < 0 && !is_interface(os.sphere.material, os.sphere.emissive(), os.sphere.medium_inside, os.sphere.medium_outside)) scene.spheres.push_back(os.sphere);
  for (OwnedCurves& oc : curves_)
    if (oc.object < 0 && !is_interface(oc.curves.material, false, oc.curves.medium_inside, oc.curves.medium_outside)) scene.curves.push_back(oc.curves);
  place_instances(is_interface, total);
  if (interfaces)
    note("interface", std::to_string(interfaces) + " shape(s) with the \"interface\" material (boundaries of media, which do not "
                      "scatter light) between the same media left out of the geometry: rays pass through them, as in pbrt-v4");
}

}  // namespace tuile::pbrt
