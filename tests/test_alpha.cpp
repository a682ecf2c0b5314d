// Alpha cutouts (wave/alpha.h): a checkerboard of alpha seen against a light (the exact
// coverage per pixel), shadows through cut-out occluders (exact), cut-out emitters under
// light sampling, BSDF sampling and MIS (exact, and against each other), and Embree's
// packet queries against single rays; and spheres, tuile's own test as Embree user
// geometry, against their exact roots.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render_util.h"
#include "test_scale.h"
#include "wave/alpha.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// Adds a quad p0 + s e1 + t e2 with uv (s, t) to m.
void add_uv_quad(Mesh& m, vec3f p0, vec3f e1, vec3f e2) {
  add_quad(m, p0, e1, e2);
  m.uvs.insert(m.uvs.end(), {0, 0, 1, 0, 1, 1, 0, 1});
}

int add_texture(Scene& s, int w, int h, std::vector<float> v) {
  FloatTexture t;
  t.name = "alpha";
  t.width = w;
  t.height = h;
  t.value = std::move(v);
  s.float_textures.push_back(std::move(t));
  return static_cast<int>(s.float_textures.size()) - 1;
}

// An n x n checkerboard of alpha 0 and 1 (n odd: the pattern is the same under flips of
// either axis and under transposition, so the exact image does not depend on how the
// camera's axes meet the texture's)
std::vector<float> checker(int n) {
  std::vector<float> v;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) v.push_back(static_cast<float>((x + y) % 2));
  return v;
}

// The bilinear, wrapping interpolation of texels tex (n x n) at (u, v), written
// independently of the renderer's: texel centres at (i + 1/2) / n.
double bilinear_ref(const std::vector<float>& tex, int n, double u, double v) {
  const double x = u * n - 0.5, y = v * n - 0.5;
  const double x0 = std::floor(x), y0 = std::floor(y), fx = x - x0, fy = y - y0;
  auto at = [&](double xi, double yi) {
    const int i = (static_cast<int>(xi) % n + n) % n, j = (static_cast<int>(yi) % n + n) % n;
    return double(tex[size_t(j * n + i)]);
  };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

RenderOptions options(Strategy st, uint32_t spp, uint32_t seed = 7) {
  return independent_options(st, LightPick::power, MisMode::multi, 1, spp, seed);  // (the estimator's defaults)
}

double image_mean(const RenderResult& r) {
  double m = 0;
  const size_t n = r.mean.size() / 3;
  for (size_t i = 0; i < n; ++i) m += r.mean[3 * i];
  return m / static_cast<double>(n);
}
double image_mean_sigma(const RenderResult& r) {
  const std::vector<float> var = r.film.variance_of_mean();
  double v = 0;
  const size_t n = var.size() / 3;
  for (size_t i = 0; i < n; ++i) v += var[3 * i];
  return std::sqrt(v) / static_cast<double>(n);
}

}  // namespace

