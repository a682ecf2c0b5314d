// --equiangular (wave/equiangular.h): a light sample more per ray through a scattering
// medium, at a distance drawn by equiangular sampling towards a source and MIS-weighted
// against the light samples at the free flights' collisions.
// - The distance's density (medium/equiangular.h) integrates to one over its stretch, its
//   samples follow it (a chi-square test), and every SIMD lane gives the scalar bits.
// - Images with and without it have the same mean (independent seeds, each quarter and
//   channel), in fog rooms lit by a 5 cm quad source, a small sphere source, a point and a
//   spot source and a distant one (which no segment sample aims at): seen from outside the
//   fog through an interface box, with a glass ball in it (rays that leave the glass start
//   their stretch there) and a chromatic fog; and from inside a fog without interfaces whose
//   rays run out of the room's open side to infinity, with the light strategy alone, the
//   balance heuristic, the light BVH's pick and two light samples per vertex; and beside
//   --light-paths (whose caustic paths neither takes twice).
// - It ran (the same seed renders differently), it changes nothing in a scene without
//   media, and the options it does not combine with are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "app/cli.h"
#include "media_util.h"
#include "medium/equiangular.h"
#include "render/options.h"
#include "render_util.h"
#include "wave/media.h"

using namespace tuile;
using namespace tuile::test;

namespace {

struct EqStretch {
  vec3f x, d, c;
  float lo, hi;
};

// EqStretches past a point, ending before it, starting after it, very close to it.
std::vector<EqStretch> eq_stretches() {
  return {{{0, 0, 0}, {1, 0, 0}, {0.5f, 0.1f, 0}, 0.f, 2.f},
          {{0, 0, 0}, {0, 0, 1}, {0.3f, -0.2f, -1}, 0.f, 3.f},
          {{1, 2, 3}, normalize(vec3f{1, 1, 0}), {2, 3.01f, 3}, 0.5f, 4.f},
          {{0, 0, 0}, {0, 1, 0}, {0.02f, 0.7f, 0}, 0.2f, 1.5f},
          {{-1, 0, 0}, {1, 0, 0}, {3, 0.5f, 0}, 0.f, 1.f}};
}

EquiangularFrame<float> eq_frame_of(const EqStretch& s) {
  return equiangular_frame(Vec3<float>{s.x.x, s.x.y, s.x.z}, Vec3<float>{s.d.x, s.d.y, s.d.z},
                           Vec3<float>{s.c.x, s.c.y, s.c.z}, s.lo, s.hi);
}

// The integral of the density over [a, b] (Simpson's rule, n intervals, in double).
double eq_integral(const EquiangularFrame<float>& f, double a, double b, int n) {
  const double h = (b - a) / n;
  double sum = 0;
  for (int i = 0; i <= n; ++i) {
    const double w = i == 0 || i == n ? 1 : i % 2 ? 4 : 2;
    sum += w * equiangular_pdf(f, static_cast<float>(a + i * h));
  }
  return sum * h / 3;
}

}  // namespace

TEST(Equiangular, DensityIntegratesToOne) {
  for (const EqStretch& s : eq_stretches()) {
    const EquiangularFrame<float> f = eq_frame_of(s);
    ASSERT_TRUE(f.ok);
    EXPECT_NEAR(eq_integral(f, s.lo, s.hi, 200000), 1.0, 1e-3) << s.lo << " " << s.hi;
  }
  // an empty stretch has no density
  EqStretch e = eq_stretches()[0];
  e.hi = e.lo;
  EXPECT_FALSE(eq_frame_of(e).ok);
  EXPECT_EQ(equiangular_pdf(eq_frame_of(e), e.lo), 0.f);
  // a stretch through the point itself, and one that meets nothing, stay finite
  const EquiangularFrame<float> through = equiangular_frame(Vec3<float>{0, 0, 0}, Vec3<float>{1, 0, 0},
                                                            Vec3<float>{0.5f, 0, 0}, 0.f, 1.f);
  const EquiangularFrame<float> far = equiangular_frame(Vec3<float>{0, 0, 0}, Vec3<float>{1, 0, 0},
                                                        Vec3<float>{0.5f, 0.2f, 0}, 0.f, segment_far);
  for (float u : {0.f, 0.25f, 0.5f, 0.999f}) {
    for (const auto& f : {through, far}) {
      const float t = equiangular_sample(f, 0.f, f.theta_b > 1.5f ? segment_far : 1.f, u);
      EXPECT_TRUE(std::isfinite(t) && std::isfinite(equiangular_pdf(f, t)) && equiangular_pdf(f, t) > 0.f) << u;
    }
  }
}

