// Light paths (--light-paths): the light tracer of render/light_paths.h.
#include "render/light_paths.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <stdexcept>

#include "light/kinds.h"
#include "light/table.h"
#include "sample/rng.h"
#include "sample/sampling.h"
#include "wave/accumulate.h"
#include "wave/alpha.h"
#include "wave/media.h"
#include "wave/path.h"
#include "wave/surface_bsdf.h"
#include "wave/surface_hits.h"

namespace tuile {

namespace {

bool is_area(int32_t type) {
  return type == static_cast<int32_t>(LightKind::triangle) || type == static_cast<int32_t>(LightKind::parallelogram) ||
         type == static_cast<int32_t>(LightKind::sphere);
}

bool is_distant(int32_t type) { return type == static_cast<int32_t>(LightKind::distant); }

// The largest alpha of the glossy lobes whose light from an area source the light tracer
// takes with --light-paths=glossy (light_paths.h), and of those auto's glossy choice counts.
constexpr float light_traced_alpha = 0.1f;
// The same for a distant source's light (where no area source's is taken: one flag per
// material). Measured (bench/results.md, "Light paths"): at 0.03 (a coat of roughness 0.01)
// dining-room's relMSE fell 1.3-2x, at 0.06 (its chrome too) and 0.1 (its chairs, lamps and
// windows) more, and classroom's body (its desks' coats of 0.1) 2.3x; 0.2 or 0.5 changed
// nothing more than the time then. Once coated first vertices joined the sun's light paths
// (wave/path.h sun_traced_material), 0.25 (its black paint's and rubber's lobes of 0.2 too)
// took dining-room's worst seed of five from 0.023 to 0.011 at 64 spp, for 5% more time;
// 0.5 gave the same there ("Coated first vertices").
constexpr float sun_glossy_alpha = 0.25f;

bool any_used_material(const Scene& scene, const std::function<bool(const Material&)>& pred) {
  const size_t n = scene.materials.size();
  auto test = [&](int m) {
    if (m < 0 || static_cast<size_t>(m) >= n) return false;
    const Material& x = scene.materials[static_cast<size_t>(m)];
    if (x.mix[0] >= 0 || x.mix[1] >= 0) {  // a mix's two choices (never mixes themselves)
      for (const int c : x.mix)
        if (c >= 0 && static_cast<size_t>(c) < n && pred(scene.materials[static_cast<size_t>(c)])) return true;
      return false;
    }
    return pred(x);
  };
  for (const Mesh& m : scene.meshes)
    if (test(m.material)) return true;
  for (const Sphere& s : scene.spheres)
    if (test(s.material)) return true;
  return false;
}

// --light-paths auto's glossy choice (light_paths_pay): the share of the area sources'
// power that falls on a near-specular surface from a source that looks small from it.
// Measured on the corpus (bench/results.md, "Area sources' glossy caustics"): veach-mis
// 0.048 (its near-mirror plate of alpha 0.01 under a lamp of radius 0.05), staircase2
// 2.5e-6, every other scene 0.
constexpr double glint_share_min = 0.01;
// A surface's highlight of a source, the source's solid angle plus its lobe's, below which
// the path tracer's paths through it (a rough point's direction towards the surface, then a
// light sample or a BSDF sample there) find the source's reflection only by chance (sr).
constexpr double glint_solid_angle_max = 3e-3;
// --light-paths auto's caustics onto surfaces: the share of the area sources' power that
// falls on smooth glass or mirrors from a source that looks small from them (below
// glint_solid_angle_max), from which on. Measured on the corpus (bench/results.md, "Auto's
// caustics onto surfaces"): veach-bidir 0.016 (its spot lamp over the glass egg; 2.2x the
// efficiency with light paths), staircase2 1.3e-4 (0.68x), the other scenes with glass or
// mirrors and area sources 0 (kitchen 0.89x, bathroom 0.89x, living-room-3 0.94x).
constexpr double caustic_share_min = 0.003;
// At most this many (surface triangle, source) pairs are visited; larger scenes stride
// through their triangles.
constexpr double glint_pairs_max = 1 << 22;

}  // namespace

namespace {

// The share of the area sources' power that falls on the surfaces whose top lobe `lobe_of`
// takes (its weight: the share of light that lobe reflects or transmits, and its alpha),
// from a source whose highlight there, its solid angle plus the lobe's, is below
// glint_solid_angle_max: area_glint_share's near-specular lobes, area_caustic_share's delta
// ones.
template <class LobeOf>
double small_source_share(const Scene& scene, LobeOf&& lobe_of) {
  constexpr double pi = 3.14159265358979323846;
  // the sources, one per emitting mesh or sphere: a sphere round them, their power, and for a
  // flat one its normal (the triangles' summed normals, as long as their summed lengths)
  struct Lamp {
    vec3f c{0, 0, 0}, n{0, 0, 0};
    double r = 0, power = 0, area = 0;
    vec3f lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    bool sphere = false, two_sided = false;
  };
  std::vector<Lamp> lamps;
  std::vector<int> mesh_lamp(scene.meshes.size(), -1), sphere_lamp(scene.spheres.size(), -1);
  double total = 0;
  for (const Light& l : scene.lights) {
    if (!is_area(static_cast<int32_t>(l.type)) || !(l.power > 0) || !std::isfinite(l.power)) continue;
    int* slot = nullptr;
    if (l.sphere >= 0 && static_cast<size_t>(l.sphere) < scene.spheres.size()) slot = &sphere_lamp[static_cast<size_t>(l.sphere)];
    else if (l.mesh >= 0 && static_cast<size_t>(l.mesh) < scene.meshes.size()) slot = &mesh_lamp[static_cast<size_t>(l.mesh)];
    if (slot == nullptr) continue;
    if (*slot < 0) {
      *slot = static_cast<int>(lamps.size());
      lamps.emplace_back();
    }
    Lamp& a = lamps[static_cast<size_t>(*slot)];
    a.power += l.power;
    total += l.power;
    a.two_sided = l.two_sided;
    if (l.type == LightKind::sphere) {
      a.sphere = true;
      a.c = l.p0;
      a.r = l.e1.x;
      continue;
    }
    const vec3f v[4] = {l.p0, l.p0 + l.e1, l.p0 + l.e2, l.p0 + l.e1 + l.e2};
    for (int i = 0; i < (l.type == LightKind::parallelogram ? 4 : 3); ++i) {
      a.lo = {std::min(a.lo.x, v[i].x), std::min(a.lo.y, v[i].y), std::min(a.lo.z, v[i].z)};
      a.hi = {std::max(a.hi.x, v[i].x), std::max(a.hi.y, v[i].y), std::max(a.hi.z, v[i].z)};
    }
    const vec3f nc = cross(l.e1, l.e2);
    a.n = a.n + nc;
    a.area += static_cast<double>(length(nc));
  }
  if (lamps.empty() || !(total > 0)) return 0;
  for (Lamp& a : lamps) {
    if (a.sphere) continue;
    a.c = (a.lo + a.hi) * 0.5f;
    a.r = static_cast<double>(length(a.hi - a.lo)) * 0.5;
    const double nl = static_cast<double>(length(a.n));
    a.n = nl > 0.9 * a.area && nl > 0 ? a.n * static_cast<float>(1 / nl) : vec3f{0, 0, 0};  // (not flat: none)
  }
  // the near-specular materials, each with the share of light its top lobe reflects or
  // transmits (a coat: its Fresnel reflectance at normal incidence)
  auto glint = [&](int mi, double& alpha) -> double {
    if (mi < 0 || static_cast<size_t>(mi) >= scene.materials.size()) return 0;
    return lobe_of(scene.materials[static_cast<size_t>(mi)], alpha);
  };
  double share = 0;
  // the light a point x of normal n and area A receives from each source, where the
  // source's highlight there (its solid angle plus the lobe's) is small
  auto visit = [&](const vec3f& x, const vec3f& n, double A, double alpha, double weight) {
    const double lobe = pi * 4 * alpha * alpha;  // (the reflected directions spread by about 2 alpha)
    if (lobe >= glint_solid_angle_max) return;
    for (const Lamp& a : lamps) {
      vec3f w = a.c - x;
      const double d2 = static_cast<double>(dot(w, w));
      if (!(d2 > a.r * a.r)) continue;  // (inside the source's sphere: not small)
      const double omega = pi * a.r * a.r / d2;
      if (omega + lobe >= glint_solid_angle_max) continue;
      w = w * static_cast<float>(1 / std::sqrt(d2));
      double intensity = a.power / (4 * pi);  // (W/sr towards x)
      if (a.n.x != 0 || a.n.y != 0 || a.n.z != 0) {
        const double c = -static_cast<double>(dot(w, a.n));
        intensity = a.two_sided ? a.power * std::abs(c) / (2 * pi) : c > 0 ? a.power * c / pi : 0;
      }
      share += weight * intensity * std::abs(static_cast<double>(dot(w, n))) * A / d2 / total;
    }
  };
  // a geometry's material: itself, or a mix's two choices, half each
  auto visit_material = [&](int mi, auto&& at) {
    if (mi < 0 || static_cast<size_t>(mi) >= scene.materials.size()) return;
    const Material& m = scene.materials[static_cast<size_t>(mi)];
    const bool mix = m.mix[0] >= 0 || m.mix[1] >= 0;
    const int choices[2] = {mix ? m.mix[0] : mi, mix ? m.mix[1] : -1};
    for (const int c : choices) {
      double alpha = 0;
      const double w = glint(c, alpha) * (mix ? 0.5 : 1.0);
      if (w > 0) at(alpha, w);
    }
  };
  size_t triangles = 0;
  for (const Mesh& m : scene.meshes)
    if (m.object < 0) triangles += m.triangle_count();
  const size_t stride = std::max<size_t>(1, static_cast<size_t>(std::ceil(static_cast<double>(triangles) *
                                                                          static_cast<double>(lamps.size()) / glint_pairs_max)));
  for (const Mesh& m : scene.meshes) {
    if (m.object >= 0) continue;
    visit_material(m.material, [&](double alpha, double weight) {
      const size_t nt = m.triangle_count(), np = m.positions.size() / 3;
      for (size_t t = 0; t < nt; t += stride) {
        uint32_t id[3];
        for (int j = 0; j < 3; ++j) id[j] = m.indices[3 * t + static_cast<size_t>(j)];
        if (id[0] >= np || id[1] >= np || id[2] >= np) continue;
        auto p = [&](uint32_t i) { return vec3f{m.positions[3 * i], m.positions[3 * i + 1], m.positions[3 * i + 2]}; };
        const vec3f p0 = p(id[0]), p1 = p(id[1]), p2 = p(id[2]);
        const vec3f nc = cross(p1 - p0, p2 - p0);
        const float l = length(nc);
        if (!(l > 0)) continue;
        visit((p0 + p1 + p2) * (1.f / 3), nc * (1.f / l), 0.5 * static_cast<double>(l) * static_cast<double>(stride), alpha,
              weight);
      }
    });
  }
  for (const Sphere& s : scene.spheres) {
    if (s.object >= 0) continue;
    visit_material(s.material, [&](double alpha, double weight) {  // (six points, a sixth of the area each)
      const vec3f axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
      for (const vec3f& n : axes)
        visit(s.center + n * s.radius, n, 4 * pi * s.radius * s.radius / 6, alpha, weight);
    });
  }
  return share;
}

// A microfacet top lobe of constant alphas: its larger alpha in `alpha` and its share of the
// light (a coat: its Fresnel reflectance at normal incidence; other lobes all of it); 0 for
// other materials.
double top_lobe_weight(const Material& m, double& alpha) {
  if (!microfacet_kind(static_cast<int32_t>(m.kind)) || m.alpha_u.texture >= 0 || m.alpha_v.texture >= 0) return 0;
  alpha = std::max(m.alpha_u.value, m.alpha_v.value);
  if (m.kind != MaterialKind::coated_diffuse) return 1;
  const double f = (m.eta - 1.0) / (m.eta + 1.0);
  return f * f;
}

}  // namespace

double area_glint_share(const Scene& scene) {
  return small_source_share(scene, [](const Material& m, double& alpha) -> double {
    const double w = top_lobe_weight(m, alpha);
    return alpha >= smooth_alpha && alpha <= light_traced_alpha ? w : 0;
  });
}

double area_caustic_share(const Scene& scene) {
  return small_source_share(scene, [](const Material& m, double& alpha) -> double {
    if (m.kind == MaterialKind::thin_dielectric) {
      alpha = 0;
      return 1;
    }
    alpha = 1;
    const double w = top_lobe_weight(m, alpha);
    if (!(alpha < smooth_alpha)) return 0;
    alpha = 0;  // (a delta lobe: no spread)
    return w;
  });
}

void set_light_ray(TileBuffers& tb, int i, const Vec3<float>& org, const Vec3<float>& d) {
  RayHit16& r = tb.bounce[i / packet_width];
  const int ln = i % packet_width;
  r.ray.org_x[ln] = org.x;
  r.ray.org_y[ln] = org.y;
  r.ray.org_z[ln] = org.z;
  r.ray.dir_x[ln] = d.x;
  r.ray.dir_y[ln] = d.y;
  r.ray.dir_z[ln] = d.z;
  r.ray.tfar[ln] = 3.0e38f;
  tb.tech.valid[i] = -1;
}

float adjoint_factor(const GeomView& G, int32_t mat, int32_t kind, float side, const Vec3<float>& ng, const Vec3<float>& ns,
                     const Vec3<float>& wo, const Vec3<float>& wi) {
  float adj = 1.f;
  const float cgi = dot(ng, wi);
  if (G.shading_normals) {
    const float den = std::abs(dot(ng, wo)) * std::abs(dot(ns, wi));
    adj = den > 0.f ? std::abs(dot(ns, wo)) * std::abs(cgi) / den : 0.f;
  }
  if (kind == static_cast<int32_t>(MaterialKind::dielectric) && cgi < 0.f) {
    const float eta = G.mat_param[mp_eta][mat];
    const float etap = side > 0.f ? eta : 1.f / eta;
    adj *= etap * etap;
  }
  return adj;
}

// The vertices a light path through a delta lobe from a point, spot or distant source joins
// to the camera (the path tracer has no sample of those paths): the rough kinds, and the
// microfacet kinds whose constant alphas are coat_join_alpha or more, the bound of the sun's
// glint joins (wave/path.h sun_traced_material: a sharper lobe's value towards the camera,
// up to 1 / (pi alpha^2), made fireflies there). Paths seen at sharper lobes stay
// unsampled, as in a path tracer.
static bool delta_path_joins(const GeomView& G, int32_t m) {
  const int32_t kind = G.mat_kind[m];
  if (light_traced_kind(kind)) return true;
  if (!microfacet_kind(kind)) return false;
  if (G.mat_alpha_tex != nullptr && (G.mat_alpha_tex[2 * m] >= 0 || G.mat_alpha_tex[2 * m + 1] >= 0)) return false;
  return std::min(G.mat_param[mp_ax][m], G.mat_param[mp_ay][m]) >= coat_join_alpha;
}

bool positional_light(int32_t type) {
  return type == static_cast<int32_t>(LightKind::point) || type == static_cast<int32_t>(LightKind::spot);
}

float spot_falloff(const LightGeom<float>& g, float cos_t) {
  const float c0 = g.e2.y, c1 = g.e2.x;
  const float t = std::min(1.f, std::max(0.f, (cos_t - c0) / std::max(c1 - c0, 1e-12f)));
  return t * t * (3.f - 2.f * t);
}

float sample_positional_direction(int32_t type, const LightGeom<float>& g, float u, float v, Vec3<float>& d, float& falloff) {
  if (type == static_cast<int32_t>(LightKind::point)) {
    d = sample_uniform_sphere<float>(u, v);
    falloff = 1.f;
    return 1.f / (4.f * pi_f);
  }
  const float ce = g.e2.y;
  const float ct = 1.f - u * (1.f - ce), st = std::sqrt(std::max(0.f, 1.f - ct * ct));
  const float ph = 2.f * pi_f * v;
  Vec3<float> t, b;
  make_basis(g.e1, t, b);
  d = normalize(t * (st * std::cos(ph)) + b * (st * std::sin(ph)) + g.e1 * ct);
  falloff = spot_falloff(g, ct);
  return 1.f / (2.f * pi_f * (1.f - ce));
}

double positional_power(int32_t type, const LightGeom<float>& g, double lum) {
  return type == static_cast<int32_t>(LightKind::point) ? 4 * pi_f * lum : 2 * pi_f * lum * (1 - 0.5 * (g.e2.x + g.e2.y));
}

namespace {

// Lane i's light path leaves its source: its first ray, its throughput (the largest
// channel m0 > 0), in medium med; eta_scale holds 1 / m0, for Russian roulette.
void emit(TileBuffers& tb, int i, const Vec3<float>& org, const Vec3<float>& d, float br, float bg, float bb, float m0,
          int32_t med) {
  set_light_ray(tb, i, org, d);
  tb.path.throughput_r[i] = br;
  tb.path.throughput_g[i] = bg;
  tb.path.throughput_b[i] = bb;
  tb.path.eta_scale[i] = 1.f / m0;  // (the light tracer's: 1 / the first throughput)
  tb.media.med[i] = med;
}

}  // namespace

LightPathsPay light_paths_pay(const Scene& scene, bool glossy_allowed) {
  bool distant = false, area = false, positional = false;
  for (const Light& l : scene.lights) {
    if (!l.radiance.any_positive()) continue;
    distant |= l.type == LightKind::distant;
    area |= is_area(static_cast<int32_t>(l.type));
    positional |= positional_light(static_cast<int32_t>(l.type));
  }
  const bool media = (scene.features & feat_media) != 0;
  if (area && glossy_allowed && !media && scene.instances.empty() && area_glint_share(scene) >= glint_share_min)
    return LightPathsPay::glossy;
  auto constant_alpha = [](const Material& m) { return m.alpha_u.texture < 0 && m.alpha_v.texture < 0; };
  if (distant && !media && scene.instances.empty() &&
      any_used_material(scene, [&](const Material& m) {
        const float a = std::max(m.alpha_u.value, m.alpha_v.value);
        return microfacet_kind(static_cast<int32_t>(m.kind)) && constant_alpha(m) && a >= smooth_alpha &&
               a <= sun_glossy_alpha;
      }))
    return LightPathsPay::on;
  // caustics onto surfaces from small sources: a spot lamp's through a glass egg
  if (area && area_caustic_share(scene) >= caustic_share_min) return LightPathsPay::on;
  // a point or spot source's light through a delta lobe, which the path tracer never samples
  auto delta_lobe = [&](const Material& m) {
    if (m.kind == MaterialKind::thin_dielectric) return true;
    return microfacet_kind(static_cast<int32_t>(m.kind)) && constant_alpha(m) &&
           std::max(m.alpha_u.value, m.alpha_v.value) < smooth_alpha;
  };
  if (positional && any_used_material(scene, delta_lobe)) return LightPathsPay::on;
  // a sun's light through smooth glass (a window), which the path tracer never samples
  // either: the light paths from a distant source reach it in scenes without media or
  // instances
  if (distant && !media && scene.instances.empty() && any_used_material(scene, [&](const Material& m) {
        return m.kind == MaterialKind::thin_dielectric || (m.kind == MaterialKind::dielectric && delta_lobe(m));
      }))
    return LightPathsPay::on;
  const bool scattering = std::any_of(scene.media.begin(), scene.media.end(),
                                      [](const Medium& m) { return m.supported && m.sigma_s.any_positive(); });
  const bool caustics = area && media && scattering && any_used_material(scene, delta_lobe);
  return caustics ? LightPathsPay::on : LightPathsPay::no;
}

float emitter_alpha(const LightView& L, int32_t l, const Vec3<float>& y) {
  if (!L.alpha_shape || L.alpha_shape[l] < 0) return 1.f;
  return std::clamp(
      alpha_at_point(L.alpha_shapes[L.alpha_shape[l]], static_cast<uint32_t>(std::max(L.alpha_prim[l], 0)), y.x, y.y, y.z), 0.f,
      1.f);
}

void source_media(const Scene& scene, const SceneViews& v, std::vector<int32_t>& out, std::vector<int32_t>& in_) {
  const LightView& L = v.lights;
  const GeomView& G = v.geom;
  out.assign(static_cast<size_t>(L.count), -1);
  in_.assign(static_cast<size_t>(L.count), -1);
  if (!G.has_media) return;
  for (int32_t i = 0; i < L.count; ++i)
    if (positional_light(L.type[i]) && static_cast<size_t>(i) < scene.lights.size())
      out[static_cast<size_t>(i)] = rendered_medium(scene, scene.lights[static_cast<size_t>(i)].medium);
  {
    std::vector<int32_t> light_geom(static_cast<size_t>(L.count), -1);
    const size_t tris = v.tri_light.size() - 1;
    for (int32_t g = 0; g < G.geom_count; ++g) {
      if (G.geom_kind[g] == static_cast<int32_t>(GeomKind::triangles)) {
        const size_t first = static_cast<size_t>(G.geom_first[g]);
        const size_t last = g + 1 < G.geom_count && G.geom_kind[g + 1] == static_cast<int32_t>(GeomKind::triangles)
                                ? static_cast<size_t>(G.geom_first[g + 1])
                                : tris;
        for (size_t t = first; t < last; ++t)
          if (G.tri_light[t] >= 0) light_geom[static_cast<size_t>(G.tri_light[t])] = g;
      } else if (G.geom_light[g] >= 0) {
        light_geom[static_cast<size_t>(G.geom_light[g])] = g;
      }
    }
    // (the geometry rows: the meshes, then the spheres, in scene order)
    const size_t meshes = scene.meshes.size();
    for (int32_t i = 0; i < L.count; ++i) {
      const int32_t g = light_geom[static_cast<size_t>(i)];
      if (g < 0) continue;
      const size_t gi = static_cast<size_t>(g);
      const int in0 = gi < meshes ? scene.meshes[gi].medium_inside : scene.spheres[gi - meshes].medium_inside;
      const int out0 = gi < meshes ? scene.meshes[gi].medium_outside : scene.spheres[gi - meshes].medium_outside;
      const int32_t inside = rendered_medium(scene, in0), outside = rendered_medium(scene, out0);
      // pbrt's outside: Embree's Ng (cross(e1, e2) for a triangle; outwards for a sphere)
      // times the shape's side; the source's normal says which side it emits on
      bool normal_out = true;
      if (L.type[i] == static_cast<int32_t>(LightKind::sphere)) {
        normal_out = G.geom_side[g] > 0.f;
      } else {
        const Vec3<float> e1{L.e1x[i], L.e1y[i], L.e1z[i]}, e2{L.e2x[i], L.e2y[i], L.e2z[i]};
        const Vec3<float> n{L.nx[i], L.ny[i], L.nz[i]};
        normal_out = dot(cross(e1, e2), n) * G.geom_side[g] > 0.f;
      }
      out[static_cast<size_t>(i)] = normal_out ? outside : inside;
      in_[static_cast<size_t>(i)] = normal_out ? inside : outside;
    }
  }
}

LightPaths::LightPaths(const Scene& scene, SceneViews& v, const Estimator& est, int width, int height, const float lo[3],
                       const float hi[3])
    : v_(v), est_(est), width_(width), height_(height) {
  const LightView& L = v.lights;
  const GeomView& G = v.geom;
  double total = 0;
  auto add_source = [&](int32_t i, double power) {
    if (!(power > 0) || !std::isfinite(power)) return;
    lights_.push_back(i);
    pmf_.push_back(static_cast<float>(power));
    total += power;
  };
  // the near-specular materials (and the discs round them)
  bool any_distant = false, any_area = false;
  for (int32_t i = 0; i < L.count; ++i) {
    any_distant |= is_distant(L.type[i]);
    any_area |= is_area(L.type[i]);
  }
  area_glossy_ = any_area && est.light_paths_glossy;
  sun_through_glass_ = any_distant && !G.has_media && !G.has_instances;
  if ((any_distant || area_glossy_) && !G.has_media && !G.has_instances) flag_glossy(scene, v, sun_through_glass_);
  area_glossy_ = area_glossy_ && glossy_discs_;
  v.lt_glossy.assign(static_cast<size_t>(L.count), 0);
  // area sources, where some surface can scatter by a delta lobe (or is near-specular)
  if ((v.bsdf_kinds & bsdf_delta_capable) != 0 || G.has_mix || area_glossy_)
    for (int32_t i = 0; i < L.count; ++i) {
      if (!is_area(L.type[i])) continue;
      const int32_t s = L.one_radiance ? 0 : i;
      const size_t before = lights_.size();
      add_source(i, static_cast<double>(luminance(L.Lr[s], L.Lg[s], L.Lb[s])) * L.area[i] * (L.two_sided[i] > 0.5f ? 2 : 1));
      if (area_glossy_ && lights_.size() > before) v.lt_glossy[static_cast<size_t>(i)] = 1;
    }
  // point and spot sources, where some surface can scatter by a delta lobe: the paths
  // whose vertex next to them is a delta lobe's have no sample of the path tracer's at all
  // (a light sample stops at the lobe, no BSDF sample meets a point), so the light tracer
  // takes them and the path tracer leaves nothing out
  if ((v.bsdf_kinds & bsdf_delta_capable) != 0 || G.has_mix)
    for (int32_t i = 0; i < L.count; ++i) {
      if (!positional_light(L.type[i])) continue;
      const int32_t s = L.one_radiance ? 0 : i;
      add_source(i, positional_power(L.type[i], broadcast_light<float>(L, i),
                                     static_cast<double>(luminance(L.Lr[s], L.Lg[s], L.Lb[s]))));
    }
  // distant sources, towards the near-specular surfaces and those with a delta lobe
  if (!discs_.empty()) {
    for (int32_t i = 0; i < L.count; ++i) {
      if (!is_distant(L.type[i])) continue;
      const int32_t s = L.one_radiance ? 0 : i;
      const size_t before = lights_.size();
      add_source(i, static_cast<double>(luminance(L.Lr[s], L.Lg[s], L.Lb[s])) * disc_area_);
      if (lights_.size() > before) v.lt_glossy[static_cast<size_t>(i)] = 1;
    }
  }
  if (std::find(v.lt_glossy.begin(), v.lt_glossy.end(), 1) == v.lt_glossy.end()) v.lt_glossy.clear();
  if (lights_.empty()) {
    why_ = "the scene has no area, point or spot light and a surface that scatters by a delta lobe, nor a distant "
           "source and a near-specular surface";
    return;
  }
  // nothing to join to the camera: no surface of a kind the light tracer joins (diffuse,
  // diffuse transmission) that scatters any light, and no medium (coffee: every surface it
  // sees a coat, the lights' own diffuse black); the path tracer's first vertices of those
  // kinds scatter nothing either, so what it would leave out is zero
  if (!G.has_media) {
    bool joinable = false;
    auto scatters = [&](int32_t m) {
      const size_t i = static_cast<size_t>(m);
      return (any_distant ? sun_traced_material(G, m) : light_traced_kind(v.mat_kind[i])) &&
             (v.mat_kind[i] != static_cast<int32_t>(MaterialKind::diffuse) || v.mat_texture[i] >= 0 ||
              v.mat_r[i] + v.mat_g[i] + v.mat_b[i] > 0.f);
    };
    for (const int32_t m : v.geom_material) {
      const size_t i = static_cast<size_t>(m);
      joinable |= v.mat_mix0[i] >= 0 ? scatters(v.mat_mix0[i]) || scatters(v.mat_mix1[i]) : scatters(m);
    }
    if (!joinable) {
      why_ = "no surface the light tracer joins to the camera (diffuse, diffuse transmission; coated diffuse under a "
             "distant source) scatters light, and the scene has no medium";
      lights_.clear();
      v.lt_glossy.clear();
      return;
    }
  }
  if (!v.lt_glossy.empty()) {  // the path tracer's light stages leave these paths to the light tracer
    v.geom.mat_lt_glossy = v.mat_lt_glossy.data();
    v.lights.lt_glossy = v.lt_glossy.data();
  }
  scene_c_[0] = 0.5f * (lo[0] + hi[0]);
  scene_c_[1] = 0.5f * (lo[1] + hi[1]);
  scene_c_[2] = 0.5f * (lo[2] + hi[2]);
  scene_r_ = 0.5f * std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) + (hi[2] - lo[2]) * (hi[2] - lo[2]));
  double run = 0;
  for (float& p : pmf_) {
    run += p;
    p = static_cast<float>(p / total);
    cdf_.push_back(static_cast<float>(run / total));
  }
  cdf_.back() = 1.f;
  source_media(scene, v, medium_out_, medium_in_);
  cam_.emplace(v.camera, width_, height_, "--light-paths");
  active_ = true;
}