// A black quad cut out by a 5 x 5 checkerboard of alpha, filling the view of a camera above
// it, in front of an emitter of radiance 1. With 20 pixels across, each pixel sees one
// bilinear piece of the alpha, whose mean over the pixel is its value at the pixel's
// centre: the exact pixel is 1 - alpha there (fractional alpha between the texels: a ray
// passes with probability 1 - alpha, Bernoulli noise of known variance).
TEST(Alpha, CheckerboardCoverageIsExact) {
  const int res = 20, n = 5;
  Scene s;
  s.source = "test:alpha-checker";
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}, -1));
  Mesh back;
  back.name = "backdrop";
  back.material = 0;
  back.emission = {1, 1, 1};
  add_quad(back, {-100, 0, -100}, {0, 0, 200}, {200, 0, 0});  // faces +y
  s.meshes.push_back(back);
  Mesh cut;
  cut.name = "cutout";
  cut.material = 0;
  add_uv_quad(cut, {-1, 1, -1}, {2, 0, 0}, {0, 0, 2});
  const std::vector<float> tex = checker(n);
  cut.alpha = {1, add_texture(s, n, n, tex)};
  s.meshes.push_back(cut);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 90;  // at distance 1 the view is 2 wide: the quad fills it
  camera_look_at(s.camera, {0, 2, 0}, {0, 0, 0}, {0, 0, 1});
  finalize_scene(s);
  const uint32_t spp = scaled(512u, 64u);
  const RenderResult r = render_scene(s, options(Strategy::mis, spp));
  int worst = 0;
  double worst_z = 0, sum_diff = 0, sum_var = 0, partial = 0;
  for (int j = 0; j < res; ++j)
    for (int i = 0; i < res; ++i) {
      const double a = bilinear_ref(tex, n, (i + 0.5) / res, (j + 0.5) / res);
      const double expect = 1 - a, got = r.mean[3 * size_t(j * res + i)];
      const double sigma = std::sqrt(a * (1 - a) / spp);
      if (a > 0 && a < 1) ++partial;
      sum_diff += got - expect;
      sum_var += sigma * sigma;
      const double z = std::abs(got - expect) / std::max(sigma, 1e-6);
      if (z > worst_z) worst_z = z, worst = j * res + i;
      // exact where alpha is 0 or 1 (to rounding), 5 sigma elsewhere
      EXPECT_LE(std::abs(got - expect), 5 * sigma + 1e-4) << "pixel " << i << "," << j << " alpha " << a;
    }
  EXPECT_GT(partial, res * res / 2);  // most pixels see a fractional alpha
  const double z_mean = sum_diff / std::sqrt(sum_var);
  EXPECT_LT(std::abs(z_mean), 4.0) << "worst pixel " << worst << " z " << worst_z;
}

namespace {

// A floor lit by a square source 1.5 above it, through two black occluders between them
// (a constant alpha 0.5, and a texture of alpha 0.4 everywhere): they let through 0.5 x 0.6
// of the light, each deciding independently. The camera sits below both.
PlaneScene shadow_scene() {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  add_source_quad(p, {-0.5f, 1.5f, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  Scene& s = p.scene;
  s.materials.push_back(diffuse_material(Rgb{0, 0, 0}, -1));
  const int black = static_cast<int>(s.materials.size()) - 1;
  Mesh o1;
  o1.name = "occluder-constant";
  o1.material = black;
  add_quad(o1, {-50, 1, -50}, {100, 0, 0}, {0, 0, 100});
  o1.alpha = {0.5f, -1};
  s.meshes.push_back(o1);
  Mesh o2;
  o2.name = "occluder-texture";
  o2.material = black;
  add_uv_quad(o2, {-50, 1.2f, -50}, {100, 0, 0}, {0, 0, 100});
  o2.alpha = {1, add_texture(s, 3, 2, std::vector<float>(6, 0.4f))};
  s.meshes.push_back(o2);
  return p;
}

}  // namespace

TEST(Alpha, ShadowsThroughCutoutsAreExact) {
  PlaneScene p = shadow_scene();
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 4);
  std::vector<double> through(exact.size());
  for (size_t i = 0; i < exact.size(); ++i) through[i] = 0.3 * exact[i];
  for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis, Strategy::ris}) {
    const uint32_t spp = scaled(st == Strategy::bsdf ? 1024u : 256u, 64u);
    const RenderResult r = render_scene(p.scene, options(st, spp));
    const double z = z_of_mean(r, through);
    EXPECT_LT(std::abs(z), 4.0) << static_cast<int>(st) << ": mean " << image_mean(r);
  }
}

namespace {

// A floor under a square source cut out by alpha texels (their uv on the source), and the
// source's own image: the exact floor for a uniform alpha c is c times the uncut one.
PlaneScene cut_source(int w, int h, std::vector<float> texels) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  Mesh& src = p.scene.meshes.back();
  src.uvs = {0, 0, 1, 0, 1, 1, 0, 1};
  src.alpha = {1, add_texture(p.scene, w, h, std::move(texels))};
  return p;
}

}  // namespace