// Samples in 20 bins of each stretch against the density's integral over each bin: a
// chi-square statistic of 19 degrees of freedom below 55 (a false alarm once in 10^5 runs).
TEST(Equiangular, SamplesFollowTheirDensity) {
  const int n = scaled(200000);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (const EqStretch& s : eq_stretches()) {
    const EquiangularFrame<float> f = eq_frame_of(s);
    constexpr int bins = 20;
    std::vector<int> count(bins, 0);
    for (int i = 0; i < n; ++i) {
      const float t = equiangular_sample(f, s.lo, s.hi, U(rng));
      ASSERT_TRUE(t >= s.lo && t <= s.hi) << t;
      count[static_cast<size_t>(std::min(bins - 1, static_cast<int>((t - s.lo) / (s.hi - s.lo) * bins)))]++;
    }
    double chi2 = 0;
    for (int b = 0; b < bins; ++b) {
      const double w = (s.hi - s.lo) / bins;
      const double e = n * eq_integral(f, s.lo + b * w, s.lo + (b + 1) * w, 2000);
      chi2 += (count[static_cast<size_t>(b)] - e) * (count[static_cast<size_t>(b)] - e) / e;
    }
    EXPECT_LT(chi2, 55.0) << "stretch from " << s.lo << " to " << s.hi;
  }
}

TEST(Equiangular, EveryLaneEqualsScalar) {
  constexpr int W = simd_width;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  for (int round = 0; round < 64; ++round) {
    alignas(64) float xs[3][W], ds[3][W], cs[3][W], lo[W], hi[W], u[W];
    for (int l = 0; l < W; ++l) {
      vec3f d = normalize(vec3f{U(rng), U(rng), U(rng)});
      for (int a = 0; a < 3; ++a) {
        xs[a][l] = 2 * U(rng);
        cs[a][l] = 2 * U(rng);
      }
      ds[0][l] = d.x, ds[1][l] = d.y, ds[2][l] = d.z;
      lo[l] = 0.5f + 0.5f * U(rng);
      hi[l] = l % 5 == 0 ? segment_far : lo[l] + 2.f + U(rng);
      u[l] = 0.5f + 0.5f * U(rng);
    }
    auto v3 = [](float (*p)[W]) { return Vec3<vfloat>{load<vfloat>(p[0]), load<vfloat>(p[1]), load<vfloat>(p[2])}; };
    const EquiangularFrame<vfloat> fv = equiangular_frame(v3(xs), v3(ds), v3(cs), load<vfloat>(lo), load<vfloat>(hi));
    const vfloat tv = equiangular_sample(fv, load<vfloat>(lo), load<vfloat>(hi), load<vfloat>(u));
    const vfloat pv = equiangular_pdf(fv, tv);
    alignas(64) float t_l[W], p_l[W], h_l[W];
    store(t_l, tv);
    store(p_l, pv);
    store(h_l, fv.h);
    for (int l = 0; l < W; ++l) {
      const EquiangularFrame<float> f = equiangular_frame(Vec3<float>{xs[0][l], xs[1][l], xs[2][l]},
                                                          Vec3<float>{ds[0][l], ds[1][l], ds[2][l]},
                                                          Vec3<float>{cs[0][l], cs[1][l], cs[2][l]}, lo[l], hi[l]);
      const float t = equiangular_sample(f, lo[l], hi[l], u[l]);
      EXPECT_EQ(h_l[l], f.h) << "lane " << l;
      EXPECT_EQ(t_l[l], t) << "lane " << l;
      EXPECT_EQ(p_l[l], equiangular_pdf(f, t)) << "lane " << l;
    }
  }
}

