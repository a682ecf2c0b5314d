// Point, spot and distant lights against their exact answers: a diffuse floor lit by a
// delta light has radiance rho/pi * I falloff cos / d^2 (point, spot) or rho/pi * E cos
// (distant). Every strategy must get it right: a BSDF ray cannot hit a delta light, so
// MIS gives them weight one and the BSDF strategy still samples them; resampled importance
// sampling takes them as candidates of density their pick probability.
#include <gtest/gtest.h>

#include <cmath>

#include "wave/generate.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

double smoothstep(double a, double b, double x) {
  const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

// Exact pixel means by q x q Gauss-Legendre-free midpoint quadrature (the integrand is
// smooth: a fine grid is accurate to well below the Monte Carlo error).
std::vector<double> exact_delta(const Scene& s, const Light& l, double rho, int q = 8) {
  return floor_pixel_means(s, q, [&](double x, double z, double) {
    if (l.type == LightKind::distant) return rho / M_PI * l.radiance.r * std::max(0.0, static_cast<double>(l.e1.y));
    const double w[3] = {l.p0.x - x, l.p0.y, l.p0.z - z};
    const double d2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2], dd = std::sqrt(d2);
    double I = l.radiance.r;
    if (l.type == LightKind::spot) {
      const double cos_t = -(w[0] * l.e1.x + w[1] * l.e1.y + w[2] * l.e1.z) / dd;
      I *= smoothstep(l.e2.y, l.e2.x, cos_t);
    }
    return rho / M_PI * I * std::max(0.0, w[1] / dd) / d2;
  });
}

}  // namespace

TEST(DeltaLights, PointSpotDistantAreExact) {
  for (LightKind type : {LightKind::point, LightKind::spot, LightKind::distant}) {
    PlaneScene p = plane_scene({0, 0.6f, 0}, 80, 20, 0.6f);
    Light l;
    l.type = type;
    l.p0 = {0.3f, 1.0f, -0.2f};
    l.radiance = {3, 3, 3};
    if (type == LightKind::spot) {
      l.e1 = normalize(vec3f{-0.2f, -1, 0.1f});
      l.e2 = {std::cos(0.35f), std::cos(0.6f), 0};  // falloff start, total
    }
    if (type == LightKind::distant) l.e1 = normalize(vec3f{0.3f, 1, -0.4f});
    p.scene.lights.push_back(l);
    finalize_scene(p.scene);
    const std::vector<double> exact = exact_delta(p.scene, p.scene.lights[0], 0.6);
    for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis, Strategy::ris})
      for (MisMode mode : {MisMode::multi, MisMode::one}) {
        RenderOptions o;
        o.est.strategy = st;
        o.est.mode = mode;
        o.est.sampler = SamplerKind::independent;
        o.est.spp = 64;
        for (bool general : {false, true}) {
          o.general_pipeline = general;
          const RenderResult r = render_scene(p.scene, o);
          const std::vector<float> var = r.film.variance_of_mean();
          double d = 0, v = 0, e = 0;
          for (size_t i = 0; i < exact.size(); ++i) {
            d += r.mean[3 * i] - exact[i];
            v += var[3 * i];
            e += exact[i];
          }
          ASSERT_GT(e, 0.0);
          // the only randomness is the pixel position: where the variance is ~0 compare
          // relatively (midpoint quadrature error ~1e-4), else within 3 standard errors
          const double z = std::fabs(d) / std::max(std::sqrt(v), 1e-4 * e);
          EXPECT_LT(z, 3.0) << int(type) << " " << describe(o.est) << " general " << general << ": mean " << d / e;
        }
      }
  }
}