// Light sampling multiplies a point's radiance by its alpha; BSDF sampling sees the hits
// the filters keep: both estimate the same image, and for a uniform alpha 0.3 it is 0.3 of
// the uncut source's exact image.
TEST(Alpha, CutOutEmittersStayUnbiased) {
  {
    PlaneScene p = cut_source(2, 2, std::vector<float>(4, 0.3f));
    finalize_scene(p.scene);
    ASSERT_EQ(p.scene.lights.size(), 2u);  // a cut-out source keeps its triangles
    const std::vector<double> exact = exact_image(p, 4);
    std::vector<double> cut(exact.size());
    for (size_t i = 0; i < exact.size(); ++i) cut[i] = 0.3 * exact[i];
    for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis, Strategy::ris}) {
      const uint32_t spp = scaled(st == Strategy::bsdf ? 1024u : 128u, 32u);
      const RenderResult r = render_scene(p.scene, options(st, spp));
      EXPECT_LT(std::abs(z_of_mean(r, cut)), 4.0) << "uniform alpha, strategy " << static_cast<int>(st);
    }
  }
  // a 4 x 4 checkerboard of alpha on the source: light sampling and BSDF sampling agree
  std::vector<float> tex;
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) tex.push_back((x + y) % 2 ? 1.f : 0.f);
  PlaneScene p = cut_source(4, 4, tex);
  finalize_scene(p.scene);
  const RenderResult light = render_scene(p.scene, options(Strategy::light, scaled(256u, 32u), 11));
  const RenderResult bsdf = render_scene(p.scene, options(Strategy::bsdf, scaled(2048u, 128u), 12));
  const RenderResult mis = render_scene(p.scene, options(Strategy::mis, scaled(256u, 32u), 13));
  const double ml = image_mean(light), mb = image_mean(bsdf), mm = image_mean(mis);
  const double sl = image_mean_sigma(light), sb = image_mean_sigma(bsdf), sm = image_mean_sigma(mis);
  EXPECT_LT(std::abs(ml - mb) / std::hypot(sl, sb), 4.0) << ml << " " << mb;
  EXPECT_LT(std::abs(mm - mb) / std::hypot(sm, sb), 4.0) << mm << " " << mb;
  // and the cut source gives about half the uncut one's light (the checkerboard's mean)
  const std::vector<double> exact = exact_image(p, 4);
  double e = 0;
  for (double v : exact) e += v;
  e /= static_cast<double>(exact.size());
  EXPECT_NEAR(ml / e, 0.5, 0.1);
}

