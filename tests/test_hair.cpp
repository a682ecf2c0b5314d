// pbrt-v4's "hair" material on curves, end to end: the loader's parameters (sigma_a,
// reflectance, melanin, defaults, bad values naming file and line), fibers that absorb
// nothing vanish in a white furnace under every strategy (the BSDF conserves energy and
// the frame, cosine and MIS around it are consistent), and the highlight of a wide fiber
// sits on the side that mirrors the light (the offset h across the fiber has the sign the
// BSDF's lobes assume). The BSDF's own sampling, pdf, energy and lanes: test_materials.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "bsdf/hair.h"
#include "render_util.h"
#include "scene/pbrt.h"
#include "test_scale.h"

using namespace tuile;
using namespace tuile::test;

namespace {

Scene load_hair(const std::string& body) {
  return load_pbrt_string("WorldBegin\n" + body + "Shape \"curve\" \"point3 P\" [0 0 0 1 0 0 2 0 0 3 0 0]\n", "h.pbrt", ".");
}

std::string hair_error(const std::string& body) {
  try {
    load_hair(body);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "(no error)";
}

Material hair_material(Rgb sigma_a, float beta_m, float beta_n, float alpha) {
  Material m;
  m.kind = MaterialKind::hair;
  m.eta = 1.55f;
  m.hair_sigma_a = sigma_a;
  m.beta_m = beta_m;
  m.beta_n = beta_n;
  m.hair_alpha = alpha;
  return m;
}

RenderOptions options(Strategy st, uint32_t spp, int depth) {
  RenderOptions o;
  o.est.strategy = st;
  o.est.sampler = SamplerKind::independent;
  o.est.spp = spp;
  o.est.seed = 5;
  o.est.max_depth = depth;
  o.threads = 2;
  return o;
}

}  // namespace

TEST(Hair, LoaderReadsPbrtParameters) {
  {  // defaults: eumelanin 1.3 (pbrt-v4's HairMaterial), eta 1.55, beta 0.3, alpha 2
    const Scene s = load_hair("Material \"hair\"\n");
    ASSERT_EQ(s.materials.size(), 1u);
    const Material& m = s.materials[0];
    EXPECT_EQ(m.kind, MaterialKind::hair);
    EXPECT_NEAR(m.hair_sigma_a.r, 1.3f * 0.419f, 1e-6f);
    EXPECT_NEAR(m.hair_sigma_a.g, 1.3f * 0.697f, 1e-6f);
    EXPECT_NEAR(m.hair_sigma_a.b, 1.3f * 1.37f, 1e-6f);
    EXPECT_FLOAT_EQ(m.eta, 1.55f);
    EXPECT_FLOAT_EQ(m.beta_m, 0.3f);
    EXPECT_FLOAT_EQ(m.beta_n, 0.3f);
    EXPECT_FLOAT_EQ(m.hair_alpha, 2.f);
    EXPECT_TRUE(m.approximated_from.empty());
    for (const std::string& w : s.warnings) EXPECT_EQ(w.find("approximated"), std::string::npos) << w;
  }
  {  // sigma_a wins; the other parameters
    const Scene s = load_hair(
        "Material \"hair\" \"rgb sigma_a\" [0.1 0.2 0.3] \"rgb reflectance\" [0.5 0.5 0.5] \"float eta\" 1.4 "
        "\"float beta_m\" 0.2 \"float beta_n\" 0.7 \"float alpha\" 3\n");
    const Material& m = s.materials[0];
    EXPECT_FLOAT_EQ(m.hair_sigma_a.g, 0.2f);
    EXPECT_FLOAT_EQ(m.eta, 1.4f);
    EXPECT_FLOAT_EQ(m.beta_m, 0.2f);
    EXPECT_FLOAT_EQ(m.beta_n, 0.7f);
    EXPECT_FLOAT_EQ(m.hair_alpha, 3.f);
  }
  {  // reflectance: Chiang et al.'s inversion, darker colours absorb more, white absorbs nothing
    const Scene s = load_hair("Material \"hair\" \"rgb reflectance\" [1 0.5 0.1] \"float beta_n\" 0.4\n");
    const Material& m = s.materials[0];
    EXPECT_FLOAT_EQ(m.hair_sigma_a.r, 0.f);
    EXPECT_GT(m.hair_sigma_a.b, m.hair_sigma_a.g);
    EXPECT_FLOAT_EQ(m.hair_sigma_a.g, hair_sigma_a_from_reflectance(0.5f, 0.4f));
    const double d = 5.969 - 0.215 * 0.4 + 2.532 * 0.16 - 10.73 * 0.064 + 5.574 * 0.0256 + 0.245 * 0.01024;
    EXPECT_NEAR(m.hair_sigma_a.g, std::pow(std::log(0.5) / d, 2), 1e-6);
  }
  {  // melanin: pheomelanin alone (eumelanin then 0, not the default)
    const Scene s = load_hair("Material \"hair\" \"float pheomelanin\" 2\n");
    EXPECT_NEAR(s.materials[0].hair_sigma_a.r, 2 * 0.187f, 1e-6f);
    EXPECT_NEAR(s.materials[0].hair_sigma_a.b, 2 * 1.05f, 1e-6f);
  }
}

TEST(Hair, BadParametersNameFileAndLine) {
  const std::string cases[] = {
      "Material \"hair\" \"float beta_m\" 1.5\n",
      "Material \"hair\" \"float beta_n\" -0.1\n",
      "Material \"hair\" \"float eta\" 0\n",
      "Material \"hair\" \"rgb sigma_a\" [0.1 -1 0.2]\n",
      "Material \"hair\" \"rgb reflectance\" [0.1 -1 0.2]\n",
  };
  for (const std::string& c : cases) {
    const std::string e = hair_error(c);
    EXPECT_EQ(e.rfind("h.pbrt:2", 0), 0u) << c << " -> " << e;
  }
}

// Fibers that absorb nothing (sigma_a = 0) of every curve type, bent so that rays meet them
// at every angle, under a uniform sky of radiance 1, paths as deep as Russian roulette lets
// them go: every pixel is 1 with light sampling, BSDF sampling and MIS. The hair BSDF
// conserves energy (test_materials.cpp: to 2e-3), so a pixel darker or brighter than that
// means the frame, the cosine or the weights around the BSDF are wrong. Tolerance: the
// image mean within 1% (its standard error is below 0.1%), no pixel beyond 6 of its
// standard errors + 0.5% (6 sigma over 1024 pixels: a false alarm below 1e-6). Light
// sampling alone (the sky uniform over the sphere against lobes that hold their energy in
// a few per cent of it, where fibers are seen edge-on) gives a pixel most of its value in
// rare samples: at 64 spp some pixels miss them and their sample variance misses them too
// (seen: 16 of 1024 pixels below 0.6 with small standard errors, converging to 1 at 8192
// spp; at 16 spp the image mean was 0.982). It takes 256 spp in every tree, 2% of the
// pixels may be off, and the image mean holds to 1%.
TEST(Hair, WhiteFurnaceIsInvisible) {
  Scene s;
  s.source = "test:hair-furnace";
  s.materials.push_back(hair_material({0, 0, 0}, 0.3f, 0.4f, 2.f));
  s.materials.push_back(hair_material({0, 0, 0}, 0.6f, 0.8f, 0.f));
  Light sky;
  sky.type = LightKind::infinite;
  sky.radiance = {1, 1, 1};
  s.lights.push_back(sky);
  for (int i = 0; i < 9; ++i) {
    Curves c = straight_curve(static_cast<CurveType>(i % 3), 1.2f, -0.8f + 0.2f * i, 0.03f + 0.01f * i);
    c.points[6] = 0.4f;
    c.points[10] = -0.3f;
    c.material = i % 2;
    s.curves.push_back(c);
  }
  s.camera.width = s.camera.height = 32;
  s.camera.fov_deg = 40;
  camera_look_at(s.camera, {0, 0, 4}, {0, 0, 0}, {0, 1, 0});
  finalize_scene(s);
  for (Strategy st : {Strategy::mis, Strategy::light, Strategy::bsdf}) {
    // (light sampling alone: 256 samples in every tree, so that each pixel's rare large
    // samples are seen; the other strategies converge fast)
    const RenderResult r = render_scene(s, options(st, st == Strategy::light ? 256u : scaled(64u, 16u), 64));
    double sum = 0;
    int off = 0;
    const std::vector<float> var = r.film.variance_of_mean();
    const size_t pixels = r.mean.size() / 3;
    for (size_t i = 0; i < pixels; ++i) {
      sum += r.mean[3 * i + 1];
      if (std::abs(r.mean[3 * i + 1] - 1) > 6 * std::sqrt(var[3 * i + 1]) + 5e-3) ++off;
    }
    EXPECT_NEAR(sum / double(pixels), 1.0, 0.01) << "strategy " << int(st);
    EXPECT_LE(off, st == Strategy::light ? int(pixels / 50) : 0) << "strategy " << int(st);
  }
}

// A wide round fiber (radius 0.3, along x) seen head-on, lit by a distant light at 60
// degrees to the view in the plane across the fiber, the fiber's inside absorbing all
// (only the R lobe, reflection at the cuticle): the highlight sits where the fiber's normal
// bisects the view and the light, on the light's side of the fiber's image. The light's side
// is read from a white Lambertian fiber lit the same way (brighter where it faces the
// light). With h's sign flipped, the highlight would sit on the other side.
TEST(Hair, HighlightSitsOnTheSideThatMirrorsTheLight) {
  for (float side : {1.f, -1.f}) {
    double half[2][2] = {{0, 0}, {0, 0}};  // [hair, lambert][upper rows, lower rows]
    for (int which = 0; which < 2; ++which) {
      Scene s;
      s.source = "test:hair-highlight";
      s.materials.push_back(which == 0 ? hair_material({1e3f, 1e3f, 1e3f}, 0.2f, 0.2f, 0.f) : diffuse_material(Rgb{1, 1, 1}, -1));
      Light sun;
      sun.type = LightKind::distant;
      sun.e1 = {0, side * std::sin(float(M_PI / 3)), std::cos(float(M_PI / 3))};
      sun.radiance = {1, 1, 1};
      s.lights.push_back(sun);
      s.curves.push_back(straight_curve(CurveType::cylinder, 3.f, 0.f, 0.3f));
      s.curves.back().material = 0;
      const int res = 48;
      s.camera.width = s.camera.height = res;
      s.camera.fov_deg = 20;
      camera_look_at(s.camera, {0, 0, 4}, {0, 0, 0}, {0, 1, 0});
      finalize_scene(s);
      const RenderResult r = render_scene(s, options(Strategy::mis, scaled(32u, 8u), 1));
      for (int y = 0; y < res; ++y)
        for (int x = 0; x < res; ++x) half[which][y < res / 2 ? 0 : 1] += r.mean[3 * size_t(y * res + x) + 1];
    }
    const int lit = half[1][0] > half[1][1] ? 0 : 1;
    EXPECT_GT(half[1][lit], 1.5 * half[1][1 - lit]) << "lambert, side " << side;
    EXPECT_GT(half[0][lit], 3 * half[0][1 - lit]) << "hair, side " << side << ": " << half[0][0] << " / " << half[0][1];
  }
}
