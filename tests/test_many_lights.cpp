// Many lights (#19): the light BVH picker and resampled importance sampling in renders with
// an exact answer. A diffuse floor under 400 small coplanar sources (triangles and
// parallelograms) whose radiance spans four decades and whose sizes span one, that nothing
// occludes: Lambert's polygon formula gives every pixel. Every estimator is unbiased (the
// image mean within 3 standard errors of the exact mean, independent sampler; at 3 sigma a
// correct estimator fails one case in 370) and its MSE falls like 1/spp. RIS with one light
// candidate and no BSDF candidate is light sampling itself (the same image to rounding).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

PlaneScene many_sources() {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 24);
  std::mt19937 rng(5);
  auto U = [&] { return static_cast<float>(rng() >> 8) * 0x1p-24f; };
  // a 20 x 20 grid of cells 0.15 m wide over [-1.5, 1.5]^2 at y = 1, one source per cell
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) {
      const float x0 = -1.5f + 0.15f * static_cast<float>(i), z0 = -1.5f + 0.15f * static_cast<float>(j);
      const float a = 0.01f + 0.09f * U(), b = 0.01f + 0.09f * U();  // sizes over one decade
      const float L = std::pow(10.f, 4 * U() - 2);                       // radiance over four decades
      const float ox = x0 + (0.15f - a) * U(), oz = z0 + (0.15f - b) * U();
      // facing down: cross(e1, e2) = -y
      if ((i + j) % 2) add_source_quad(p, {ox, 1, oz}, {a, 0, 0}, {0, 0, b}, L);
      else add_source_triangle(p, {ox, 1, oz}, {ox + a, 1, oz}, {ox, 1, oz + b}, L);
    }
  return p;
}

struct Combo {
  std::string name;
  Strategy strategy;
  LightPick pick;
  LightPoint point = LightPoint::solid_angle;
  Heuristic heuristic = Heuristic::power;
  MisMode mode = MisMode::multi;
  int ris_light = 8, ris_bsdf = 1;
  uint32_t spp = 64;
};

RenderOptions options_for(const Combo& c, uint32_t spp, uint32_t seed) {
  RenderOptions o;
  o.est.strategy = c.strategy;
  o.est.pick = c.pick;
  o.est.point = c.point;
  o.est.heuristic = c.heuristic;
  o.est.mode = c.mode;
  o.est.ris_light = c.ris_light;
  o.est.ris_bsdf = c.ris_bsdf;
  o.est.sampler = SamplerKind::independent;  // independent samples: textbook standard errors
  o.est.spp = spp;
  o.est.seed = seed;
  o.threads = 2;
  return o;
}

double mse(const RenderResult& r, const std::vector<double>& exact) {
  double s = 0;
  for (size_t i = 0; i < exact.size(); ++i) s += (r.mean[3 * i] - exact[i]) * (r.mean[3 * i] - exact[i]);
  return s / static_cast<double>(exact.size());
}

struct Fixture {
  PlaneScene p = many_sources();
  std::vector<double> exact;
  Fixture() {
    finalize_scene(p.scene);
    exact = exact_image(p, 4);
  }
};
const Fixture& fixture() {
  static const Fixture f;
  return f;
}

}  // namespace

