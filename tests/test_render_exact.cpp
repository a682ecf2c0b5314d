// Images against exact answers: a diffuse floor lit by polygonal sources that nothing
// occludes has a closed form (Lambert's polygon formula). Every estimator must be
// unbiased there (image mean within 3 standard errors of the exact mean) and its MSE
// must fall like 1/spp.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "render_util.h"
#include "scene/pbrt.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// The four scenes of the issue; cameras look straight down and see only the floor.
PlaneScene one_square() {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 24);
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  return p;
}
PlaneScene tiled_square() {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 24);
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j)
      add_source_quad(p, {-0.5f + 0.1f * i, 1, -0.5f + 0.1f * j}, {0.1f, 0, 0}, {0, 0, 0.1f}, 2.f);
  return p;
}
PlaneScene near_source() {
  // a source 3 mm above the floor, the camera sees the floor right beside it
  PlaneScene p = plane_scene({0.5f, 0.5f, 0}, 87, 24);
  add_source_quad(p, {-1, 0.003f, -0.5f}, {1, 0, 0}, {0, 0, 1}, 1.f);
  return p;
}
PlaneScene contrast() {
  // radiance ratio 1e5, a sheared parallelogram and a triangle
  PlaneScene p = plane_scene({0, 0.4f, 0}, 90, 24);
  add_source_quad(p, {-1.5f, 1, -0.5f}, {1, 0, 0}, {0.3f, 0, 1}, 1000.f);
  add_source_triangle(p, {0.2f, 0.6f, 0.1f}, {0.4f, 0.6f, 0.1f}, {0.3f, 0.6f, -0.1f}, 0.01f);
  return p;
}

struct Combo {
  Strategy strategy;
  LightPick pick;
  LightPoint point;
  Heuristic heuristic;
  MisMode mode;
  std::string name() const {
    static const char* s[] = {"light", "bsdf", "mis"};
    static const char* pk[] = {"all", "uniform", "area", "power"};
    static const char* pt[] = {"area", "sa"};
    static const char* h[] = {"balance", "power", "cutoff", "maximum", "optimal"};
    std::string n = std::string(s[int(strategy)]) + "_" + pk[int(pick)] + "_" + pt[int(point)];
    if (strategy == Strategy::mis) n += std::string("_") + h[int(heuristic)] + (mode == MisMode::one ? "_one" : "_multi");
    return n;
  }
};

std::vector<Combo> all_combos() {
  std::vector<Combo> c;
  for (LightPick pk : {LightPick::all, LightPick::uniform, LightPick::area, LightPick::power})
    for (LightPoint pt : {LightPoint::area, LightPoint::solid_angle}) {
      c.push_back({Strategy::light, pk, pt, Heuristic::balance, MisMode::multi});
      for (Heuristic h : {Heuristic::balance, Heuristic::power, Heuristic::cutoff, Heuristic::maximum})
        for (MisMode m : {MisMode::multi, MisMode::one}) c.push_back({Strategy::mis, pk, pt, h, m});
      // optimal MIS (wave/optimal_mis.h): its per-pixel weights come from the pixel's earlier
      // samples, independent of the later ones (the independent sampler), so it stays unbiased
      c.push_back({Strategy::mis, pk, pt, Heuristic::optimal, MisMode::multi});
      if (pk == LightPick::power) c.push_back({Strategy::mis, pk, pt, Heuristic::optimal, MisMode::one});
    }
  c.push_back({Strategy::bsdf, LightPick::power, LightPoint::area, Heuristic::balance, MisMode::multi});
  return c;
}

struct Case {
  const char* name;
  PlaneScene (*make)();
};
const Case cases[] = {{"one_square", one_square}, {"tiled_square", tiled_square}, {"near_source", near_source},
                      {"contrast", contrast}};

RenderOptions options_for(const Combo& c, uint32_t spp, uint32_t seed) {
  RenderOptions o;
  o.est.strategy = c.strategy;
  o.est.pick = c.pick;
  o.est.point = c.point;
  o.est.heuristic = c.heuristic;
  o.est.mode = c.mode;
  o.est.sampler = SamplerKind::independent;  // independent samples: textbook standard errors
  o.est.spp = spp;
  o.est.seed = seed;
  o.threads = 2;
  return o;
}

}  // namespace