// Every query sees the same cutouts: nearest hits in packets of 16 against single rays,
// and occlusion in packets against the nearest hit (a ray is occluded exactly when it hits
// something before its end).
TEST(Alpha, PacketsEqualSingleRays) {
  PlaneScene p = shadow_scene();
  Scene& s = p.scene;
  Mesh cut;
  cut.name = "checker";
  cut.material = 0;
  add_uv_quad(cut, {-0.4f, 0.8f, -0.4f}, {0.8f, 0, 0}, {0, 0, 0.8f});
  cut.alpha = {1, add_texture(s, 5, 5, checker(5))};
  s.meshes.push_back(cut);
  finalize_scene(s);
  Accel accel(s);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(-1, 1);
  int hits[8] = {};
  for (int batch = 0; batch < 64; ++batch) {
    RayHit16 a{}, b{};
    Ray16 occ{};
    alignas(64) int32_t valid[16];  // (Embree reads the mask with aligned 512-bit loads on AVX-512 machines)
    for (int i = 0; i < 16; ++i) {
      valid[i] = -1;
      const float ox = 0.6f * U(rng), oz = 0.6f * U(rng);
      const vec3f d = normalize(vec3f{0.3f * U(rng), 1, 0.3f * U(rng)});
      for (RayHit16* r : {&a, &b}) {
        r->ray.org_x[i] = ox;
        r->ray.org_y[i] = 0.01f;
        r->ray.org_z[i] = oz;
        r->ray.dir_x[i] = d.x;
        r->ray.dir_y[i] = d.y;
        r->ray.dir_z[i] = d.z;
        r->ray.tnear[i] = 0;
        r->ray.tfar[i] = 10;
        r->ray.mask[i] = ~0u;
        r->geomID[i] = ~0u;
      }
      occ.org_x[i] = ox;
      occ.org_y[i] = 0.01f;
      occ.org_z[i] = oz;
      occ.dir_x[i] = d.x;
      occ.dir_y[i] = d.y;
      occ.dir_z[i] = d.z;
      occ.tnear[i] = 0;
      occ.tfar[i] = 1.1f;  // below the source: only the cutouts can stop it
      occ.mask[i] = ~0u;
    }
    accel.intersect16(valid, a, batch % 2 == 0);
    for (int i = 0; i < 16; ++i) accel.intersect1(b, i);
    accel.occluded16(valid, occ, false);
    for (int i = 0; i < 16; ++i) {
      ASSERT_EQ(a.geomID[i], b.geomID[i]) << batch << " lane " << i;
      if (a.geomID[i] != ~0u) {
        ASSERT_EQ(a.primID[i], b.primID[i]) << batch << " lane " << i << " geom " << a.geomID[i] << " t " << a.ray.tfar[i] << " "
                                           << b.ray.tfar[i] << " uv " << a.u[i] << " " << a.v[i] << " / " << b.u[i] << " " << b.v[i];
      }
      EXPECT_EQ(a.ray.tfar[i], b.ray.tfar[i]);
      ++hits[a.geomID[i] < 8 ? a.geomID[i] : 7];
      const bool blocked = a.geomID[i] != ~0u && a.ray.tfar[i] < 1.1f;
      EXPECT_EQ(occ.tfar[i] < 0, blocked) << batch << " lane " << i;  // Embree marks occlusion by tfar = -inf
    }
  }
  // every occluder and the checker stopped some rays and let others through to the source
  EXPECT_GT(hits[1], 0);  // the source
  EXPECT_GT(hits[2], 0);
  EXPECT_GT(hits[3], 0);
  EXPECT_GT(hits[4], 0);
}

// pbrt-v4's rule for fractional alpha: kept with probability alpha, independently per
// primitive, deterministic per ray.
TEST(Alpha, FractionalAlphaKeepsItsShare) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(-1, 1);
  const int n = 200000;
  int kept[3] = {}, both = 0;
  for (int i = 0; i < n; ++i) {
    const float ray[6] = {U(rng), U(rng), U(rng), U(rng), U(rng), U(rng)};
    const bool k1 = alpha_keeps(0.3f, ray, 1, 7), k2 = alpha_keeps(0.3f, ray, 2, 7);
    kept[0] += k1;
    kept[1] += k2;
    kept[2] += alpha_keeps(0.9f, ray, 1, 8);
    both += k1 && k2;
    EXPECT_EQ(k1, alpha_keeps(0.3f, ray, 1, 7));
  }
  // binomial: 5 sigma
  auto near = [&](int k, double p) { return std::abs(k - n * p) < 5 * std::sqrt(n * p * (1 - p)); };
  EXPECT_TRUE(near(kept[0], 0.3)) << kept[0];
  EXPECT_TRUE(near(kept[1], 0.3)) << kept[1];
  EXPECT_TRUE(near(kept[2], 0.9)) << kept[2];
  EXPECT_TRUE(near(both, 0.09)) << both;  // independent across primitives
  const float any[6] = {0, 0, 0, 0, 0, 1};
  EXPECT_FALSE(alpha_keeps(0.f, any, 0, 0));
  EXPECT_FALSE(alpha_keeps(-1.f, any, 0, 0));
  EXPECT_FALSE(alpha_keeps(std::nanf(""), any, 0, 0));
  EXPECT_TRUE(alpha_keeps(1.f, any, 0, 0));
}