TEST(ManyLights, EveryEstimatorIsUnbiased) {
  const Fixture& fx = fixture();
  ASSERT_EQ(fx.p.scene.lights.size(), 400u);
  double exact_mean = 0;
  for (double e : fx.exact) exact_mean += e;
  exact_mean /= static_cast<double>(fx.exact.size());
  ASSERT_GT(exact_mean, 0.0);
  const Combo combos[] = {
      {"light:bvh", Strategy::light, LightPick::bvh},
      {"light:bvh:area", Strategy::light, LightPick::bvh, LightPoint::area},
      {"mis:bvh", Strategy::mis, LightPick::bvh},
      {"mis:bvh:balance-one", Strategy::mis, LightPick::bvh, LightPoint::solid_angle, Heuristic::balance, MisMode::one},
      {"ris", Strategy::ris, LightPick::bvh},
      {"ris:M1", Strategy::ris, LightPick::bvh, LightPoint::solid_angle, Heuristic::power, MisMode::multi, 1, 0},
      {"ris:M4:power", Strategy::ris, LightPick::power, LightPoint::solid_angle, Heuristic::power, MisMode::multi, 4, 0},
      {"ris:M32:K1", Strategy::ris, LightPick::bvh, LightPoint::solid_angle, Heuristic::power, MisMode::multi, 32, 1, 16},
      {"ris:M1:K1:uniform:area", Strategy::ris, LightPick::uniform, LightPoint::area, Heuristic::power, MisMode::multi, 1, 1},
      // BSDF candidates alone: the BSDF technique's heavy tails need more samples
      {"ris:K2", Strategy::ris, LightPick::bvh, LightPoint::solid_angle, Heuristic::power, MisMode::multi, 0, 2, 512},
  };
  for (const Combo& c : combos) {
    // the knob's samples (at least 8 per pixel): z is computed from the samples drawn
    const RenderResult r = render_scene(fx.p.scene, options_for(c, scaled(c.spp, 8u), 7));
    for (float v : r.mean) ASSERT_TRUE(std::isfinite(v)) << c.name;
    EXPECT_EQ(r.stats.rejected_light + r.stats.rejected_bsdf + r.stats.rejected_camera, 0u) << c.name;
    const double z = z_of_mean(r, fx.exact);
    EXPECT_LT(std::fabs(z), 3.0) << c.name << ": image mean is " << z << " standard errors from the exact mean " << exact_mean;
  }
}

// Per-pixel MSE against the exact image falls like 1/spp (ratio 4 for 4x the samples;
// 576 pixels: within about +-25%). And the BVH beats power-proportional picking here, where
// each point sees its nearby sources best: at equal samples its MSE is lower.
TEST(ManyLights, MseFallsLikeOneOverSppAndTheBvhBeatsPower) {
  const Fixture& fx = fixture();
  const Combo combos[] = {{"light:bvh", Strategy::light, LightPick::bvh},
                          {"mis:bvh", Strategy::mis, LightPick::bvh},
                          {"ris", Strategy::ris, LightPick::bvh},
                          {"light:power", Strategy::light, LightPick::power}};
  double at64[4];
  for (int i = 0; i < 4; ++i) {
    const double m16 = mse(render_scene(fx.p.scene, options_for(combos[i], 16, 11)), fx.exact);
    at64[i] = mse(render_scene(fx.p.scene, options_for(combos[i], 64, 11)), fx.exact);
    EXPECT_GT(m16 / at64[i], 3.0) << combos[i].name;
    EXPECT_LT(m16 / at64[i], 5.3) << combos[i].name;
  }
  EXPECT_LT(at64[0], 0.5 * at64[3]) << "bvh " << at64[0] << " vs power " << at64[3];
}

// RIS with M = 1, K = 0 keeps its one candidate with weight p-hat / p_light: the estimate
// f Le cos / p-hat * p-hat / p_light is light sampling's f Le cos / p_light, from the same
// random numbers (the light sample's pairs), to rounding.
TEST(ManyLights, RisWithOneLightCandidateIsLightSampling) {
  const Fixture& fx = fixture();
  for (LightPick pick : {LightPick::bvh, LightPick::power}) {
    Combo light{"light", Strategy::light, pick};
    Combo ris{"ris", Strategy::ris, pick, LightPoint::solid_angle, Heuristic::power, MisMode::multi, 1, 0};
    const RenderResult a = render_scene(fx.p.scene, options_for(light, 4, 3));
    const RenderResult b = render_scene(fx.p.scene, options_for(ris, 4, 3));
    ASSERT_EQ(a.mean.size(), b.mean.size());
    double worst = 0, total = 0;
    for (size_t i = 0; i < a.mean.size(); ++i) {
      total += a.mean[i];
      const double d = std::fabs(static_cast<double>(a.mean[i]) - b.mean[i]);
      worst = std::max(worst, d / std::max(1e-30, static_cast<double>(std::fabs(a.mean[i]))));
    }
    EXPECT_GT(total, 0.0);
    EXPECT_LT(worst, 1e-5) << (pick == LightPick::bvh ? "bvh" : "power");
  }
}