class ExactPlane : public ::testing::TestWithParam<int> {};

TEST_P(ExactPlane, EveryEstimatorIsUnbiased) {
  const Case& cs = cases[GetParam()];
  PlaneScene p = cs.make();
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 6);
  double exact_mean = 0;
  for (double e : exact) exact_mean += e;
  exact_mean /= exact.size();
  ASSERT_GT(exact_mean, 0.0);
  int failures = 0;
  for (const Combo& c : all_combos()) {
    // Heavy tails (the course's "accidents") make the sample variance underestimate the
    // error at low counts: area sampling of a source 3 mm above the floor, and the BSDF
    // technique alone, get more samples so that the normal approximation holds.
    uint32_t spp = c.strategy == Strategy::bsdf ? 256 : 64;
    if (GetParam() == 2 && c.point == LightPoint::area && c.strategy != Strategy::bsdf) spp = 2048;
    // the sanitizer tree draws 1/TUILE_TEST_SCALE of them (tests/test_scale.h), at least 16
    // per pixel (9216 per image), and 32 for the BSDF technique alone (at 16 it may not
    // reach the source 3 mm above the floor at all: a zero mean with a zero variance); z
    // divides by the standard error of the samples drawn
    // (--light-pick all samples every source at each sample: on tiled_square, 100 of them, a
    // sum whose distribution is close to normal already, and 100 times the work; there the
    // floor is 4 per pixel, 2304 samples per image, enough for the variance of every pixel)
    // Area sampling of the source 3 mm above the floor keeps at least 128 (at 64, 1/32 of
    // its 2048, the sample variance fell short and z reached -3.5 for every pick).
    const bool many_all = c.pick == LightPick::all && p.scene.lights.size() >= 100;
    const bool near_area = GetParam() == 2 && c.point == LightPoint::area && c.strategy != Strategy::bsdf;
    spp = scaled(spp, c.strategy == Strategy::bsdf ? 32u : near_area ? 128u : many_all ? 4u : 16u);
    const RenderResult r = render_scene(p.scene, options_for(c, spp, 7));
    for (float v : r.mean) ASSERT_TRUE(std::isfinite(v)) << c.name();
    EXPECT_EQ(r.stats.rejected_light + r.stats.rejected_bsdf + r.stats.rejected_camera, 0u) << c.name();
    const double z = z_of_mean(r, exact);
    if (!(std::fabs(z) < 3.0)) {
      ++failures;
      ADD_FAILURE() << cs.name << " " << c.name() << ": image mean is " << z << " standard errors from the exact mean "
                    << exact_mean;
    }
  }
  EXPECT_EQ(failures, 0);
}

INSTANTIATE_TEST_SUITE_P(Scenes, ExactPlane, ::testing::Range(0, 4), [](const auto& info) {
  return std::string(cases[info.param].name);
});

// Per-pixel MSE against the exact image falls like 1/spp (ratio 4 for 4x the samples).
TEST(ExactPlane, MseFallsLikeOneOverSpp) {
  PlaneScene p = one_square();
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 6);
  const Combo combos[] = {{Strategy::light, LightPick::uniform, LightPoint::area, Heuristic::balance, MisMode::multi},
                          {Strategy::bsdf, LightPick::uniform, LightPoint::area, Heuristic::balance, MisMode::multi},
                          {Strategy::mis, LightPick::uniform, LightPoint::solid_angle, Heuristic::power, MisMode::multi},
                          {Strategy::mis, LightPick::uniform, LightPoint::area, Heuristic::balance, MisMode::one},
                          {Strategy::mis, LightPick::uniform, LightPoint::area, Heuristic::optimal, MisMode::multi}};
  for (const Combo& c : combos) {
    double mse[2];
    for (int k = 0; k < 2; ++k) {
      // (optimal MIS learns its weights over a pixel's first samples, where its error falls
      // faster than 1/spp: it is compared once they are learnt, at 64 and 256)
      const uint32_t base = c.heuristic == Heuristic::optimal ? 64 : 16;
      const RenderResult r = render_scene(p.scene, options_for(c, k == 0 ? base : 4 * base, 11));
      double s = 0;
      for (size_t i = 0; i < exact.size(); ++i) s += (r.mean[3 * i] - exact[i]) * (r.mean[3 * i] - exact[i]);
      mse[k] = s / exact.size();
    }
    const double ratio = mse[0] / mse[1];
    // 576 pixels: the MSE ratio of independent estimates is 4 within about +-25%
    EXPECT_GT(ratio, 3.0) << c.name();
    EXPECT_LT(ratio, 5.3) << c.name();
  }
}