namespace {

// A room (diffuse walls, the left one red, its front open) full of fog, lit by small
// sources in the fog: a 5 cm quad under the ceiling facing down, a sphere of radius 4 cm, a
// point and a spot source, and a distant one through the open side. outside: the camera
// looks in from outside the fog, which an interface box bounds, and a glass ball stands in
// it; else the camera is in the fog, which has no interface and fills the world.
Scene fog_room(int res, bool outside) {
  Scene s;
  s.source = "test:fog-room";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.7f, 0.7f}));  // 0
  s.materials.push_back(diffuse_material(Rgb{0.6f, 0.2f, 0.1f}));  // 1
  s.materials.push_back(glass_material());  // 2
  s.media.push_back(outside ? homogeneous({0.05f, 0.1f, 0.02f}, {0.5f, 0.6f, 0.8f}, 0.3f)
                            : homogeneous({0.1f, 0.1f, 0.1f}, {0.4f, 0.4f, 0.4f}, -0.2f));
  const int fog = 0;
  add_named_quad(s, "floor", 0, {-1, 0, -1}, {0, 0, 2}, {2, 0, 0});
  add_named_quad(s, "ceiling", 0, {-1, 2, -1}, {2, 0, 0}, {0, 0, 2});
  add_named_quad(s, "back", 0, {-1, 0, -1}, {2, 0, 0}, {0, 2, 0});
  add_named_quad(s, "left", 1, {-1, 0, -1}, {0, 2, 0}, {0, 0, 2});
  add_named_quad(s, "right", 0, {1, 0, -1}, {0, 0, 2}, {0, 2, 0});
  add_named_quad(s, "lamp", 0, {-0.5f, 1.9f, -0.6f}, {0.4f, 0, 0}, {0, 0, 0.4f}, 6);  // facing down
  Sphere bulb;
  bulb.center = {0.5f, 1.2f, -0.5f};
  bulb.radius = 0.15f;
  bulb.material = 0;
  bulb.emission = {4, 6, 8};
  s.spheres.push_back(bulb);
  s.lights.push_back(point_light({-0.5f, 0.8f, 0.2f}, {0.6f, 0.5f, 0.4f}));
  s.lights.push_back(spot_light({0.6f, 1.7f, 0.3f}, {-0.3f, -1, -0.2f}, std::cos(0.3f), std::cos(0.5f), {1.5f, 1.5f, 1.5f}));
  s.lights.push_back(distant_light({0.2f, 0.3f, 1}, {0.3f, 0.3f, 0.3f}));  // in through the open side
  if (outside) {
    s.materials.push_back(interface_material());  // 3
    Mesh box = media_box({-0.99f, 0.01f, -0.99f}, {0.99f, 1.99f, 1.f});
    box.material = 3;
    box.medium_inside = fog;
    s.meshes.push_back(box);
    for (Mesh& m : s.meshes)
      if (m.name == "lamp") m.medium_inside = m.medium_outside = fog;
    s.spheres[0].medium_inside = s.spheres[0].medium_outside = fog;
    Sphere ball;
    ball.center = {0.1f, 0.45f, -0.2f};
    ball.radius = 0.35f;
    ball.material = 2;
    ball.medium_outside = fog;
    s.spheres.push_back(ball);
  } else {
    s.camera_medium = fog;
  }
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 55;
  camera_look_at(s.camera, {0, 1.f, 2.6f}, {0, 0.9f, 0}, {0, 1, 0});
  finalize_scene(s);
  return s;
}

RenderOptions eq_options(bool equiangular, uint32_t spp) {
  RenderOptions o = independent_options(Strategy::mis, LightPick::power, MisMode::multi, 5, spp, 0);
  o.est.equiangular = equiangular;
  return o;
}

}  // namespace