// The light kinds (light/kinds.h): the dispatch over a batch of lanes visits each kind the
// batch holds exactly once, with the mask of its lanes (disjoint masks covering the batch),
// only the kinds of the groups asked for, and a rectangle pipeline's one case over every
// lane; each kind's power is its documented formula.
TEST(LightKinds, DispatchVisitsEachKindPresentOnceWithItsLanes) {
  alignas(64) int32_t types[simd_width];
  const uint32_t all_lanes = simd_width == 32 ? ~0u : (1u << simd_width) - 1;
  for (int pattern = 0; pattern < 64; ++pattern) {
    for (int l = 0; l < simd_width; ++l) types[l] = (pattern * 7 + l * (pattern % 5 + 1)) % light_kind_count;
    LightGeom<vfloat> g;
    g.type = load_i32<vfloat>(types);
    for (unsigned groups : {kind_all, kind_area, kind_delta}) {
      int visits[light_kind_count] = {};
      uint32_t seen = 0;
      for_each_light_kind<0u>(g, [](auto, const vmask&) {});  // no group: nothing runs
      auto visit = [&](auto ops, const vmask& m) {
        const int k = static_cast<int>(decltype(ops)::kind);
        ++visits[k];
        const uint32_t bits = lane_bits(m);
        EXPECT_EQ(bits & seen, 0u) << "masks overlap";
        seen |= bits;
        for (int l = 0; l < simd_width; ++l) EXPECT_EQ(((bits >> l) & 1u) != 0, types[l] == k) << k << " lane " << l;
      };
      if (groups == kind_all) for_each_light_kind<kind_all>(g, visit);
      else if (groups == kind_area) for_each_light_kind<kind_area>(g, visit);
      else for_each_light_kind<kind_delta>(g, visit);
      uint32_t expected = 0;
      for (int k = 0; k < light_kind_count; ++k) {
        bool present = false;
        for (int l = 0; l < simd_width; ++l) present = present || types[l] == k;
        const bool asked = (kind_info(static_cast<LightKind>(k)).group & groups) != 0;
        EXPECT_EQ(visits[k], present && asked ? 1 : 0) << "kind " << kind_info(static_cast<LightKind>(k)).name;
        for (int l = 0; l < simd_width; ++l)
          if (types[l] == k && asked) expected |= 1u << l;
      }
      EXPECT_EQ(seen, expected);
    }
  }
  // the planar kinds together (their shared code), every other kind alone
  for (int pattern = 0; pattern < 16; ++pattern) {
    for (int l = 0; l < simd_width; ++l) types[l] = (pattern + l * (pattern % 3 + 1)) % light_kind_count;
    LightGeom<vfloat> g;
    g.type = load_i32<vfloat>(types);
    uint32_t seen = 0;
    int planar_runs = 0;
    for_each_light_shape<kind_all>(g, [&](auto ops, const vmask& m) {
      const uint32_t bits = lane_bits(m);
      EXPECT_EQ(bits & seen, 0u);
      seen |= bits;
      if constexpr (decltype(ops)::planar) {
        ++planar_runs;
        for (int l = 0; l < simd_width; ++l)
          EXPECT_EQ(((bits >> l) & 1u) != 0, types[l] <= static_cast<int>(LightKind::parallelogram));
      }
    });
    EXPECT_EQ(seen, all_lanes);
    EXPECT_LE(planar_runs, 1);
  }
  int runs = 0;
  for_each_light_kind<kind_area | kind_rects>(LightGeom<vfloat>{}, [&](auto ops, const vmask& m) {
    ++runs;
    EXPECT_EQ(decltype(ops)::kind, LightKind::parallelogram);
    EXPECT_EQ(lane_bits(m), all_lanes);
  });
  EXPECT_EQ(runs, 1);
  // the groups: delta kinds have no surface, the others a density
  for (int k = 0; k < light_kind_count; ++k) {
    const LightKind kind = static_cast<LightKind>(k);
    EXPECT_EQ(is_delta(kind), kind == LightKind::point || kind == LightKind::spot || kind == LightKind::distant);
    EXPECT_EQ(is_planar(kind), kind == LightKind::triangle || kind == LightKind::parallelogram);
  }
}

TEST(LightKinds, PowerAndBoundsFollowEachKindsFormula) {
  const float pi = 3.14159265f;
  LightShape l;
  l.p0 = {1, 2, 3};
  l.e1 = {0.5f, 0, 0};
  l.e2 = {0, 0, 2};
  l.area = 1;
  l.type = LightKind::parallelogram;
  EXPECT_FLOAT_EQ(light_power(l, 3.f, 10.f), 3.f * pi);
  l.two_sided = true;
  EXPECT_FLOAT_EQ(light_power(l, 3.f, 10.f), 6.f * pi);
  l.type = LightKind::sphere;
  l.two_sided = false;
  l.area = 4 * pi * 0.25f;
  EXPECT_FLOAT_EQ(light_power(l, 2.f, 10.f), 2.f * pi * l.area);
  l.type = LightKind::point;
  EXPECT_FLOAT_EQ(light_power(l, 2.f, 10.f), 8.f * pi);
  l.type = LightKind::spot;
  l.e1 = {0, -1, 0};
  l.e2 = {0.9f, 0.7f, 0};  // cos of the falloff start, of the cone's edge
  EXPECT_FLOAT_EQ(light_power(l, 2.f, 10.f), 4.f * pi * (1.f - 0.8f));
  l.type = LightKind::distant;
  EXPECT_FLOAT_EQ(light_power(l, 2.f, 10.f), pi * 100.f * 2.f);
  // a sky: what the scene's disc receives facing it, pi r^2 times the irradiance pi L, so a
  // sky of radiance L weighs as a distant source of irradiance pi L (not pbrt-v4's 4 pi^2 r^2 L)
  const float distant_pi = light_power(l, 2.f * pi, 10.f);
  l.type = LightKind::infinite;
  EXPECT_FLOAT_EQ(light_power(l, 2.f, 10.f), pi * pi * 100.f * 2.f);
  EXPECT_FLOAT_EQ(light_power(l, 2.f, 10.f), distant_pi);
  // bounds: a point with every direction, a spot's cone around its axis, none at infinity
  LightBounds b;
  l.type = LightKind::point;
  ASSERT_TRUE(light_bounds(l, 1.0, b));
  EXPECT_EQ(b.lo.x, 1.f);
  EXPECT_EQ(b.hi.z, 3.f);
  EXPECT_EQ(b.cos_o, -1.0);
  b = LightBounds{};
  l.type = LightKind::spot;
  ASSERT_TRUE(light_bounds(l, 1.0, b));
  EXPECT_EQ(b.w.y, -1.f);
  EXPECT_NEAR(b.cos_o, 0.9, 1e-7);
  EXPECT_NEAR(b.cos_e, std::cos(std::acos(0.7) - std::acos(0.9)), 1e-7);
  b = LightBounds{};
  l.type = LightKind::distant;
  EXPECT_FALSE(light_bounds(l, 1.0, b));
  b = LightBounds{};
  l.type = LightKind::triangle;
  l.e1 = {1, 0, 0};
  l.e2 = {0, 0, 1};
  l.area = 0.5f;
  ASSERT_TRUE(light_bounds(l, 2.0, b));
  EXPECT_EQ(b.w.y, -1.f);  // cross(e1, e2) = (0, -1, 0)
  EXPECT_EQ(b.hi.x, 2.f);
  EXPECT_NEAR(b.phi, 2.0 * 0.5 * 3.14159265358979323846, 1e-12);
}
