// Helpers for tests that render scenes built in code and compare with exact answers.
#pragma once
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "accel/embree.h"
#include "light/polygon_irradiance.h"
#include "render/render.h"
#include "scene/scene.h"
#include "scene/sky_map.h"
#include "test_scale.h"
#include "wave/generate.h"

namespace tuile::test {

inline void add_quad(Mesh& m, vec3f p0, vec3f e1, vec3f e2) {
  const uint32_t base = static_cast<uint32_t>(m.positions.size() / 3);
  for (vec3f p : {p0, p0 + e1, p0 + e1 + e2, p0 + e2}) m.positions.insert(m.positions.end(), {p.x, p.y, p.z});
  for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) m.indices.push_back(base + i);
}
// A straight curve from (-a, y, z) to (a, y, z) of radius r (4 control points, 1 segment;
// a ribbon's normals +z).
inline Curves straight_curve(CurveType type, float a, float y, float r, float z = 0) {
  Curves c;
  c.name = "straight";
  c.type = type;
  c.points.assign(16, 0.f);
  for (int k = 0; k < 4; ++k) {
    c.points[size_t(4 * k)] = -a + 2 * a * static_cast<float>(k) / 3.f;
    c.points[size_t(4 * k + 1)] = y;
    c.points[size_t(4 * k + 2)] = z;
    c.points[size_t(4 * k + 3)] = r;
  }
  if (type == CurveType::ribbon)
    for (int k = 0; k < 4; ++k) c.normals.insert(c.normals.end(), {0.f, 0.f, 1.f});
  return c;
}

// A mesh of one parallelogram p0 + u e1 + v e2 (material mat, emitting L where L > 0) added to s.
inline void add_named_quad(Scene& s, const char* name, int mat, vec3f p0, vec3f e1, vec3f e2, float L = 0) {
  Mesh m;
  m.name = name;
  m.material = mat;
  if (L > 0) m.emission = {L, L, L};
  add_quad(m, p0, e1, e2);
  s.meshes.push_back(m);
}

// Delta sources as the pbrt loader stores them: a point source at p of intensity I; a spot
// at p along dir of intensity I whose falloff starts where the cosine from its axis is
// cos_start and ends at the cone's edge, cos_end; a distant source whose light comes from
// `towards` (the direction to it) with radiance L.
inline Light point_light(vec3f p, Rgb I) {
  Light l;
  l.type = LightKind::point;
  l.p0 = p;
  l.radiance = I;
  return l;
}
inline Light spot_light(vec3f p, vec3f dir, float cos_start, float cos_end, Rgb I) {
  Light l;
  l.type = LightKind::spot;
  l.p0 = p;
  l.e1 = normalize(dir);
  l.e2 = {cos_start, cos_end, 0};
  l.radiance = I;
  return l;
}
inline Light distant_light(vec3f towards, Rgb L) {
  Light l;
  l.type = LightKind::distant;
  l.e1 = normalize(towards);
  l.radiance = L;
  return l;
}

// Smooth glass (a delta lobe), pbrt-v4's dielectric of index eta.
// A sky with an environment map made of img (light/kinds/infinite.h) added to s: radiance
// scale L, its frame turned so that its x axis is along x (its y axis across x and world z).
inline void add_map_sky(Scene& s, const RgbImage& img, Rgb L, vec3f x) {
  SkyMap map;
  std::string why;
  if (!make_sky_map("test sky", img, map, why)) throw std::runtime_error(why);
  s.sky_maps.push_back(std::move(map));
  Light env;
  env.type = LightKind::infinite;
  env.radiance = L;
  env.sky_map = static_cast<int>(s.sky_maps.size()) - 1;
  env.e1 = normalize(x);
  env.e2 = normalize(cross(vec3f{0, 0, 1}, env.e1));
  env.p0 = cross(env.e1, env.e2);
  s.lights.push_back(env);
}

inline Material glass_material(float eta = 1.5f) {
  Material g;
  g.kind = MaterialKind::dielectric;
  g.eta = eta;
  return g;
}

inline void add_triangle(Mesh& m, vec3f a, vec3f b, vec3f c) {
  const uint32_t base = static_cast<uint32_t>(m.positions.size() / 3);
  for (vec3f p : {a, b, c}) m.positions.insert(m.positions.end(), {p.x, p.y, p.z});
  for (uint32_t i : {0u, 1u, 2u}) m.indices.push_back(base + i);
}