TEST(Equiangular, RendersTheSameMeanSeenThroughAnInterface) {
  const Scene s = fog_room(20, true);
  const uint32_t spp = static_cast<uint32_t>(scaled(48));
  expect_same_mean_over_seeds(s, eq_options(true, spp), eq_options(false, spp), 24, "fog seen from outside");
  // with the light tracer beside it (the glass ball's caustic in the fog)
  RenderOptions both = eq_options(true, spp);
  both.est.light_paths = true;
  expect_same_mean_over_seeds(s, both, eq_options(false, spp), 24, "fog seen from outside, light paths");
}

TEST(Equiangular, RendersTheSameMeanInAFogWithoutInterfaces) {
  const Scene s = fog_room(20, false);
  const uint32_t spp = static_cast<uint32_t>(scaled(48));
  RenderOptions with = eq_options(true, spp), without = eq_options(false, spp);
  for (RenderOptions* o : {&with, &without}) {
    o->est.pick = LightPick::bvh;
    o->est.heuristic = Heuristic::balance;
    o->est.light_samples = 2;
  }
  expect_same_mean_over_seeds(s, with, without, 24, "fog around the camera");
  with.est.strategy = without.est.strategy = Strategy::light;
  with.est.light_samples = without.est.light_samples = 1;
  expect_same_mean_over_seeds(s, with, without, 24, "fog around the camera, light strategy");
}

TEST(Equiangular, RunsOnlyInMediaAndRefusesWhatItCannotDo) {
  const Scene s = fog_room(12, true);
  Accel accel(s);
  EXPECT_NE(render_mean(s, accel, eq_options(true, 4), 4), render_mean(s, accel, eq_options(false, 4), 4));
  // a scene without media: the same bits
  Scene plain = fog_room(12, true);
  plain.media.clear();
  std::erase_if(plain.meshes, [](const Mesh& m) { return m.name == "box"; });  // the interface box
  for (Mesh& m : plain.meshes) m.medium_inside = m.medium_outside = -1;
  for (Sphere& sp : plain.spheres) sp.medium_inside = sp.medium_outside = -1;
  finalize_scene(plain);
  Accel pa(plain);
  EXPECT_EQ(render_mean(plain, pa, eq_options(true, 4), 4), render_mean(plain, pa, eq_options(false, 4), 4));
  for (int k = 0; k < 6; ++k) {
    RenderOptions o = eq_options(true, 4);
    if (k == 0) o.est.strategy = Strategy::bsdf;
    if (k == 5) o.est.strategy = Strategy::ris;
    if (k == 1) o.est.mode = MisMode::one;
    if (k == 2) o.est.pick = LightPick::all;
    if (k == 3) o.est.heuristic = Heuristic::optimal;
    if (k == 4) o.est.guide = true;
    EXPECT_THROW(validate(o), std::invalid_argument) << k;
  }
}

// The default, auto: on in a scene with a medium that scatters where the estimator allows
// it, off in one whose media only absorb, without media, or with --guide; on and off as
// told, a wrong word refused.
TEST(Equiangular, AutoIsOnWhereAMediumScatters) {
  auto resolved = [](Scene s, const std::string& value, bool guide = false) {
    RenderFlags f;
    f.equiangular = value;
    f.guide = guide;
    f.max_depth = 5;
    f.max_depth_given = true;
    return resolve_options(f, s).est.equiangular;
  };
  const Scene fog = fog_room(8, true);
  Scene absorbing = fog;
  absorbing.media[0].sigma_s = {0, 0, 0};
  Scene plain = fog;
  plain.media.clear();
  EXPECT_TRUE(resolved(fog, ""));
  EXPECT_TRUE(resolved(fog, "auto"));
  EXPECT_FALSE(resolved(fog, "off"));
  EXPECT_FALSE(resolved(fog, "", true));
  EXPECT_FALSE(resolved(absorbing, ""));
  EXPECT_FALSE(resolved(plain, ""));
  EXPECT_TRUE(resolved(plain, "on"));
  EXPECT_THROW(resolved(fog, "yes"), std::invalid_argument);
  EXPECT_THROW(resolved(fog, "on", true), std::invalid_argument);
}
