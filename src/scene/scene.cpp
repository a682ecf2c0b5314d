// finalize_scene: the light table (one source per emissive triangle or parallelogram,
// spheres, delta lights), their powers, validation of the geometry, and the scene's
// features; load_scene.
#include "scene/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>

#include "light/dispatch.h"
#include "sample/spherical.h"
#include "scene/pbrt.h"
#include "wave/alpha.h"

namespace tuile {

void camera_look_at(Camera& cam, vec3f eye, vec3f look, vec3f up) {
  const vec3f dir = normalize(look - eye);
  const vec3f up_n = normalize(up);
  vec3f right = cross(up_n, dir);
  if (!(length(right) > 1e-12f)) throw SceneError("LookAt: the up vector is parallel to the viewing direction");
  right = normalize(right);
  const vec3f new_up = cross(dir, right);
  const vec3f cols[4] = {right, new_up, dir, eye};
  for (int c = 0; c < 4; ++c) {
    cam.world_from_camera[0][c] = cols[c].x;
    cam.world_from_camera[1][c] = cols[c].y;
    cam.world_from_camera[2][c] = cols[c].z;
  }
}

size_t Scene::triangle_count() const {
  size_t n = 0;
  for (const Mesh& m : meshes) n += m.triangle_count();
  return n;
}

size_t Scene::instanced_triangle_count() const {
  std::vector<size_t> per_object(objects.size(), 0);
  size_t n = 0;
  for (const Mesh& m : meshes) (m.object < 0 ? n : per_object[static_cast<size_t>(m.object)]) += m.triangle_count();
  for (const Instance& in : instances) n += per_object[static_cast<size_t>(in.object)];
  return n;
}


static vec3f vertex(const Mesh& m, uint32_t i) {
  return {m.positions[3 * i], m.positions[3 * i + 1], m.positions[3 * i + 2]};
}

static bool finite3(vec3f v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Degenerate for lighting: zero or non-finite area relative to the edge lengths.
static bool degenerate(vec3f e1, vec3f e2) {
  const float a2 = length_sq(cross(e1, e2));
  const float scale = length_sq(e1) * length_sq(e2);
  return !(a2 > 1e-12f * scale) || !(a2 > 0.f) || !std::isfinite(a2);
}

// Triangles t and t+1 of a mesh forming a parallelogram with a shared diagonal become
// one parallelogram source (sampled as a spherical rectangle when its edges are orthogonal).
static bool match_parallelogram(const Mesh& m, size_t t, vec3f& p0, vec3f& e1, vec3f& e2) {
  if (t + 1 >= m.triangle_count()) return false;
  const uint32_t* a = &m.indices[3 * t];
  const uint32_t* b = &m.indices[3 * t + 3];
  // find the vertex of t not shared with t+1, and the vertex of t+1 not in t
  int lone_a = -1, shared = 0;
  for (int i = 0; i < 3; ++i) {
    bool in_b = a[i] == b[0] || a[i] == b[1] || a[i] == b[2];
    if (in_b) ++shared;
    else lone_a = i;
  }
  if (shared != 2 || lone_a < 0) return false;
  int lone_b = -1;
  for (int i = 0; i < 3; ++i)
    if (b[i] != a[0] && b[i] != a[1] && b[i] != a[2]) lone_b = i;
  if (lone_b < 0) return false;
  const vec3f o = vertex(m, a[lone_a]);
  const vec3f x = vertex(m, a[(lone_a + 1) % 3]);
  const vec3f y = vertex(m, a[(lone_a + 2) % 3]);
  const vec3f q = vertex(m, b[lone_b]);
  const vec3f d = (x + y - o) - q;
  // relative to the edges, plus the rounding of the coordinates themselves
  const float size = std::max(length(x - o), length(y - o));
  const float coord = std::max({max_abs(o), max_abs(x), max_abs(y), max_abs(q)});
  if (!(length(d) <= 1e-5f * size + 0x1p-20f * coord)) return false;
  // same orientation for both triangles
  const vec3f na = cross(vertex(m, a[1]) - vertex(m, a[0]), vertex(m, a[2]) - vertex(m, a[0]));
  const vec3f nb = cross(vertex(m, b[1]) - vertex(m, b[0]), vertex(m, b[2]) - vertex(m, b[0]));
  if (!(dot(na, nb) > 0.f)) return false;
  p0 = o;
  e1 = x - o;
  e2 = y - o;
  if (dot(cross(e1, e2), na) < 0.f) std::swap(e1, e2);
  return true;
}

namespace {

bool is_pow2(int x) { return x > 0 && (x & (x - 1)) == 0; }

// pbrt-v4's weights for resampling old_res texels up to new_res (Image::ResampleWeights):
// four taps of a windowed sinc (radius 2, tau 2) around each new texel's centre, normalised.
void resample_weights(int old_res, int new_res, std::vector<int>& first, std::vector<std::array<float, 4>>& w) {
  first.resize(static_cast<size_t>(new_res));
  w.resize(static_cast<size_t>(new_res));
  const auto sinc = [](float x) {
    const float px = 3.14159265358979f * x;
    return 1.f - px * px == 1.f ? 1.f : std::sin(px) / px;
  };
  for (int i = 0; i < new_res; ++i) {
    const float centre = (static_cast<float>(i) + 0.5f) * static_cast<float>(old_res) / static_cast<float>(new_res);
    const int f = static_cast<int>(std::floor((centre - 2.f) + 0.5f));
    float sum = 0;
    for (int j = 0; j < 4; ++j) {
      const float x = static_cast<float>(f + j) + 0.5f - centre;
      const float v = std::fabs(x) > 2.f ? 0.f : sinc(x) * sinc(x / 2.f);
      w[static_cast<size_t>(i)][static_cast<size_t>(j)] = v;
      sum += v;
    }
    for (float& v : w[static_cast<size_t>(i)]) v /= sum;
    first[static_cast<size_t>(i)] = f;
  }
}

}  // namespace

void build_mip(FloatTexture& t) {
  t.mip.clear();
  t.mip_w.clear();
  t.mip_h.clear();
  t.mip_at.clear();
  if (t.width < 1 || t.height < 1 || t.value.size() != static_cast<size_t>(t.width) * static_cast<size_t>(t.height)) return;
  int w = t.width, h = t.height;
  std::vector<float> level = t.value;
  if (!is_pow2(w) || !is_pow2(h)) {  // pbrt-v4's FloatResizeUp: x, then y (clamped at 0)
    int nw = 1, nh = 1;
    while (nw < w) nw *= 2;
    while (nh < h) nh *= 2;
    std::vector<int> fx, fy;
    std::vector<std::array<float, 4>> wx, wy;
    resample_weights(w, nw, fx, wx);
    resample_weights(h, nh, fy, wy);
    const auto wrap = [](int i, int n) { return ((i % n) + n) % n; };
    std::vector<float> xs(static_cast<size_t>(nw) * static_cast<size_t>(h));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < nw; ++x) {
        float v = 0;
        for (int j = 0; j < 4; ++j)
          v += wx[static_cast<size_t>(x)][static_cast<size_t>(j)] *
               level[static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(wrap(fx[static_cast<size_t>(x)] + j, w))];
        xs[static_cast<size_t>(y) * static_cast<size_t>(nw) + static_cast<size_t>(x)] = v;
      }
    level.assign(static_cast<size_t>(nw) * static_cast<size_t>(nh), 0.f);
    for (int y = 0; y < nh; ++y)
      for (int x = 0; x < nw; ++x) {
        float v = 0;
        for (int j = 0; j < 4; ++j)
          v += wy[static_cast<size_t>(y)][static_cast<size_t>(j)] *
               xs[static_cast<size_t>(wrap(fy[static_cast<size_t>(y)] + j, h)) * static_cast<size_t>(nw) + static_cast<size_t>(x)];
        level[static_cast<size_t>(y) * static_cast<size_t>(nw) + static_cast<size_t>(x)] = std::max(0.f, v);
      }
    w = nw;
    h = nh;
  }
  for (;;) {
    t.mip_at.push_back(t.mip.size());
    t.mip_w.push_back(w);
    t.mip_h.push_back(h);
    t.mip.insert(t.mip.end(), level.begin(), level.end());
    if (w == 1 && h == 1) break;
    const int nw = std::max(1, w / 2), nh = std::max(1, h / 2);
    std::vector<float> next(static_cast<size_t>(nw) * static_cast<size_t>(nh));
    for (int y = 0; y < nh; ++y)
      for (int x = 0; x < nw; ++x) {
        const int x0 = 2 * x, y0 = 2 * y, x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
        const auto at = [&](int xx, int yy) { return level[static_cast<size_t>(yy) * static_cast<size_t>(w) + static_cast<size_t>(xx)]; };
        next[static_cast<size_t>(y) * static_cast<size_t>(nw) + static_cast<size_t>(x)] =
            (at(x0, y0) + at(x1, y0) + at(x0, y1) + at(x1, y1)) / 4;
      }
    level.swap(next);
    w = nw;
    h = nh;
  }
}

namespace {

// Whether material m bumps (a displacement texture whose texels are not all equal: a
// constant moves a surface without turning it, render/views.cpp drops it).
bool bumps(const Scene& scene, const Material& m) {
  if (m.displacement < 0) return false;
  const FloatTexture& t = scene.float_textures[static_cast<size_t>(m.displacement)];
  return std::any_of(t.value.begin(), t.value.end(), [&](float x) { return x != t.value[0]; });
}

// Checks every material's numbers and indices, and applies what tuile approximates, once,
// with one warning per kind: a float texture for roughness becomes its mean (remapped as
// pbrt would at each hit), a mix's own textures are not looked up by the materials it
// chooses between, spheres are not bump mapped (displacement textures are, on triangles:
// surface_hits.h bump_normal).
void resolve_material_params(Scene& scene) {
  // Reflectances, transmittances and a layer's albedo are clamped to [0, 1], as pbrt-v4's
  // materials clamp their textures' values (a reflectance of 2, or a scale texture that
  // overflows to infinity, is 1); texels are looked up nearest, so clamping them here is
  // clamping each lookup. NaN is an error.
  for (Material& m : scene.materials)
    for (Rgb* c : {&m.reflectance, &m.transmittance, &m.albedo})
      for (float* x : {&c->r, &c->g, &c->b}) {
        if (std::isnan(*x)) throw SceneError("material: error: a reflectance, transmittance or albedo is NaN");
        *x = std::clamp(*x, 0.f, 1.f);
      }
  for (Texture& t : scene.textures)
    for (float& x : t.rgb) {
      if (std::isnan(x)) throw SceneError("texture \"" + t.name + "\": error: a texel is NaN");
      x = std::clamp(x, 0.f, 1.f);
    }
  const int nm = static_cast<int>(scene.materials.size());
  const int nt = static_cast<int>(scene.textures.size()), nf = static_cast<int>(scene.float_textures.size());
  bool averaged = false;
  for (Material& m : scene.materials) {
    if (m.texture >= nt || m.transmittance_texture >= nt) throw SceneError("material: error: texture index out of range");
    if (m.displacement >= nf) throw SceneError("material: error: displacement texture index out of range");
    if (m.displacement >= 0) {  // the bump map reads its texels (surface_hits.h float_texture_bilinear)
      const FloatTexture& t = scene.float_textures[static_cast<size_t>(m.displacement)];
      if (t.width < 1 || t.height < 1 || t.value.size() != static_cast<size_t>(t.width) * static_cast<size_t>(t.height))
        throw SceneError("material: error: displacement texture \"" + t.name + "\" has " + std::to_string(t.value.size()) +
                         " values for " + std::to_string(t.width) + "x" + std::to_string(t.height) + " texels");
    }
    for (FloatParam* f : {&m.alpha_u, &m.alpha_v})  // looked up per hit (surface_hits.h)
      if (f->texture >= nf) throw SceneError("material: error: float texture index out of range");
    for (FloatParam* f : {&m.base_alpha_u, &m.base_alpha_v, &m.mix_amount}) {
      if (f->texture >= nf) throw SceneError("material: error: float texture index out of range");
      if (f->texture < 0) continue;
      const FloatTexture& t = scene.float_textures[static_cast<size_t>(f->texture)];
      double sum = 0;
      for (float v : t.value) sum += v;
      const float mean = t.value.empty() ? 0.f : static_cast<float>(sum / static_cast<double>(t.value.size()));
      const bool alpha = f != &m.mix_amount;  // a coated conductor's base
      f->value = alpha && m.remap_roughness ? std::sqrt(std::max(mean, 0.f)) : mean;
      f->texture = -1;
      averaged = averaged || t.width * t.height > 1;
    }
    for (float v : {m.eta, m.alpha_u.value, m.alpha_v.value, m.base_alpha_u.value, m.base_alpha_v.value, m.thickness,
                    m.eta_rgb.r, m.eta_rgb.g, m.eta_rgb.b, m.k_rgb.r, m.k_rgb.g, m.k_rgb.b})
      if (!std::isfinite(v) || v < 0) throw SceneError("material: error: a parameter is negative, NaN or infinite");
    if (m.mix[0] >= 0) {
      for (int i : m.mix)
        if (i < 0 || i >= nm || scene.materials[static_cast<size_t>(i)].mix[0] >= 0)
          throw SceneError("material: error: mix of a material index out of range, or of a mix");
    }
  }
  std::vector<char> built(scene.float_textures.size(), 0);
  for (const Material& m : scene.materials)  // the bump maps read MIP levels (wave/textures.h)
    if (m.displacement >= 0 && !built[static_cast<size_t>(m.displacement)]) {
      build_mip(scene.float_textures[static_cast<size_t>(m.displacement)]);
      built[static_cast<size_t>(m.displacement)] = 1;
    }
  if (averaged)
    scene.warnings.push_back(
        "textured mix amount or coated conductor base roughness: approximated by the texture's mean (one value per material)");
  // pbrt-v4 bumps a sphere in its (phi, theta) parameterisation, which tuile does not keep
  bool sphere_bump = false;
  for (const Sphere& s : scene.spheres) {
    if (s.material < 0 || s.material >= nm) continue;
    const Material& m = scene.materials[static_cast<size_t>(s.material)];
    if (m.mix[0] < 0) sphere_bump = sphere_bump || bumps(scene, m);
    else  // (a mix's own displacement is not used: pbrt-v4 bumps with the material it chose)
      for (int i : m.mix) sphere_bump = sphere_bump || bumps(scene, scene.materials[static_cast<size_t>(i)]);
  }
  if (sphere_bump) scene.warnings.push_back("displacement (bump mapping) on spheres: not supported, they are shaded smooth");
}

// Numbers and indices: a clear error naming what is wrong (meshes, spheres, materials, the
// camera); pads each mesh's vertex buffer for Embree.
void validate_scene(Scene& scene) {
  for (Mesh& m : scene.meshes) {
    if (m.positions.size() % 3 != 0 && m.positions.size() % 3 != 1)
      throw SceneError(m.name + ": error: vertex positions are not a multiple of 3");
    if (m.indices.size() % 3 != 0) throw SceneError(m.name + ": error: triangle indices are not a multiple of 3");
    const size_t nv = m.positions.size() / 3;
    for (size_t i = 0; i < 3 * nv; ++i)
      if (!std::isfinite(m.positions[i]))
        throw SceneError(m.name + ": error: vertex " + std::to_string(i / 3) + " has a NaN or infinite coordinate");
    for (size_t i = 0; i < m.indices.size(); ++i)
      if (m.indices[i] >= nv)
        throw SceneError(m.name + ": error: index " + std::to_string(m.indices[i]) + " out of range (" +
                         std::to_string(nv) + " vertices)");
    if (!m.uvs.empty() && m.uvs.size() != 2 * nv) throw SceneError(m.name + ": error: uv count does not match vertices");
    if (!m.normals.empty() && m.normals.size() != 3 * nv)
      throw SceneError(m.name + ": error: normal count does not match vertices");
    for (float v : m.normals)
      if (!std::isfinite(v)) throw SceneError(m.name + ": error: a shading normal has a NaN or infinite component");
    for (float v : m.uvs)
      if (!std::isfinite(v)) throw SceneError(m.name + ": error: a uv coordinate is NaN or infinite");
    if (m.material >= static_cast<int>(scene.materials.size()))
      throw SceneError(m.name + ": error: material index out of range");
    for (float c : {m.emission.r, m.emission.g, m.emission.b})
      if (!std::isfinite(c) || c < 0) throw SceneError(m.name + ": error: emitted radiance must be finite and >= 0");
    // Embree may read 4 bytes past the last float3 vertex of a shared buffer.
    if (m.positions.size() % 3 == 0) m.positions.push_back(0.f);
  }
  for (const Sphere& s : scene.spheres)
    if (!finite3(s.center) || !std::isfinite(s.radius) || !(s.radius > 0))
      throw SceneError("sphere: error: centre and radius must be finite, radius > 0");
  for (Curves& c : scene.curves) {
    if (c.points.size() % 16 != 0) throw SceneError(c.name + ": error: curve control points are not 4 per segment");
    for (size_t i = 0; i < c.points.size(); ++i)
      if (!std::isfinite(c.points[i]) || (i % 4 == 3 && c.points[i] < 0))
        throw SceneError(c.name + ": error: a curve control point is not finite or has a negative width");
    if (c.type == CurveType::ribbon && c.normals.size() / 3 != c.points.size() / 4)
      throw SceneError(c.name + ": error: a ribbon curve needs one normal per control point");
    if (c.material >= static_cast<int>(scene.materials.size()))
      throw SceneError(c.name + ": error: material index out of range");
    if (c.normals.size() % 3 == 0 && !c.normals.empty()) c.normals.push_back(0.f);  // Embree's float3 read past the end
  }
  // instanced objects: shapes of a known object that do not emit; placements by finite,
  // invertible transforms
  const auto bad_object = [&](int o) { return o < -1 || o >= static_cast<int>(scene.objects.size()); };
  for (const Mesh& m : scene.meshes) {
    if (bad_object(m.object)) throw SceneError(m.name + ": error: object index out of range");
    if (m.object >= 0 && m.emissive())
      throw SceneError(m.name + ": error: an instanced object's shape cannot emit (pbrt-v4 does not instance area lights)");
  }
  for (const Sphere& s : scene.spheres)
    if (bad_object(s.object) || (s.object >= 0 && s.emissive()))
      throw SceneError("sphere: error: object index out of range, or an instanced object's sphere emits");
  for (const Curves& c : scene.curves)
    if (bad_object(c.object)) throw SceneError(c.name + ": error: object index out of range");
  for (const Instance& in : scene.instances) {
    const std::string where = in.where.empty() ? scene.source : in.where;
    if (in.object < 0 || in.object >= static_cast<int>(scene.objects.size()))
      throw SceneError(where + ": error: instance of an unknown object");
    const auto& m = in.world_from_object;
    for (const auto& row : m)
      for (float v : row)
        if (!std::isfinite(v)) throw SceneError(where + ": error: instance transform has a NaN or infinite entry");
    const double det = double(m[0][0]) * (double(m[1][1]) * m[2][2] - double(m[1][2]) * m[2][1]) -
                       double(m[0][1]) * (double(m[1][0]) * m[2][2] - double(m[1][2]) * m[2][0]) +
                       double(m[0][2]) * (double(m[1][0]) * m[2][1] - double(m[1][1]) * m[2][0]);
    if (!(std::abs(det) > 1e-30) || !std::isfinite(det) || !std::isfinite(1 / det))
      throw SceneError(where + ": error: singular instance transform (determinant " + std::to_string(det) +
                       "; expected an invertible transform)");
  }
  resolve_material_params(scene);
  const Camera& c = scene.camera;
  if (c.width < 1 || c.height < 1 || c.width > 32768 || c.height > 32768 ||
      static_cast<double>(c.width) * c.height > double(1u << 28))
    throw SceneError(scene.source + ": error: absurd image resolution " + std::to_string(c.width) + "x" +
                     std::to_string(c.height) + " (expected 1..32768 per axis, at most 2^28 pixels)");
  if (!(c.fov_deg > 0 && c.fov_deg < 180)) throw SceneError(scene.source + ": error: camera fov must be in (0, 180)");
}

// The light table: the delta lights the loader gave, its skies (constant ones added into
// one: the same density, their radiances sum), an area light per emissive triangle (or
// parallelogram, where two triangles of a mesh form one) and per emissive sphere, each
// with its kind's power (light/kinds/).
void derive_lights(Scene& scene) {
  std::vector<Light> lights;
  int sky = -1;
  for (const Light& l : scene.lights) {
    if (is_delta(l.type)) lights.push_back(l);
    if (!is_sky(l.type)) continue;
    if (l.sky_map >= 0) {  // a map: a source of its own
      if (static_cast<size_t>(l.sky_map) >= scene.sky_maps.size())
        throw SceneError(scene.source + ": error: a sky refers to a missing environment map");
      lights.push_back(l);
      continue;
    }
    if (sky < 0) {
      sky = static_cast<int>(lights.size());
      lights.push_back(l);
    } else {
      Rgb& L = lights[static_cast<size_t>(sky)].radiance;
      L = {L.r + l.radiance.r, L.g + l.radiance.g, L.b + l.radiance.b};
    }
  }
  size_t slivers = 0;  // emissive triangles of some area, too thin to sample (dropped as lights)
  double sliver_power = 0;
  std::string sliver_mesh;
  for (size_t mi = 0; mi < scene.meshes.size(); ++mi) {
    Mesh& m = scene.meshes[mi];
    m.prim_light.clear();
    if (!m.emissive() || m.object >= 0) continue;
    m.prim_light.assign(m.triangle_count(), -1);
    const float sign = m.reverse_orientation ? -1.f : 1.f;
    for (size_t t = 0; t < m.triangle_count(); ++t) {
      Light l;
      l.radiance = m.emission;
      l.two_sided = m.two_sided;
      l.mesh = static_cast<int>(mi);
      l.prim = static_cast<int>(t);
      vec3f p0, e1, e2;
      // (a cut-out mesh keeps its triangles: the light stage looks its alpha up per triangle)
      const bool quad = !m.has_alpha() && match_parallelogram(m, t, p0, e1, e2);
      if (!quad) {
        p0 = vertex(m, m.indices[3 * t]);
        e1 = vertex(m, m.indices[3 * t + 1]) - p0;
        e2 = vertex(m, m.indices[3 * t + 2]) - p0;
      }
      if (degenerate(e1, e2)) {  // a zero-area emitter emits nothing
        const float a2 = length_sq(cross(e1, e2));
        if (a2 > 0.f && std::isfinite(a2)) {  // (not zero: a sliver, too thin to sample as a light)
          ++slivers;
          sliver_power += 0.5 * std::sqrt(double(a2)) * luminance(m.emission) * 3.14159265358979 * (m.two_sided ? 2 : 1);
          if (sliver_mesh.empty()) sliver_mesh = m.name;
        }
        continue;
      }
      l.type = quad ? LightKind::parallelogram : LightKind::triangle;
      if (sign < 0) std::swap(e1, e2);  // emission side follows cross(e1, e2)
      l.p0 = p0;
      l.e1 = e1;
      l.e2 = e2;
      l.area = length(cross(e1, e2)) * (quad ? 1.f : 0.5f);
      m.prim_light[t] = static_cast<int32_t>(lights.size());
      if (quad) m.prim_light[t + 1] = static_cast<int32_t>(lights.size());
      lights.push_back(l);
      if (quad) ++t;
    }
  }
  if (slivers > 0) {
    char power[32];
    std::snprintf(power, sizeof(power), "%.3g", sliver_power);
    scene.warnings.push_back(std::to_string(slivers) + " emissive triangle(s) (the first in " + sliver_mesh +
                             ") are slivers, narrower than a millionth of their edges: too thin to sample as lights, "
                             "they emit nothing (" + power + " W of the file's emission lost)");
  }
  for (size_t si = 0; si < scene.spheres.size(); ++si) {
    Sphere& s = scene.spheres[si];
    s.light = -1;
    if (!s.emissive()) continue;
    if (s.reverse_orientation) {
      scene.warnings.push_back("sphere emitting inwards: not supported as a light, its emission is ignored");
      continue;
    }
    Light l;
    l.type = LightKind::sphere;
    l.p0 = s.center;
    l.e1 = {s.radius, 0, 0};
    l.radiance = s.emission;
    l.area = 4.f * 3.14159265f * s.radius * s.radius;
    l.sphere = static_cast<int>(si);
    s.light = static_cast<int>(lights.size());
    lights.push_back(l);
  }
  // scene bounds for the power of distant lights
  vec3f lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
  // (an object's bounds once, then its box's corners placed by each instance)
  std::vector<vec3f> olo(scene.objects.size(), vec3f{1e30f, 1e30f, 1e30f}), ohi(scene.objects.size(), vec3f{-1e30f, -1e30f, -1e30f});
  for (const Mesh& m : scene.meshes) {
    vec3f& l = m.object < 0 ? lo : olo[static_cast<size_t>(m.object)];
    vec3f& h = m.object < 0 ? hi : ohi[static_cast<size_t>(m.object)];
    for (size_t i = 0; i + 2 < m.positions.size(); i += 3) {
      l = {std::min(l.x, m.positions[i]), std::min(l.y, m.positions[i + 1]), std::min(l.z, m.positions[i + 2])};
      h = {std::max(h.x, m.positions[i]), std::max(h.y, m.positions[i + 1]), std::max(h.z, m.positions[i + 2])};
    }
  }
  for (const Instance& in : scene.instances) {
    const vec3f a = olo[static_cast<size_t>(in.object)], b = ohi[static_cast<size_t>(in.object)];
    if (!(b.x >= a.x)) continue;
    const auto& M = in.world_from_object;
    for (int c = 0; c < 8; ++c) {
      const vec3f p{c & 1 ? b.x : a.x, c & 2 ? b.y : a.y, c & 4 ? b.z : a.z};
      const vec3f w{M[0][0] * p.x + M[0][1] * p.y + M[0][2] * p.z + M[0][3], M[1][0] * p.x + M[1][1] * p.y + M[1][2] * p.z + M[1][3],
                    M[2][0] * p.x + M[2][1] * p.y + M[2][2] * p.z + M[2][3]};
      lo = {std::min(lo.x, w.x), std::min(lo.y, w.y), std::min(lo.z, w.z)};
      hi = {std::max(hi.x, w.x), std::max(hi.y, w.y), std::max(hi.z, w.z)};
    }
  }
  const float radius = hi.x >= lo.x ? 0.5f * length(hi - lo) : 1.f;
  for (Light& l : lights) {
    for (float v : {l.radiance.r, l.radiance.g, l.radiance.b})
      if (!std::isfinite(v) || v < 0) throw SceneError(scene.source + ": error: light intensity must be finite and >= 0");
    Rgb L = l.radiance;
    if (l.sky_map >= 0) {  // a map's power: its mean texel times the radiance's scale
      const double* m = scene.sky_maps[static_cast<size_t>(l.sky_map)].mean;
      L = {L.r * static_cast<float>(m[0]), L.g * static_cast<float>(m[1]), L.b * static_cast<float>(m[2])};
    }
    l.power = light_power(l, luminance(L), radius);
  }
  scene.lights = std::move(lights);
}

// The scene's feature bits (SceneFeature), which pick its tile pipeline.
void detect_features(Scene& scene) {
  uint32_t f = 0;
  bool any_area = false, any_delta = false, any_sky = false;
  for (const Light& l : scene.lights) (is_delta(l.type) ? any_delta : is_sky(l.type) ? any_sky : any_area) = true;
  if (any_area) f |= feat_area_lights | feat_visible_emitters;
  if (any_delta) f |= feat_delta_lights;
  if (any_sky) f |= feat_sky;
  if (scene.lights.size() == 1) f |= feat_single_light;
  for (const Material& mt : scene.materials)
    if (mt.texture >= 0) f |= feat_textures;
  if (!scene.spheres.empty()) f |= feat_spheres;
  auto rendered = [&](int m) { return m >= 0 && scene.media[static_cast<size_t>(m)].supported; };
  bool media = rendered(scene.camera_medium);
  for (const Mesh& m : scene.meshes) media = media || rendered(m.medium_inside) || rendered(m.medium_outside);
  for (const Sphere& s : scene.spheres) media = media || rendered(s.medium_inside) || rendered(s.medium_outside);
  for (const Curves& c : scene.curves) media = media || rendered(c.medium_inside) || rendered(c.medium_outside);
  if (media) f |= feat_media;
  // the test light_geom_derive applies to a source's edges (a kernel's rule, in one place)
  bool all_rects = !scene.lights.empty();
  for (const Light& l : scene.lights)
    all_rects = all_rects && l.type == LightKind::parallelogram && parallelogram_is_rectangle(l.e1, l.e2);
  if (all_rects) f |= feat_rect_lights_only;
  scene.features = f;
}

}  // namespace

AlphaShape alpha_shape(const Scene& scene, const Mesh& m) {
  AlphaShape a;
  a.indices = m.indices.data();
  a.positions = m.positions.data();
  a.uvs = m.uvs.empty() ? nullptr : m.uvs.data();
  a.value = m.alpha.value;
  if (m.alpha.texture >= 0) {
    const FloatTexture& t = scene.float_textures[static_cast<size_t>(m.alpha.texture)];
    a.tex = t.value.data();
    a.tex_w = t.width;
    a.tex_h = t.height;
  }
  return a;
}

void finalize_scene(Scene& scene) {
  validate_scene(scene);
  derive_lights(scene);
  detect_features(scene);
}

Scene load_scene(const std::string& path, const LoadOptions& options) {
  Scene s;
  if (path.rfind("built-in:", 0) == 0) s = builtin_scene(path.substr(9));
  else s = load_pbrt(path, options);
  finalize_scene(s);
  return s;
}

int rendered_medium(const Scene& scene, int medium) {
  return medium >= 0 && scene.media[static_cast<size_t>(medium)].supported ? medium : -1;
}

bool passes_between_media(const Scene& scene, int material, int medium_inside, int medium_outside, bool emissive) {
  return (scene.features & feat_media) && !emissive && material >= 0 &&
         scene.materials[static_cast<size_t>(material)].interface &&
         rendered_medium(scene, medium_inside) != rendered_medium(scene, medium_outside);
}

}  // namespace tuile