// The near-specular materials (mat_lt_glossy) and the discs a distant source emits through:
// one per mesh or sphere that carries such a material (through a mix too), its bounding
// sphere. A material on another kind of geometry (curves) is not flagged: its paths stay
// the path tracer's.
void LightPaths::flag_glossy(const Scene& scene, SceneViews& v, bool sun_through_glass) {
  const GeomView& G = v.geom;
  const size_t nm = v.mat_kind.size();
  std::vector<int32_t>& flag = v.mat_lt_glossy;
  flag.assign(nm, 0);
  std::vector<uint8_t>& glass = sun_glass_;  // (glass: thin, or smooth: constant alphas below smooth_alpha)
  glass.assign(nm, 0);
  for (size_t m = 0; m < nm; ++m) {
    if (v.mat_kind[m] == static_cast<int32_t>(MaterialKind::thin_dielectric) && v.mat_mix0[m] < 0) glass[m] = sun_through_glass;
    if (!microfacet_kind(v.mat_kind[m]) || v.mat_mix0[m] >= 0) continue;
    if (2 * m + 1 < v.mat_alpha_tex.size() && (v.mat_alpha_tex[2 * m] >= 0 || v.mat_alpha_tex[2 * m + 1] >= 0)) continue;
    const float a = std::max(G.mat_param[mp_ax][m], G.mat_param[mp_ay][m]);
    flag[m] = a >= smooth_alpha && a <= (area_glossy_ ? light_traced_alpha : sun_glossy_alpha) ? 1 : 0;
    glass[m] = sun_through_glass && a < smooth_alpha && v.mat_kind[m] == static_cast<int32_t>(MaterialKind::dielectric);
  }
  for (size_t m = 0; m < nm && m < v.mat_reg.size(); ++m)  // (--regularize's twins: as their originals)
    if (v.mat_reg[m] != static_cast<int32_t>(m)) flag[static_cast<size_t>(v.mat_reg[m])] = flag[m];
  // the materials a geometry's material stands for: itself, or a mix's two choices (never
  // mixes themselves)
  auto reach = [&](int32_t m, auto&& visit) {
    if (v.mat_mix0[m] >= 0) {
      visit(v.mat_mix0[m]);
      visit(v.mat_mix1[m]);
    } else {
      visit(m);
    }
  };
  const size_t meshes = scene.meshes.size();
  auto supported = [&](int32_t g) {
    const auto k = static_cast<GeomKind>(G.geom_kind[g]);
    return (k == GeomKind::triangles && static_cast<size_t>(g) < meshes) || k == GeomKind::sphere;
  };
  for (int32_t g = 0; g < G.geom_count; ++g)
    if (!supported(g) && G.geom_kind[g] != static_cast<int32_t>(GeomKind::medium))
      reach(G.geom_material[g], [&](int32_t m) { flag[static_cast<size_t>(m)] = 0; });
  glossy_discs_ = false;
  for (int32_t g = 0; g < G.geom_count; ++g) {
    if (!supported(g)) continue;
    bool flagged = false, glassy = false;
    reach(G.geom_material[g], [&](int32_t m) {
      flagged |= flag[static_cast<size_t>(m)] != 0;
      glassy |= glass[static_cast<size_t>(m)] != 0;
    });
    if (!flagged && !glassy) continue;
    glossy_discs_ |= flagged;
    near_specular_surfaces_ += flagged;
    glass_surfaces_ += !flagged;
    Disc d{};
    if (G.geom_kind[g] == static_cast<int32_t>(GeomKind::sphere)) {
      const float* c = G.sphere_center + 4 * static_cast<size_t>(G.geom_first[g]);
      d = {c[0], c[1], c[2], c[3]};
    } else {
      const std::vector<float>& p = scene.meshes[static_cast<size_t>(g)].positions;
      if (p.empty()) continue;
      float b0[3] = {p[0], p[1], p[2]}, b1[3] = {p[0], p[1], p[2]};
      for (size_t i = 0; i + 2 < p.size(); i += 3)
        for (int a = 0; a < 3; ++a) {
          b0[a] = std::min(b0[a], p[i + a]);
          b1[a] = std::max(b1[a], p[i + a]);
        }
      d.cx = 0.5f * (b0[0] + b1[0]);
      d.cy = 0.5f * (b0[1] + b1[1]);
      d.cz = 0.5f * (b0[2] + b1[2]);
      double r2 = 0;
      for (size_t i = 0; i + 2 < p.size(); i += 3) {
        const double x = p[i] - d.cx, y = p[i + 1] - d.cy, z = p[i + 2] - d.cz;
        r2 = std::max(r2, x * x + y * y + z * z);
      }
      d.r = static_cast<float>(std::sqrt(r2));
    }
    d.r = d.r * (1.f + 0x1p-10f) + 1e-6f * (std::abs(d.cx) + std::abs(d.cy) + std::abs(d.cz) + d.r);  // (rounding)
    if (!(d.r > 0.f) || !std::isfinite(d.r)) continue;
    discs_.push_back(d);
  }
  // many surfaces: one disc round them all (the count per point stays cheap)
  if (discs_.size() > 64) {
    float b0[3] = {INFINITY, INFINITY, INFINITY}, b1[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (const Disc& d : discs_) {
      const float c[3] = {d.cx, d.cy, d.cz};
      for (int a = 0; a < 3; ++a) {
        b0[a] = std::min(b0[a], c[a] - d.r);
        b1[a] = std::max(b1[a], c[a] + d.r);
      }
    }
    const float h[3] = {0.5f * (b1[0] - b0[0]), 0.5f * (b1[1] - b0[1]), 0.5f * (b1[2] - b0[2])};
    discs_.assign(1, Disc{b0[0] + h[0], b0[1] + h[1], b0[2] + h[2], std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]) * 1.001f});
  }
  double run = 0;
  for (const Disc& d : discs_) run += static_cast<double>(d.r) * d.r * pi_f;
  disc_area_ = run;
  run = 0;
  for (const Disc& d : discs_) {
    run += static_cast<double>(d.r) * d.r * pi_f;
    disc_cdf_.push_back(static_cast<float>(run / disc_area_));
  }
  if (!disc_cdf_.empty()) disc_cdf_.back() = 1.f;
  if (discs_.empty()) flag.clear();
}