// Spheres, Embree user geometry with tuile's own ray test (src/accel/embree.cpp): packets
// of random rays (from outside and from inside, of random lengths) against the roots of
// each ray and sphere in long double: the nearest hit's sphere and distance (to 1e-6 of
// it), in packets, in single rays and as occlusion, alike. A sphere with alpha 0.5 lets
// about half of the rays that meet only it through (0.5 +- 0.05: over the 1000 and more
// such rays asked for, 3 standard deviations are at most 0.047). Rays leaving a sphere's surface from a point offset by
// 2^-21 (|x| + r) (32 times less than the hit stage's offset) never hit it again.
namespace {
long double sphere_root(const Sphere& s, const double o[3], const double d[3], long double tfar) {
  const float cen[3] = {s.center.x, s.center.y, s.center.z};
  long double f[3], a = 0, b = 0, c = 0;
  for (int i = 0; i < 3; ++i) {
    f[i] = static_cast<long double>(o[i]) - cen[i];
    a += static_cast<long double>(d[i]) * d[i];
    b += f[i] * d[i];
    c += f[i] * f[i];
  }
  c -= static_cast<long double>(s.radius) * s.radius;
  const long double disc = b * b - a * c;
  if (disc < 0) return -1;
  const long double t0 = (-b - std::sqrt(disc)) / a, t1 = (-b + std::sqrt(disc)) / a;
  if (t0 > 0 && t0 <= tfar) return t0;
  if (t1 > 0 && t1 <= tfar) return t1;
  return -1;
}
}  // namespace