// A polygonal source for the exact answer: vertices in order, radiance (grey).
struct Polygon {
  std::vector<vec3f> v;
  float L = 1;
};

// A diffuse floor (y = 0, albedo rho) seen from straight above, lit by polygons facing
// down that nothing occludes.
struct PlaneScene {
  Scene scene;
  std::vector<Polygon> sources;
  float rho = 0.5f;
};

inline PlaneScene plane_scene(vec3f eye, float fov, int res, float rho = 0.5f) {
  PlaneScene p;
  p.rho = rho;
  Scene& s = p.scene;
  s.source = "test:plane";
  s.materials.push_back(diffuse_material(Rgb{rho, rho, rho}, -1));
  Mesh floor;
  floor.name = "floor";
  floor.material = 0;
  add_quad(floor, {-100, 0, -100}, {0, 0, 200}, {200, 0, 0});
  s.meshes.push_back(floor);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = fov;
  camera_look_at(s.camera, eye, {eye.x, 0, eye.z}, {0, 0, 1});
  return p;
}

// A downward-facing parallelogram source p0 + u e1 + v e2 (cross(e1, e2) must point down).
inline void add_source_quad(PlaneScene& p, vec3f p0, vec3f e1, vec3f e2, float L) {
  Mesh m;
  m.name = "source";
  m.material = 0;
  m.emission = {L, L, L};
  add_quad(m, p0, e1, e2);
  p.scene.meshes.push_back(m);
  p.sources.push_back({{p0, p0 + e1, p0 + e1 + e2, p0 + e2}, L});
}
inline void add_source_triangle(PlaneScene& p, vec3f a, vec3f b, vec3f c, float L) {
  Mesh m;
  m.name = "source";
  m.material = 0;
  m.emission = {L, L, L};
  add_triangle(m, a, b, c);
  p.scene.meshes.push_back(m);
  p.sources.push_back({{a, b, c}, L});
}

// Exact outgoing radiance of the floor at (x, 0, z).
inline double exact_floor_radiance(const PlaneScene& p, double x, double z) {
  const double px[3] = {x, 0, z}, n[3] = {0, 1, 0};
  double e = 0;
  for (const Polygon& poly : p.sources) {
    std::vector<double> v;
    for (vec3f q : poly.v) v.insert(v.end(), {q.x, q.y, q.z});
    e += poly.L * polygon_irradiance_clipped(px, n, v.data(), static_cast<int>(poly.v.size()));
  }
  return p.rho / 3.14159265358979 * e;
}

// Exact pixel values of a scene whose camera sees the floor y = 0 only, under a radiance
// known in closed form: the mean over each pixel's raster square of f(x, z, t), the floor's
// radiance at (x, 0, z) seen from the camera t away, by q x q midpoint quadrature.
template <class F>
std::vector<double> floor_pixel_means(const Scene& s, int q, F&& f) {
  const SceneViews v = build_views(s, LightPick::power);
  std::vector<double> img(static_cast<size_t>(s.camera.width) * s.camera.height, 0.0);
  for (int py = 0; py < s.camera.height; ++py)
    for (int px = 0; px < s.camera.width; ++px) {
      double sum = 0;
      for (int i = 0; i < q; ++i)
        for (int j = 0; j < q; ++j) {
          vec3f o, d;
          camera_ray(v.camera, px + (i + 0.5f) / q, py + (j + 0.5f) / q, o, d);
          const double t = -static_cast<double>(o.y) / d.y;
          sum += f(o.x + t * d.x, o.z + t * d.z, t * std::sqrt(static_cast<double>(dot(d, d))));
        }
      img[static_cast<size_t>(py) * s.camera.width + px] = sum / (q * q);
    }
  return img;
}

// Exact pixel values (the box-filtered radiance: the mean over the pixel's raster square),
// by q x q Gauss-Legendre quadrature in raster space of the smooth floor radiance.
std::vector<double> exact_image(const PlaneScene& p, int q = 4);