std::string LightPaths::describe() const {
  const LightView& L = v_.lights;
  int area = 0, positional = 0, distant = 0;
  for (const int32_t l : lights_) {
    area += is_area(L.type[l]);
    positional += positional_light(L.type[l]);
    distant += is_distant(L.type[l]);
  }
  std::string s = std::to_string(area) + " area, " + std::to_string(positional) + " point or spot, " +
                  std::to_string(distant) + " distant source(s)";
  if (distant > 0)
    s += "; the distant ones through " + std::to_string(discs_.size()) + " disc(s) round " +
         std::to_string(near_specular_surfaces_) + " near-specular surface(s) and " + std::to_string(glass_surfaces_) +
         " of smooth glass" + (discs_.size() == 1 && near_specular_surfaces_ + glass_surfaces_ > 1 ? " (one round them all)" : "");
  return s;
}

// A distant source's emission into lane i: a disc picked by area (u), a point uniform on it
// (u2, u3), the density the number of discs holding the point over their total area; the
// ray starts beyond the scene's bounding sphere and goes along the source's light. The lane's
// first_rough marks it as a distant source's (its first vertex: trace_tile).
void LightPaths::emit_distant(int32_t l, float pmf, float u, float u2, float u3, TileBuffers& tb, int i) const {
  const LightView& L = v_.lights;
  const Vec3<float> w{L.e1x[l], L.e1y[l], L.e1z[l]};  // towards the source
  const size_t di = std::min(static_cast<size_t>(std::upper_bound(disc_cdf_.begin(), disc_cdf_.end(), u) - disc_cdf_.begin()),
                             disc_cdf_.size() - 1);
  const Disc& dc = discs_[di];
  Vec3<float> t, b;
  make_basis(w, t, b);
  const float rr = dc.r * std::sqrt(u2), phi = 2.f * pi_f * u3;
  const Vec3<float> p = Vec3<float>(dc.cx, dc.cy, dc.cz) + t * (rr * std::cos(phi)) + b * (rr * std::sin(phi));
  int holding = 0;
  for (const Disc& o : discs_) {
    const double dx = static_cast<double>(p.x) - o.cx, dy = static_cast<double>(p.y) - o.cy, dz = static_cast<double>(p.z) - o.cz;
    const double along = dx * w.x + dy * w.y + dz * w.z;
    holding += dx * dx + dy * dy + dz * dz - along * along <= static_cast<double>(o.r) * o.r;
  }
  const int32_t sl = L.one_radiance ? 0 : l;
  const float scale = static_cast<float>(disc_area_ / (std::max(holding, 1) * static_cast<double>(pmf)));
  const float br = L.Lr[sl] * scale, bg = L.Lg[sl] * scale, bb = L.Lb[sl] * scale;
  const float m0 = std::max(std::max(br, bg), bb);
  if (!(m0 > 0.f) || !std::isfinite(m0)) return;
  const Vec3<float> c{scene_c_[0], scene_c_[1], scene_c_[2]};
  const float back = dot(c - p, w) + scene_r_ * 1.01f + 1e-3f * (scene_r_ + 1.f);
  emit(tb, i, p + w * back, -w, br, bg, bb, m0, -1);
  tb.path.first_rough[i] = 1.f;
}