TEST(Spheres, HitsAreTheNearestRootsInPacketsSingleRaysAndOcclusion) {
  Scene s;
  s.source = "test:spheres";
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}));
  const auto sphere = [&](vec3f c, float r, float alpha) {
    Sphere sp;
    sp.center = c;
    sp.radius = r;
    sp.material = 0;
    sp.alpha = alpha;
    s.spheres.push_back(sp);
  };
  sphere({0.3f, 0.2f, -0.1f}, 0.7f, 1);
  sphere({1.6f, 0.1f, 0.2f}, 0.05f, 1);
  sphere({-1.8f, 0.f, 0.3f}, 0.5f, 0.5f);
  finalize_scene(s);
  Accel accel(s);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(-1, 1);
  int inside = 0, small = 0, through = 0, alpha_only = 0;
  for (int batch = 0; batch < 800; ++batch) {
    RayHit16 a{}, b{};
    Ray16 occ{};
    alignas(64) int32_t valid[16];
    for (int i = 0; i < 16; ++i) {
      valid[i] = -1;
      vec3f o{2.5f * U(rng), 1.5f * U(rng), 1.5f * U(rng)};
      vec3f d = normalize(vec3f{U(rng), U(rng), U(rng)});
      if (batch % 4 == 1) d = normalize(vec3f{1.6f, 0.1f, 0.2f} + 0.04f * vec3f{U(rng), U(rng), U(rng)} - o);  // at the small one
      if (batch % 4 == 2) d = normalize(vec3f{-1.8f, 0.f, 0.3f} + 0.4f * vec3f{U(rng), U(rng), U(rng)} - o);  // at the cut-out one
      const float tfar = batch % 3 == 0 ? 1e30f : 0.5f + 4.f * (U(rng) + 1);
      for (RayHit16* r : {&a, &b}) {
        r->ray.org_x[i] = o.x, r->ray.org_y[i] = o.y, r->ray.org_z[i] = o.z;
        r->ray.dir_x[i] = d.x, r->ray.dir_y[i] = d.y, r->ray.dir_z[i] = d.z;
        r->ray.tnear[i] = 0;
        r->ray.tfar[i] = tfar;
        r->ray.mask[i] = ~0u;
        r->geomID[i] = ~0u;
      }
      occ.org_x[i] = o.x, occ.org_y[i] = o.y, occ.org_z[i] = o.z;
      occ.dir_x[i] = d.x, occ.dir_y[i] = d.y, occ.dir_z[i] = d.z;
      occ.tnear[i] = 0;
      occ.tfar[i] = tfar;
      occ.mask[i] = ~0u;
    }
    std::vector<float> tfar(16);
    for (int i = 0; i < 16; ++i) tfar[static_cast<size_t>(i)] = a.ray.tfar[i];
    accel.intersect16(valid, a, false);
    for (int i = 0; i < 16; ++i) accel.intersect1(b, i);
    accel.occluded16(valid, occ, false);
    for (int i = 0; i < 16; ++i) {
      ASSERT_EQ(a.geomID[i], b.geomID[i]) << batch << " lane " << i;
      ASSERT_EQ(a.ray.tfar[i], b.ray.tfar[i]) << batch << " lane " << i;
      EXPECT_EQ(occ.tfar[i] == -INFINITY, a.geomID[i] != ~0u) << batch << " lane " << i;
      const double o[3] = {a.ray.org_x[i], a.ray.org_y[i], a.ray.org_z[i]};
      const double d[3] = {a.ray.dir_x[i], a.ray.dir_y[i], a.ray.dir_z[i]};
      long double best = -1;
      uint32_t want = ~0u;
      for (uint32_t k = 0; k < 2; ++k) {
        const long double t = sphere_root(s.spheres[k], o, d, tfar[static_cast<size_t>(i)]);
        if (t > 0 && (best < 0 || t < best)) best = t, want = k;
      }
      const long double t_alpha = sphere_root(s.spheres[2], o, d, tfar[static_cast<size_t>(i)]);
      if (t_alpha > 0 && (best < 0 || t_alpha < best)) {  // the cut-out sphere first: either
        if (want == ~0u) {
          ++alpha_only;
          through += a.geomID[i] == ~0u;
        }
        if (a.geomID[i] == 2u) continue;
      }
      ASSERT_EQ(a.geomID[i], want) << batch << " lane " << i;
      if (want == ~0u) continue;
      EXPECT_NEAR(a.ray.tfar[i], static_cast<double>(best), 1e-6 * static_cast<double>(best)) << batch << " lane " << i;
      inside += want == 0 && sphere_root(s.spheres[0], o, d, 1e30L) > 0 &&
                std::hypot(o[0] - 0.3, o[1] - 0.2, o[2] + 0.1) < 0.7;
      small += want == 1;
    }
  }
  std::printf("[ spheres ] from inside %d, the small one %d, through the cut-out %d of %d\n", inside, small, through, alpha_only);
  EXPECT_GT(inside, 200);
  EXPECT_GT(small, 200);
  ASSERT_GT(alpha_only, 1000);
  EXPECT_NEAR(static_cast<double>(through) / alpha_only, 0.5, 0.05);
  // rays leaving the big sphere's surface, outwards, from 2^-21 (|x| + r) off it
  int left = 0;
  for (int batch = 0; batch < 200; ++batch) {
    RayHit16 r{};
    alignas(64) int32_t valid[16];
    for (int i = 0; i < 16; ++i) {
      valid[i] = -1;
      const vec3f n = normalize(vec3f{U(rng), U(rng), U(rng)});
      const Sphere& sp = s.spheres[0];
      vec3f x = sp.center + n * sp.radius;
      const float k = 0x1p-21f;
      x = x + vec3f{n.x * k * (std::fabs(x.x) + sp.radius), n.y * k * (std::fabs(x.y) + sp.radius), n.z * k * (std::fabs(x.z) + sp.radius)};
      vec3f d = normalize(vec3f{U(rng), U(rng), U(rng)});
      if (dot(d, n) < 0) d = -d;
      r.ray.org_x[i] = x.x, r.ray.org_y[i] = x.y, r.ray.org_z[i] = x.z;
      r.ray.dir_x[i] = d.x, r.ray.dir_y[i] = d.y, r.ray.dir_z[i] = d.z;
      r.ray.tnear[i] = 0;
      r.ray.tfar[i] = 1e30f;
      r.ray.mask[i] = ~0u;
      r.geomID[i] = ~0u;
    }
    accel.intersect16(valid, r, false);
    for (int i = 0; i < 16; ++i) {
      EXPECT_NE(r.geomID[i], 0u) << batch << " lane " << i << " t " << r.ray.tfar[i];
      ++left;
    }
  }
  EXPECT_EQ(left, 3200);
}