// A textured reflectance replaces the material's constant (pbrt: "texture reflectance"
// instead of "rgb reflectance"): a floor whose texture holds the texel t renders exactly
// as the floor of constant reflectance t, bit for bit, whatever constant the textured
// material also carries; where a hit has no texel (a mesh without uv) the texture's mean
// stands in. (Until this test, a texel was multiplied by the default 0.5 and textured
// surfaces came out half as bright as pbrt-v4's.)
TEST(ExactPlane, TexturedReflectanceReplacesTheConstant) {
  auto scene = [](bool textured, bool uv) {
    PlaneScene p = one_square();
    Scene& s = p.scene;
    if (textured) {
      Texture t;
      t.name = "two texels";
      t.width = 2;
      t.height = 1;
      t.rgb = {0.8f, 0.6f, 0.3f, 0.8f, 0.6f, 0.3f};  // one colour: the image is exact
      s.textures.push_back(t);
      s.materials[0] = diffuse_material(Rgb{0.5f, 0.5f, 0.5f}, 0);
      if (uv) s.meshes[0].uvs = {0, 0, 1, 0, 1, 1, 0, 1};
    } else {
      s.materials[0] = diffuse_material(Rgb{0.8f, 0.6f, 0.3f});
    }
    finalize_scene(s);
    return s;
  };
  RenderOptions o;
  o.est.spp = 4;
  const std::vector<float> plain = render_scene(scene(false, false), o).mean;
  for (bool uv : {true, false}) {
    const std::vector<float> tex = render_scene(scene(true, uv), o).mean;
    ASSERT_EQ(tex.size(), plain.size());
    double sum = 0;
    for (size_t i = 0; i < tex.size(); ++i) {
      ASSERT_EQ(tex[i], plain[i]) << (uv ? "texel" : "texture mean") << " value " << i;
      sum += tex[i];
    }
    EXPECT_GT(sum, 0.0);
  }
}

// An emissive dome: a sphere of radius 10 turned inwards by ReverseOrientation, black, of
// radiance 1, round a grey floor of reflectance 0.5 that the camera sees alone. Every
// direction above the floor meets the dome, so the floor's radiance is exactly 0.5 (its
// light reaches only the black dome). The dome's light was dropped ("emitting inwards: not
// supported") and the image was black. 3 standard errors (0.3% two-sided).
TEST(ExactPlane, AnInwardEmittingDomeLightsTheFloor) {
  Scene s = load_pbrt_string(
      "Film \"rgb\" \"integer xresolution\" [ 16 ] \"integer yresolution\" [ 16 ]\n"
      "LookAt 0 1 0  0 0 0  0 0 1\nCamera \"perspective\" \"float fov\" [ 40 ]\nWorldBegin\n"
      "Material \"diffuse\" \"rgb reflectance\" [ 0.5 0.5 0.5 ]\n"
      "Shape \"trianglemesh\" \"point3 P\" [ -4 0 -4  4 0 -4  4 0 4  -4 0 4 ] \"integer indices\" [ 0 2 1  0 3 2 ]\n"
      "AttributeBegin\nReverseOrientation\nAreaLightSource \"diffuse\" \"rgb L\" [ 1 1 1 ]\n"
      "Material \"diffuse\" \"rgb reflectance\" [ 0 0 0 ]\nShape \"sphere\" \"float radius\" [ 10 ]\nAttributeEnd\n",
      "dome.pbrt", ".");
  finalize_scene(s);
  RenderOptions o;
  o.est.max_depth = 3;
  o.est.sampler = SamplerKind::independent;
  o.est.spp = scaled(64u, 16u);
  o.est.seed = 5;
  o.threads = 2;
  const RenderResult r = render_scene(s, o);
  const std::vector<double> exact(16 * 16, 0.5);
  const double z = z_of_mean(r, exact);
  EXPECT_LT(std::fabs(z), 3.0) << "mean " << r.mean[0] << " ...";
  EXPECT_GT(r.mean[0], 0.3f);
}