void LightPaths::trace_tile(const Accel& accel, TileBuffers& tb, int tile, int tile_size, int tiles_x, uint32_t begin,
                            uint32_t end, uint32_t first_pair, std::vector<LightPathSplat>& out, uint64_t& rejected) const {
  if (!active_) return;
  const GeomView& G = v_.geom;
  const LightView& L = v_.lights;
  const Estimator& est = est_;
  Estimator hits = est;  // the hit stages' estimator: no one-sample choice, no regularization
  hits.mode = MisMode::multi;
  hits.regularize = false;
  const int x0 = (tile % tiles_x) * tile_size, y0 = (tile / tiles_x) * tile_size;
  const int tw = std::min(tile_size, width_ - x0), th = std::min(tile_size, height_ - y0);
  const int lanes = tw * th;
  const int padded = packet_padded(lanes);
  for (int i = 0; i < padded; ++i) {
    const int j = i < lanes ? i : 0;
    tb.lanes.pixel[i] = static_cast<uint32_t>(y0 + j / tw) * static_cast<uint32_t>(width_) + static_cast<uint32_t>(x0 + j % tw);
  }
  // the sampler's pairs: three for the emission, three per vertex (BSDF direction; lobe
  // and Russian roulette; the free flight of the ray that leaves it)
  const uint32_t pick_pair = first_pair, point_pair = first_pair + 1, dir_pair = first_pair + 2, flight0 = first_pair + 3;
  auto vertex_pair = [&](int j, int what) { return first_pair + 4 + 3 * static_cast<uint32_t>(j - 1) + static_cast<uint32_t>(what); };
  auto pairs = [&](const uint32_t* pixel, uint32_t s, uint32_t pair, int count, float* u, float* w) {
    sample_pairs(est.sampler, est.seed, pixel, s, est.spp, pair, count, u, w);
  };
  const bool media = G.has_media;
  const float inv_t = 1.f / est.rr_threshold;
  auto trace = [&](const int32_t* valid, RayHit16& p) { accel.intersect16(valid, p, false, Bvh::scene); };
  float* rx = tb.queue.x;  // per shading point: its raster position (the queue is free here)
  float* ry = tb.queue.y;

  for (uint32_t s = begin; s < end; ++s) {
    // the emission: a source by power, a point on it, a cosine-weighted direction
    pairs(tb.lanes.pixel, s, pick_pair, padded, tb.tech.u0, tb.tech.u1);
    pairs(tb.lanes.pixel, s, point_pair, padded, tb.tech.u2, tb.tech.u3);
    pairs(tb.lanes.pixel, s, dir_pair, padded, tb.ris.cr, tb.ris.cg);
    for (int i = 0; i < padded; ++i) {
      tb.points.lane[i] = i;
      tb.points.pixel[i] = tb.lanes.pixel[i];
      tb.tech.valid[i] = 0;
      tb.path.throughput_r[i] = tb.path.throughput_g[i] = tb.path.throughput_b[i] = 0.f;
      tb.path.eta_scale[i] = 1.f;
      tb.path.rough[i] = tb.path.first_rough[i] = 0.f;
      tb.media.med[i] = -1;
      if (i >= lanes) continue;
      const size_t pick = std::min(static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), tb.tech.u0[i]) - cdf_.begin()),
                                   cdf_.size() - 1);
      const int32_t l = lights_[pick];
      if (is_distant(L.type[l])) {  // a point on a disc, the ray from beyond the scene
        emit_distant(l, pmf_[pick], tb.tech.u1[i], tb.tech.u2[i], tb.tech.u3[i], tb, i);
        continue;
      }
      if (positional_light(L.type[l])) {  // from its position, the intensity I / (p pdf(d)) the spot's falloff
        const LightGeom<float> g = broadcast_light<float>(L, l);
        Vec3<float> d;
        float falloff;
        const float pdf_dir = sample_positional_direction(L.type[l], g, tb.ris.cr[i], tb.ris.cg[i], d, falloff);
        const int32_t sl = L.one_radiance ? 0 : l;
        const float scale = falloff / (pmf_[pick] * pdf_dir);
        const float br = L.Lr[sl] * scale, bg = L.Lg[sl] * scale, bb = L.Lb[sl] * scale;
        const float m0 = std::max(std::max(br, bg), bb);
        if (!(m0 > 0.f) || !std::isfinite(m0)) continue;
        emit(tb, i, g.p0, d, br, bg, bb, m0, medium_out_[static_cast<size_t>(l)]);
        tb.path.first_rough[i] = -1.f;  // (marks a positional source's path: its first vertex a delta lobe's alone)
        continue;
      }
      const LightGeom<float> g = broadcast_light<float>(L, l);
      Vec3<float> y, n;
      if (L.type[l] == static_cast<int32_t>(LightKind::sphere)) {
        y = LightKindOps<LightKind::sphere>::area_point(g, tb.tech.u2[i], tb.tech.u3[i]);
        n = normalize(y - g.p0);
      } else if (L.type[l] == static_cast<int32_t>(LightKind::triangle)) {
        y = LightKindOps<LightKind::triangle>::area_point(g, tb.tech.u2[i], tb.tech.u3[i]);
        n = g.n;
      } else {
        y = LightKindOps<LightKind::parallelogram>::area_point(g, tb.tech.u2[i], tb.tech.u3[i]);
        n = g.n;
      }
      const bool two = g.two_sided > 0.5f;
      const bool back = two && tb.tech.u1[i] >= 0.5f;
      if (back) n = Vec3<float>(0.f, 0.f, 0.f) - n;
      Vec3<float> t, b;
      make_basis(n, t, b);
      const Vec3<float> dl = sample_cosine_hemisphere<float>(tb.ris.cr[i], tb.ris.cg[i]);
      const Vec3<float> d = normalize(t * dl.x + b * dl.y + n * dl.z);
      const int32_t sl = L.one_radiance ? 0 : l;
      const float scale = g.area * pi_f * (two ? 2.f : 1.f) / pmf_[pick] * emitter_alpha(L, l, y);
      const float br = L.Lr[sl] * scale, bg = L.Lg[sl] * scale, bb = L.Lb[sl] * scale;
      const float m0 = std::max(std::max(br, bg), bb);
      if (!(m0 > 0.f) || !std::isfinite(m0) || !(dl.z > 0.f)) continue;
      const float eps = (std::max(std::max(std::abs(y.x), std::abs(y.y)), std::abs(y.z)) + 1.f) * 0x1p-16f;
      emit(tb, i, y + n * eps, d, br, bg, bb, m0, back ? medium_in_[static_cast<size_t>(l)] : medium_out_[static_cast<size_t>(l)]);
    }
    tb.points.count = lanes;
    for (int j = 1;; ++j) {
      // the rays that leave vertex j - 1 (the source at j = 1): their hits become vertex j
      const int count = tb.points.count;
      const int cp = packet_padded(count);
      for (int p = 0; p < cp / packet_width; ++p) {
        reset_hit(tb.bounce[p]);
        trace(tb.tech.valid + p * packet_width, tb.bounce[p]);
      }
      if (media) {
        pairs(tb.points.pixel, s, j == 1 ? flight0 : vertex_pair(j - 1, 2), cp, tb.media.u0, tb.media.u1);
        medium_flights(G, tb.bounce, tb.tech.valid, count, tb.media, tb.stats.rejected_bsdf, trace);
        for (int k = 0; k < count; ++k) {
          tb.path.throughput_r[k] *= tb.media.wr[k];
          tb.path.throughput_g[k] *= tb.media.wg[k];
          tb.path.throughput_b[k] *= tb.media.wb[k];
        }
      }
      if (j == 1) {
        // the first vertex must take a delta lobe's sample (from a distant source: a flagged
        // material's non-delta one): a hit whose material has none (a diffuse surface, a
        // point in a medium) ends its path before the hit stage
        for (int k = 0; k < count; ++k) {
          if (!tb.tech.valid[k]) continue;
          const RayHit16& r = tb.bounce[k / packet_width];
          const uint32_t g = r.geomID[k % packet_width];
          if (g == invalid_id) continue;
          const int32_t m = G.geom_material[g];
          const bool mix = G.has_mix && G.mat_mix0[m] >= 0;
          const bool from_distant = tb.path.first_rough[k] > 0.f;  // (near-specular: its own flag)
          const bool positional = tb.path.first_rough[k] < 0.f;   // (delta alone)
          const bool glossy = G.mat_lt_glossy != nullptr && G.mat_lt_glossy[m] != 0;
          const bool delta = ((1u << G.mat_kind[m]) & bsdf_delta_capable) != 0;
          const bool glass = !sun_glass_.empty() && sun_glass_[static_cast<size_t>(m)] != 0;
          if (!mix && (from_distant ? !(glossy || glass) : !(delta || (area_glossy_ && !positional && glossy))))
            tb.tech.valid[k] = 0;
        }
      }
      bounce_hits<vfloat, true>(G, L, hits, s, 0, tb);
      const int n = tb.points.count;
      if (n == 0) break;
      const int np = packet_padded(n);
      const ShadingPoints& P = tb.points;
      // vertex 2 on (the first took a delta lobe): joined to the camera
      if (j >= 2) {
        bool any = false;
        for (int k = 0; k < np; ++k) {
          tb.tech.valid[k] = 0;
          if (k >= n) continue;
          const Vec3<float> x{P.px[k], P.py[k], P.pz[k]};
          double rxk, ryk, vv[3], d2, density;
          if (!cam_->see(x, rxk, ryk, vv, d2, density)) continue;  // behind the camera, or outside the image
          const double dist = std::sqrt(d2);
          const Vec3<float> w{static_cast<float>(vv[0] / dist), static_cast<float>(vv[1] / dist), static_cast<float>(vv[2] / dist)};
          // the camera's importance per unit solid angle, per pixel: |M q|^3 / (A |det M|)
          const double importance = density / d2;
          const Vec3<float> ng{P.nx[k], P.ny[k], P.nz[k]};
          const Vec3<float> ns = G.shading_normals ? Vec3<float>(P.snx[k], P.sny[k], P.snz[k]) : ng;
          const Vec3<float> wo{P.wox[k], P.woy[k], P.woz[k]};  // towards the vertex before
          SurfaceBsdf<float, bsdf_all> bsdf = load_surface_bsdf<float, bsdf_all>(G, P, k, ns);
          // (a glossy or coated vertex: the path tracer's; but a distant source's light path
          // joins coated diffuse too: sun_traced_material, the path tracer's first_rough 0.5;
          // and a light path through a delta lobe from a point, spot or distant source, which
          // no sample of the path tracer's reaches, joins every vertex whose lobes are no
          // sharper than coat_join_alpha: delta_path_joins)
          if (!(tb.path.first_rough[k] > 0.f   ? sun_traced_material(G, P.mat[k])
                : tb.path.first_rough[k] < 0.f ? delta_path_joins(G, P.mat[k])
                                                : light_traced_kind(bsdf.kind)))
            continue;
          const bool in_medium = bsdf.kind == static_cast<int32_t>(MaterialKind::phase);
          const float cg = dot(ng, w);
          double geo = 1;
          if (!in_medium) {
            if (cg < 0.f) {  // the camera on the other side: the BSDF seen from there
              bsdf.n = Vec3<float>(0.f, 0.f, 0.f) - bsdf.n;
              bsdf.side = -bsdf.side;
            }
            const float ngo = std::abs(dot(ng, wo));
            if (!(ngo > 0.f)) continue;
            geo = static_cast<double>(std::abs(dot(ns, wo))) / ngo * std::abs(cg);
          }
          bsdf.wo = w;
          const BsdfEval<float> e = bsdf.eval(wo);
          const double k0 = geo * importance;
          float cc[3] = {static_cast<float>(tb.path.throughput_r[k] * e.f.r * k0),
                         static_cast<float>(tb.path.throughput_g[k] * e.f.g * k0),
                         static_cast<float>(tb.path.throughput_b[k] * e.f.b * k0)};
          if (!(cc[0] > 0.f || cc[1] > 0.f || cc[2] > 0.f)) continue;
          if (!(std::isfinite(cc[0]) && std::isfinite(cc[1]) && std::isfinite(cc[2]))) {
            ++rejected;
            continue;
          }
          const float side = in_medium ? 0.f : (cg < 0.f ? -1.f : 1.f);
          const Vec3<float> org = x + ng * (P.eps[k] * side);
          Ray16& sh = tb.shadow[k / packet_width];
          const int ln = k % packet_width;
          sh.org_x[ln] = org.x;
          sh.org_y[ln] = org.y;
          sh.org_z[ln] = org.z;
          sh.dir_x[ln] = w.x;
          sh.dir_y[ln] = w.y;
          sh.dir_z[ln] = w.z;
          sh.tfar[ln] = static_cast<float>(dist) * (1.f - 1.f / 4096.f);
          tb.tech.valid[k] = -1;
          tb.tech.cr[k] = cc[0];
          tb.tech.cg[k] = cc[1];
          tb.tech.cb[k] = cc[2];
          rx[k] = static_cast<float>(rxk);
          ry[k] = static_cast<float>(ryk);
          any = true;
        }
        if (any) {
          trace_shadow_rays(
              G, tb, n, [&](const int32_t* valid, Ray16& sh, int32_t* crossed) { accel.occluded16(valid, sh, false, crossed); },
              trace);
          for (int k = 0; k < n; ++k) {
            if (!tb.tech.valid[k] || tb.shadow[k / packet_width].tfar[k % packet_width] == -INFINITY) continue;
            const float cc[3] = {tb.tech.cr[k], tb.tech.cg[k], tb.tech.cb[k]};
            cam_->splat(rx[k], ry[k], cc, out);
          }
        }
      }
      if (j >= est.max_depth) break;
      // the path goes on along a BSDF sample (the vertex before as the viewer), with the
      // adjoint's weight; at vertex 1 only a delta lobe's
      pairs(tb.points.pixel, s, vertex_pair(j, 0), np, tb.tech.u0, tb.tech.u1);
      pairs(tb.points.pixel, s, vertex_pair(j, 1), np, tb.tech.u2, tb.tech.u3);
      const bool roulette = j > est.rr_depth;
      for (int k = 0; k < np; ++k) {
        tb.tech.valid[k] = 0;
        if (k >= n) continue;
        const Vec3<float> x{P.px[k], P.py[k], P.pz[k]};
        const Vec3<float> ng{P.nx[k], P.ny[k], P.nz[k]};
        const Vec3<float> ns = G.shading_normals ? Vec3<float>(P.snx[k], P.sny[k], P.snz[k]) : ng;
        const Vec3<float> wo{P.wox[k], P.woy[k], P.woz[k]};
        const SurfaceBsdf<float, bsdf_all> bsdf = load_surface_bsdf<float, bsdf_all>(G, P, k, ns);
        const BsdfSample<float> bs = bsdf.sample(tb.tech.u2[k], tb.tech.u0[k], tb.tech.u1[k]);
        if (!bs.valid) continue;
        bool join_all = false;  // (a distant source's path through a delta lobe: joined as a positional one's)
        if (j == 1) {  // (a delta lobe from an area or positional source; a flagged material's other lobes)
          const bool glossy = G.mat_lt_glossy != nullptr && G.mat_lt_glossy[P.mat[k]] != 0;
          const bool positional = tb.path.first_rough[k] < 0.f;
          const bool glass = !sun_glass_.empty() && sun_glass_[static_cast<size_t>(P.mat[k])] != 0;
          if (tb.path.first_rough[k] > 0.f ? (bs.delta ? !glass : !glossy)
                                           : !(bs.delta || (area_glossy_ && !positional && glossy)))
            continue;
          join_all = tb.path.first_rough[k] > 0.f && bs.delta;
        }
        const bool in_medium = bsdf.kind == static_cast<int32_t>(MaterialKind::phase);
        const float cgi = dot(ng, bs.wi);
        const float adj = in_medium ? 1.f : adjoint_factor(G, P.mat[k], bsdf.kind, P.side[k], ng, ns, wo, bs.wi);
        float br = tb.path.throughput_r[k] * bs.weight.r * adj;
        float bg = tb.path.throughput_g[k] * bs.weight.g * adj;
        float bb = tb.path.throughput_b[k] * bs.weight.b * adj;
        const float m = std::max(std::max(br, bg), bb);
        if (!std::isfinite(m)) {
          ++rejected;
          continue;
        }
        if (!(m > 0.f)) continue;
        if (roulette) {
          const float rr = m * tb.path.eta_scale[k] * inv_t;
          if (rr < 1.f) {
            if (tb.tech.u3[k] >= rr) continue;  // q = 1 - rr
            br /= rr;
            bg /= rr;
            bb /= rr;
          }
        }
        const float side = in_medium ? 0.f : (cgi < 0.f ? -1.f : 1.f);
        set_light_ray(tb, k, x + ng * (P.eps[k] * side), bs.wi);
        if (join_all) tb.path.first_rough[k] = -1.f;
        tb.path.throughput_r[k] = br;
        tb.path.throughput_g[k] = bg;
        tb.path.throughput_b[k] = bb;
        if (media) tb.media.med[k] = cgi >= 0.f ? P.medf[k] : P.medb[k];
      }
    }
  }
}

}  // namespace tuile