// Options for tests that weigh images in standard errors: the independent sampler (whose
// per-pixel variances estimate the error), two threads.
inline RenderOptions independent_options(Strategy strategy, LightPick pick, MisMode mode, int depth, uint32_t spp,
                                         uint32_t seed) {
  RenderOptions o;
  o.est.strategy = strategy;
  o.est.pick = pick;
  o.est.mode = mode;
  o.est.max_depth = depth;
  o.est.sampler = SamplerKind::independent;
  o.est.spp = spp;
  o.est.seed = seed;
  o.threads = 2;
  return o;
}

struct RenderResult {
  Film film;
  RenderStats stats;
  std::vector<float> mean;
};
inline RenderResult render_scene(const Scene& s, const RenderOptions& o) {
  Accel accel(s);
  Renderer r(s, accel, o);
  RenderResult out;
  out.film.reset(s.camera.width, s.camera.height);
  out.stats = r.render(out.film, 0, o.est.spp);
  out.mean = out.film.mean();
  return out;
}

// The z-score of an image's mean (first channel) against the exact image's, from the
// per-pixel variance of the mean.
inline double z_of_mean(const RenderResult& r, const std::vector<double>& exact) {
  const std::vector<float> var = r.film.variance_of_mean();
  double diff = 0, v = 0;
  const size_t n = exact.size();
  for (size_t i = 0; i < n; ++i) {
    diff += r.mean[3 * i] - exact[i];
    v += var[3 * i];
  }
  return (diff / static_cast<double>(n)) / (std::sqrt(v) / static_cast<double>(n));
}

// The image of spp samples per pixel (seed and the rest in o).
inline std::vector<float> render_mean(const Scene& s, const Accel& accel, const RenderOptions& o, uint32_t spp) {
  Film f;
  f.reset(s.camera.width, s.camera.height);
  Renderer(s, accel, o).render(f, 0, spp);
  return f.mean();
}

// Per seed, the mean of each quarter of the image and channel (12 numbers).
inline std::vector<double> quarter_means(const Scene& s, const std::vector<float>& m) {
  const int w = s.camera.width, h = s.camera.height;
  std::vector<double> q(12, 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        q[static_cast<size_t>(3 * ((y * 2 / h) * 2 + x * 2 / w) + c)] +=
            m[3 * (static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x)) + static_cast<size_t>(c)];
  for (double& v : q) v /= w * h / 4.0;
  return q;
}

// Two estimators' images (with, without: the options, whose seeds this sets) over `seeds` independent seeds each: for every quarter and
// channel, the difference of their means over its standard error (from the spread over the
// seeds) is below 5.5 (12 tests of a t statistic with about 2 (seeds - 1) degrees of
// freedom: with 24 seeds, a false alarm once in some 50,000 runs).
inline void expect_same_mean_over_seeds(const Scene& s, RenderOptions with, RenderOptions without, int seeds, const char* what) {
  Accel accel(s);
  std::vector<std::vector<double>> a, b;
  for (int k = 0; k < seeds; ++k) {
    with.est.seed = static_cast<uint32_t>(2 * k + 1);
    without.est.seed = static_cast<uint32_t>(2 * k + 2);
    for (auto [o, out] : {std::pair{&with, &a}, std::pair{&without, &b}})
      out->push_back(quarter_means(s, render_mean(s, accel, *o, o->est.spp)));
  }
  const double n = seeds;
  for (size_t i = 0; i < 12; ++i) {
    double ma = 0, mb = 0, va = 0, vb = 0;
    for (int k = 0; k < seeds; ++k) {
      ma += a[static_cast<size_t>(k)][i] / n;
      mb += b[static_cast<size_t>(k)][i] / n;
    }
    for (int k = 0; k < seeds; ++k) {
      va += (a[static_cast<size_t>(k)][i] - ma) * (a[static_cast<size_t>(k)][i] - ma) / (n - 1);
      vb += (b[static_cast<size_t>(k)][i] - mb) * (b[static_cast<size_t>(k)][i] - mb) / (n - 1);
    }
    ASSERT_GT(mb, 0);
    const double z = (ma - mb) / std::sqrt(va / n + vb / n);
    std::printf("[ %s ] quarter %zu channel %zu: %.5f with, %.5f without (z %.2f; std. errors %.2g, %.2g)\n", what,
                i / 3, i % 3, ma, mb, z, std::sqrt(va / n), std::sqrt(vb / n));
    EXPECT_LT(std::abs(z), 5.5) << what << ": quarter " << i / 3 << " channel " << i % 3;
  }
}

}  // namespace tuile::test
