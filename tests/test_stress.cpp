// Stiff and extreme cases (issue "Stiff and extreme cases"): shading points next to a
// light, tiny and very bright sources, 10 000 sources, grazing and tangent-plane sources,
// degenerate and non-finite geometry, scenes far from the origin or very small, MIS at
// extreme pdfs, 10^7 samples in one pixel, solid-angle sampling at its limits, odd cameras
// and empty scenes. Each test states its tolerance; docs/stress.md says what each shows.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "wave/generate.h"
#include "wave/sample_lights.h"
#include "scene/pbrt.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;
namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------------------
// helpers

struct Est {
  Strategy strategy = Strategy::mis;
  LightPick pick = LightPick::power;
  LightPoint point = LightPoint::solid_angle;
  Heuristic heuristic = Heuristic::power;
  MisMode mode = MisMode::multi;
};

RenderOptions options(const Est& e, uint32_t spp, uint32_t seed = 1, SamplerKind s = SamplerKind::independent) {
  RenderOptions o;
  o.est.strategy = e.strategy;
  o.est.pick = e.pick;
  o.est.point = e.point;
  o.est.heuristic = e.heuristic;
  o.est.mode = e.mode;
  o.est.sampler = s;
  o.est.spp = spp;
  o.est.seed = seed;
  o.threads = 2;
  return o;
}

std::string name_of(const RenderOptions& o) { return describe(o.est); }

uint64_t rejected(const RenderStats& s) { return s.rejected_camera + s.rejected_light + s.rejected_bsdf; }

// Every pixel and its variance finite, and no sample thrown away as non-finite.
void expect_clean(const RenderResult& r, const std::string& what) {
  size_t bad = 0;
  for (float v : r.mean) bad += !std::isfinite(v);
  for (float v : r.film.variance_of_mean()) bad += !(std::isfinite(v) && v >= 0.f);
  EXPECT_EQ(bad, 0u) << what << ": non-finite pixels";
  EXPECT_EQ(rejected(r.stats), 0u) << what << ": rejected camera=" << r.stats.rejected_camera
                                   << " light=" << r.stats.rejected_light << " bsdf=" << r.stats.rejected_bsdf;
  EXPECT_TRUE(std::isfinite(r.stats.worst_ratio)) << what;
}

struct Cmp {
  double exact = 0, mean = 0, se = 0;
  double z() const { return se > 0 ? (mean - exact) / se : (mean == exact ? 0.0 : INFINITY); }
  double rel() const { return exact != 0 ? (mean - exact) / exact : mean; }
};

// Image mean (channel 0) against the exact image mean, with the standard error of the
// image mean from the per-pixel variances of the mean.
Cmp compare(const RenderResult& r, const std::vector<double>& exact) {
  const std::vector<float> var = r.film.variance_of_mean();
  Cmp c;
  double v = 0;
  for (size_t i = 0; i < exact.size(); ++i) {
    c.exact += exact[i];
    c.mean += r.mean[3 * i];
    v += var[3 * i];
  }
  const double n = static_cast<double>(exact.size());
  c.exact /= n;
  c.mean /= n;
  c.se = std::sqrt(v) / n;
  return c;
}

std::string show(const Cmp& c) {
  std::ostringstream s;
  s << "mean " << c.mean << " exact " << c.exact << " (rel " << c.rel() << ", " << c.z() << " SE)";
  return s.str();
}

// Unbiased within k standard errors of the image mean, clean, and the standard error
// small enough (relative) that the comparison means something.
void expect_exact(const RenderResult& r, const std::vector<double>& exact, double k, const std::string& what,
                  double max_rel_se = 0.05) {
  expect_clean(r, what);
  const Cmp c = compare(r, exact);
  EXPECT_LT(std::fabs(c.z()), k) << what << ": " << show(c);
  EXPECT_LT(c.se, max_rel_se * std::fabs(c.exact) + 1e-30) << what << ": " << show(c);
}

// Replace plane_scene's 200 x 200 m floor by one of half-size a, centred at (cx, cz).
void set_floor(PlaneScene& p, float a, float cx = 0, float cz = 0) {
  Mesh& f = p.scene.meshes[0];
  f.positions.clear();
  f.indices.clear();
  add_quad(f, {cx - a, 0, cz - a}, {0, 0, 2 * a}, {2 * a, 0, 0});
}

double mean_of(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / static_cast<double>(v.size());
}

const Est light_sa{Strategy::light, LightPick::power, LightPoint::solid_angle, Heuristic::power, MisMode::multi};
const Est light_area{Strategy::light, LightPick::power, LightPoint::area, Heuristic::power, MisMode::multi};
const Est mis_sa{Strategy::mis, LightPick::power, LightPoint::solid_angle, Heuristic::power, MisMode::multi};
const Est mis_area{Strategy::mis, LightPick::power, LightPoint::area, Heuristic::balance, MisMode::multi};
const Est mis_one{Strategy::mis, LightPick::area, LightPoint::solid_angle, Heuristic::balance, MisMode::one};
const Est bsdf_only{Strategy::bsdf, LightPick::power, LightPoint::area, Heuristic::power, MisMode::multi};

std::string source_dir() { return TUILE_SOURCE_DIR; }

// Runs a command, returns its exit status and standard output.
int run_command(const std::string& cmd, std::string& out) {
  out.clear();
  FILE* f = popen((cmd + " 2>/dev/null").c_str(), "r");
  if (!f) return -1;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
  const int st = pclose(f);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

std::string tmp_path(const std::string& name) { return (fs::path(::testing::TempDir()) / name).string(); }

}  // namespace

// =========================================================================================
// 1. A shading point next to a light. A 1 x 1 m source facing down at height h over a
//    4 x 4 m floor; the camera sits between them at h/2 and sees the floor square
//    [-h/2, h/2]^2: half of it under the source, half beside its edge. Every shading
//    point is within h of the source (h = 1e-2 .. 1e-6 of the source's size).
namespace {
PlaneScene near_light(float h) {
  // the view [-0.2 h, 0.8 h] is asymmetric about the edge: for a symmetric one the image
  // mean of a half-plane source does not depend on h and would hide an error in h
  PlaneScene p = plane_scene({0.3f * h, 0.5f * h, 0}, 90, 16);
  set_floor(p, 2);
  add_source_quad(p, {-1, h, -0.5f}, {1, 0, 0}, {0, 0, 1}, 1.f);
  finalize_scene(p.scene);
  return p;
}
}  // namespace

class StressNearLight : public ::testing::TestWithParam<int> {};

// Solid-angle light sampling, MIS (solid angle and area) and cosine sampling are
// unbiased within 3 standard errors at every distance; none rejects a sample.
TEST_P(StressNearLight, SolidAngleAndMisMatchExact) {
  const float h = std::pow(10.f, -static_cast<float>(GetParam()));
  const PlaneScene p = near_light(h);
  const std::vector<double> exact = exact_image(p, 6);
  ASSERT_GT(mean_of(exact), 0.05);
  for (const Est& e : {light_sa, mis_sa, mis_area, mis_one, bsdf_only}) {
    const RenderOptions o = options(e, 256, 3);
    const std::string what = "h=" + std::to_string(h) + " " + name_of(o);
    if (GetParam() <= 4) {
      expect_exact(render_scene(p.scene, o), exact, 3.0, what);
    } else {
      // Below 1e-4 of the source's size float coordinates cannot resolve the geometry:
      // the 1 m source's edge at x = 0 is known to ulp(1) = 1.2e-7 m, 1.2% of h = 1e-5 and
      // 12% of h = 1e-6 (measured errors: 0.9% and 7-12%). Stated tolerance: finite, no
      // rejected sample, mean within 2% (1e-5) or 15% (1e-6) of the exact mean.
      const RenderResult r = render_scene(p.scene, o);
      expect_clean(r, what);
      const Cmp c = compare(r, exact);
      EXPECT_LT(std::fabs(c.rel()), GetParam() == 5 ? 0.02 : 0.15) << what << ": " << show(c);
    }
  }
}

// Area sampling alone: its variance grows like 1/h^2 (the integrand peaks at 1/h^2 on an
// area h^2), so below h = 1e-3 the normal approximation fails at any affordable count.
// It must stay finite with zero rejected samples, and at h = 1e-2 and 1e-3 its mean is
// within 4 SE (heavy tails) of the exact one and the error shrinks with more samples.
TEST_P(StressNearLight, AreaSamplingFiniteAndConverging) {
  const float h = std::pow(10.f, -static_cast<float>(GetParam()));
  const PlaneScene p = near_light(h);
  const std::vector<double> exact = exact_image(p, 6);
  Est e = light_area;
  e.pick = LightPick::all;
  double err_small = 0;
  for (uint32_t spp : {64u, 4096u}) {
    const RenderOptions o = options(e, spp, 9);
    const RenderResult r = render_scene(p.scene, o);
    const std::string what = "h=" + std::to_string(h) + " " + name_of(o);
    expect_clean(r, what);
    const Cmp c = compare(r, exact);
    std::printf("[ near-light area ] h=%g spp=%u %s\n", h, spp, show(c).c_str());
    if (spp == 64) err_small = std::fabs(c.rel());
    else if (GetParam() <= 3) {
      EXPECT_LT(std::fabs(c.z()), 4.0) << what << ": " << show(c);
      EXPECT_LT(std::fabs(c.rel()), std::max(0.5 * err_small, 0.02)) << what << ": " << show(c);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(StressHeights, StressNearLight, ::testing::Range(2, 7),
                         [](const auto& info) { return "h_1e_minus_" + std::to_string(info.param); });

// =========================================================================================
// 2. Tiny and very bright sources, and many of them.
namespace {
PlaneScene tiny_beside_large() {
  // a 1e-4 x 1e-4 m source (area 1e-8) beside a 1 x 1 m one, equal power (radiance 2e8 vs 2)
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  add_source_quad(p, {-1.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  add_source_quad(p, {0.3f, 1, 0.1f}, {1e-4f, 0, 0}, {0, 0, 1e-4f}, 2e8f);
  finalize_scene(p.scene);
  return p;
}
PlaneScene radiance_ratio() {
  // two equal 0.5 x 0.5 m sources of radiance 1e4 and 1e-4
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  add_source_quad(p, {-1.25f, 1, -0.25f}, {0.5f, 0, 0}, {0, 0, 0.5f}, 1e4f);
  add_source_quad(p, {0.75f, 1, -0.25f}, {0.5f, 0, 0}, {0, 0, 0.5f}, 1e-4f);
  finalize_scene(p.scene);
  return p;
}
}  // namespace

// Power, uniform and "all" selection with area or solid-angle points are unbiased within
// 3 SE. Area-proportional selection picks the tiny source once in 1e8 picks: finite and
// clean, but at affordable counts it misses half of the light (an accident, not a bug).
TEST(StressLights, TinySourceBesideLargeOne) {
  const PlaneScene p = tiny_beside_large();
  // the tiny quad is one parallelogram source (finalize_scene's parallelogram match uses a
  // tolerance relative to the edge length only: at x = 0.3 the rounding of the fourth vertex
  // exceeds it and the quad becomes two triangle sources; the light is the same)
  EXPECT_EQ(p.scene.lights.size(), 2u) << "tiny quad not recognised as a parallelogram";
  double tiny_area = 0;
  for (size_t i = 1; i < p.scene.lights.size(); ++i) tiny_area += p.scene.lights[i].area;
  EXPECT_NEAR(tiny_area, 1e-8, 1e-11);
  const std::vector<double> exact = exact_image(p, 6);
  for (LightPick pk : {LightPick::power, LightPick::uniform, LightPick::all})
    for (const Est& base : {light_sa, light_area, mis_sa, mis_area}) {
      Est e = base;
      e.pick = pk;
      const RenderOptions o = options(e, 128, 5);
      expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
    }
  Est e = light_area;
  e.pick = LightPick::area;
  const RenderOptions o = options(e, 64, 5);
  const RenderResult r = render_scene(p.scene, o);
  expect_clean(r, name_of(o));
  EXPECT_LT(compare(r, exact).mean, compare(r, exact).exact * 0.75) << "area pick should miss the tiny source";
}

TEST(StressLights, RadianceRatio1e8) {
  const PlaneScene p = radiance_ratio();
  const std::vector<double> exact = exact_image(p, 6);
  for (LightPick pk : {LightPick::power, LightPick::uniform, LightPick::area, LightPick::all})
    for (const Est& base : {light_sa, mis_sa, mis_area, mis_one}) {
      Est e = base;
      e.pick = pk;
      const RenderOptions o = options(e, 64, 6);
      expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
    }
}

// 10 000 sources of 2 x 2 cm on a 100 x 100 grid 2 m up, radiance spanning two decades
// (as scenes/stress/many-lights.pbrt), built in code so the exact image is known.
TEST(StressLights, TenThousandSources) {
  PlaneScene p = plane_scene({0, 1.5f, 0}, 60, 8);
  for (int m = 0; m < 10; ++m) {
    Mesh mesh;
    mesh.name = "grid" + std::to_string(m);
    mesh.material = 0;
    const float L = 5.f * std::pow(10.f, -2.f * static_cast<float>(m) / 9.f);
    mesh.emission = {L, L, L};
    for (int k = 0; k < 1000; ++k) {
      const int i = m * 10 + k / 100, j = k % 100;
      const vec3f p0{-4.95f + 0.1f * static_cast<float>(i), 2, -4.95f + 0.1f * static_cast<float>(j)};
      add_quad(mesh, p0, {0.02f, 0, 0}, {0, 0, 0.02f});
      p.sources.push_back({{p0, p0 + vec3f{0.02f, 0, 0}, p0 + vec3f{0.02f, 0, 0.02f}, p0 + vec3f{0, 0, 0.02f}}, L});
    }
    p.scene.meshes.push_back(mesh);
  }
  finalize_scene(p.scene);
  double area = 0;
  for (const Light& l : p.scene.lights) area += l.area;
  EXPECT_NEAR(area, 4.0, 1e-3);  // 10 000 x 4 cm^2
  EXPECT_EQ(p.scene.lights.size(), 10000u) << "quads not recognised as parallelograms";
  const std::vector<double> exact = exact_image(p, 2);
  for (LightPick pk : {LightPick::power, LightPick::uniform})
    for (const Est& base : {light_sa, mis_area}) {
      Est e = base;
      e.pick = pk;
      const RenderOptions o = options(e, 256, 8);
      expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
    }
}

TEST(StressLights, ManyLightsFileHasTenThousandSources) {
  Scene s = load_scene(source_dir() + "/scenes/stress/many-lights.pbrt");
  double area = 0;
  for (const Light& l : s.lights) area += l.area;
  EXPECT_NEAR(area, 4.0, 1e-3);
  EXPECT_EQ(s.lights.size(), 10000u) << "quads not recognised as parallelograms";
}

// =========================================================================================
// 3. Grazing: source and receiver nearly coplanar, a source in the tangent plane, behind
//    it, and one crossing it. The floor ends at x = 1.9 so that sources beyond it are
//    seen only along the floor's plane.
namespace {
PlaneScene grazing_base() {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  Mesh& f = p.scene.meshes[0];
  f.positions.clear();
  f.indices.clear();
  add_quad(f, {-2, 0, -2}, {0, 0, 4}, {3.9f, 0, 0});
  return p;
}
// an emitter that is not part of the exact answer (it must contribute nothing)
void add_emitter(PlaneScene& p, vec3f p0, vec3f e1, vec3f e2, float L, bool two_sided = false) {
  Mesh m;
  m.name = "emitter";
  m.material = 0;
  m.emission = {L, L, L};
  m.two_sided = two_sided;
  add_quad(m, p0, e1, e2);
  p.scene.meshes.push_back(m);
}
}  // namespace

// A 1 x 1 source 1 mm above the floor, seen from 1.5 to 2.5 m away: cos at both ends ~5e-4.
TEST(StressGrazing, NearlyCoplanarSource) {
  PlaneScene p = grazing_base();
  add_source_quad(p, {-2, 1e-3f, -0.5f}, {1, 0, 0}, {0, 0, 1}, 1e3f);
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 6);
  ASSERT_GT(mean_of(exact), 0.0);
  for (const Est& e : {light_sa, light_area, mis_sa, mis_area, mis_one}) {
    const RenderOptions o = options(e, 1024, 10);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
  }
}

// Sources exactly in the floor's plane (one- and two-sided), below it facing up, and above
// it facing away: the exact answer is 0 from each, and the image is exactly black.
TEST(StressGrazing, TangentPlaneAndBehindGiveZero) {
  PlaneScene p = grazing_base();
  add_emitter(p, {2, 0, -0.5f}, {0, 0, 1}, {1, 0, 0}, 100.f);               // in the plane, facing up
  add_emitter(p, {2, 0, 1}, {0, 0, 1}, {1, 0, 0}, 100.f, true);             // in the plane, two-sided
  add_emitter(p, {2, -0.5f, -2}, {0, 0, 1}, {1, 0, 0}, 100.f);              // below the plane, facing up
  add_emitter(p, {-0.5f, 1, -0.5f}, {0, 0, 1}, {1, 0, 0}, 100.f);           // above, facing away
  finalize_scene(p.scene);
  ASSERT_EQ(p.scene.lights.size(), 4u);
  for (const Est& e : {light_sa, light_area, mis_sa, mis_area, mis_one, bsdf_only}) {
    for (LightPick pk : {LightPick::power, LightPick::all}) {
      Est e2 = e;
      e2.pick = pk;
      const RenderOptions o = options(e2, 16, 11);
      const RenderResult r = render_scene(p.scene, o);
      expect_clean(r, name_of(o));
      float mx = 0;
      for (float v : r.mean) mx = std::max(mx, v);
      EXPECT_EQ(mx, 0.f) << name_of(o);
    }
  }
}

// A vertical source beyond the floor's edge reaching from 0.5 m below its plane to 0.5 m
// above: only the upper half lights the floor (exact: the polygon clipped to the tangent
// plane).
TEST(StressGrazing, SourceCrossingTheTangentPlane) {
  PlaneScene p = grazing_base();
  add_source_quad(p, {2, -0.5f, -0.5f}, {0, 0, 1}, {0, 1, 0}, 10.f);  // faces -x
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 6);
  ASSERT_GT(mean_of(exact), 0.0);
  for (const Est& e : {light_sa, light_area, mis_sa, mis_area, mis_one, bsdf_only}) {
    const RenderOptions o = options(e, e.strategy == Strategy::bsdf ? 512 : 64, 12);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
  }
}

// =========================================================================================
// 4. Degenerate triangles; NaN and Inf vertices.
TEST(StressDegenerate, DegenerateEmittersAreNotLightsAndRenderFinite) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  Mesh& floor = p.scene.meshes[0];
  add_triangle(floor, {0, 0.2f, 0}, {0, 0.2f, 0}, {1, 0.2f, 0});          // repeated vertex
  add_triangle(floor, {0, 0.1f, 0}, {0.1f, 0.1f, 0}, {0.3f, 0.1f, 0});    // collinear
  add_triangle(floor, {0.2f, 0.3f, 0.1f}, {0.2f, 0.3f, 0.1f}, {0.2f, 0.3f, 0.1f});  // a point
  // a good quad source with degenerate triangles mixed in
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  Mesh& src = p.scene.meshes.back();
  add_triangle(src, {0, 1, 0}, {0.2f, 1, 0}, {0.4f, 1, 0});
  add_triangle(src, {0, 1, 0}, {0, 1, 0}, {0.2f, 1, 0});
  add_triangle(src, {0.1f, 1, 0.1f}, {0.1f, 1, 0.1f}, {0.1f, 1, 0.1f});
  // an emitter made only of degenerate triangles, and a sliver of relative area 1e-9
  Mesh bad;
  bad.name = "degenerate emitter";
  bad.emission = {5, 5, 5};
  add_triangle(bad, {1, 1.5f, 0}, {1.5f, 1.5f, 0}, {2, 1.5f, 0});
  add_triangle(bad, {1, 1.5f, 0}, {1, 1.5f, 0}, {1, 1.5f, 0});
  add_triangle(bad, {1, 1.5f, 0}, {2, 1.5f, 0}, {1.5f, 1.5f, 1e-9f});
  p.scene.meshes.push_back(bad);
  finalize_scene(p.scene);
  EXPECT_EQ(p.scene.lights.size(), 1u);
  for (const Mesh& m : p.scene.meshes)
    for (size_t t = 0; t < m.prim_light.size(); ++t)
      if (t >= 2) {
        EXPECT_EQ(m.prim_light[t], -1) << m.name << " triangle " << t;
      }
  const std::vector<double> exact = exact_image(p, 6);  // the degenerate triangles are invisible
  for (const Est& e : {light_sa, mis_area, mis_one, bsdf_only}) {
    const RenderOptions o = options(e, e.strategy == Strategy::bsdf ? 256 : 64, 13);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
  }
}

TEST(StressDegenerate, PbrtSceneLoadsWithOneLightAndInfoWorks) {
  const std::string path = source_dir() + "/scenes/stress/degenerate.pbrt";
  Scene s = load_scene(path);
  EXPECT_EQ(s.lights.size(), 1u);
  std::string out;
  ASSERT_EQ(run_command(std::string(TUILE_BINARY) + " info " + path, out), 0) << out;
  EXPECT_NE(out.find("lights: 1 "), std::string::npos) << out;
}

TEST(StressDegenerate, NanAndInfVerticesAreRejectedWithFileAndLine) {
  for (const char* bad : {"nan", "NaN", "inf", "-inf", "1e39"}) {
    const std::string text = std::string("WorldBegin\n\nShape \"trianglemesh\" \"point3 P\" [ 0 0 0 1 0 0 ") + bad +
                             " 1 0 ] \"integer indices\" [ 0 1 2 ]\n";
    try {
      Scene s = load_pbrt_string(text, "stress.pbrt", ".");
      finalize_scene(s);
      ADD_FAILURE() << bad << ": no error";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("stress.pbrt:3:"), std::string::npos) << bad << ": " << e.what();
    }
  }
  // a mesh built in code with a NaN vertex: finalize_scene names the mesh and the vertex
  Scene s;
  Mesh m;
  m.name = "code mesh";
  add_triangle(m, {0, 0, 0}, {1, 0, 0}, {0, NAN, 1});
  s.meshes.push_back(m);
  try {
    finalize_scene(s);
    ADD_FAILURE() << "NaN vertex accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("code mesh"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("vertex 2"), std::string::npos) << e.what();
  }
}

// =========================================================================================
// 5. Far from the origin and very small. A 1 m room whose coordinates are multiples of
//    1/128 m, so that translating it by 1e4 or 1e5 m and scaling it by 2^-13 is exact in
//    float: any difference between the images comes from how rays are traced and spawned.
namespace {
void add_box(Mesh& m, vec3f lo, vec3f hi) {
  const vec3f d = hi - lo;
  const vec3f ex{d.x, 0, 0}, ey{0, d.y, 0}, ez{0, 0, d.z};
  add_quad(m, lo, ey, ex);
  add_quad(m, lo + ez, ex, ey);
  add_quad(m, lo, ez, ey);
  add_quad(m, lo + ex, ey, ez);
  add_quad(m, lo, ex, ez);
  add_quad(m, lo + ey, ez, ex);
}

Scene room(vec3f t, float s, int res) {
  auto P = [&](vec3f p) { return p * s + t; };
  auto E = [&](vec3f e) { return e * s; };
  Scene sc;
  sc.source = "test:room";
  sc.materials.push_back(diffuse_material(Rgb{0.73f, 0.73f, 0.73f}, -1));
  sc.materials.push_back(diffuse_material(Rgb{0.65f, 0.05f, 0.05f}, -1));
  Mesh white;
  white.name = "white";
  white.material = 0;
  add_quad(white, P({0, 0, 0}), E({0, 0, 1}), E({1, 0, 0}));
  add_quad(white, P({0, 1, 0}), E({1, 0, 0}), E({0, 0, 1}));
  add_quad(white, P({0, 0, 0}), E({1, 0, 0}), E({0, 1, 0}));
  add_quad(white, P({1, 0, 0}), E({0, 0, 1}), E({0, 1, 0}));
  add_box(white, P({0.5625f, 0, 0.125f}), P({0.8125f, 0.5f, 0.375f}));
  add_box(white, P({0.125f, 0, 0.5f}), P({0.375f, 0.25f, 0.75f}));
  sc.meshes.push_back(white);
  Mesh red;
  red.name = "red";
  red.material = 1;
  add_quad(red, P({0, 0, 0}), E({0, 1, 0}), E({0, 0, 1}));
  sc.meshes.push_back(red);
  Mesh light;
  light.name = "light";
  light.material = 0;
  light.emission = {10, 10, 10};
  add_quad(light, P({0.375f, 0.9921875f, 0.375f}), E({0.25f, 0, 0}), E({0, 0, 0.25f}));
  sc.meshes.push_back(light);
  sc.camera.width = sc.camera.height = res;
  sc.camera.fov_deg = 40;
  camera_look_at(sc.camera, P({0.5f, 0.5f, 1.9375f}), P({0.5f, 0.5f, 0}), {0, 1, 0});
  finalize_scene(sc);
  return sc;
}

struct ImageDiff {
  double rel_mean = 0;     // |mean(b) - mean(a)| / mean(a)
  double worst_block = 0;  // largest |block mean difference| / block mean, 8 x 8 blocks
  double worst_z = 0;      // the same difference in standard errors of the two renders
};
// Moved geometry decorrelates the noise of the two renders, so block differences are
// judged both relative to the block and against the renders' own standard errors.
ImageDiff image_diff(const RenderResult& ra, const RenderResult& rb, int res) {
  const std::vector<float>&a = ra.mean, &b = rb.mean;
  const std::vector<float> va = ra.film.variance_of_mean(), vb = rb.film.variance_of_mean();
  ImageDiff d;
  double sa = 0, sb = 0;
  for (size_t i = 0; i < a.size(); ++i) sa += a[i], sb += b[i];
  d.rel_mean = std::fabs(sb - sa) / sa;
  for (int by = 0; by < res; by += 8)
    for (int bx = 0; bx < res; bx += 8) {
      double ba = 0, bb = 0, v = 0;
      for (int y = by; y < by + 8; ++y)
        for (int x = bx; x < bx + 8; ++x)
          for (int c = 0; c < 3; ++c) {
            const size_t i = 3 * (static_cast<size_t>(y) * res + x) + c;
            ba += a[i];
            bb += b[i];
            v += va[i] + vb[i];
          }
      if (ba > 1e-3 * sa / ((res / 8) * (res / 8))) {
        d.worst_block = std::max(d.worst_block, std::fabs(bb - ba) / ba);
        if (v > 0) d.worst_z = std::max(d.worst_z, std::fabs(bb - ba) / std::sqrt(v));
      }
    }
  return d;
}
}  // namespace

TEST(StressFarAndSmall, MovedAndScaledRoomsMatchTheOriginal) {
  const int res = 32;
  struct Case {
    const char* name;
    vec3f t;
    float s;
    double max_rel_mean, max_block;
  };
  // Stated tolerances: the float spacing at 1e4 is 2^-10 m, at 1e5 2^-7 m (1/128 of the
  // room, a quarter of a pixel here): the geometry itself, camera included, is quantised
  // that coarsely, so edges and contact shadows move by that much (measured: worst 8x8
  // block 10% at 1e5 for every estimator, 0.9% at 1e4). Rendering camera-relative
  // coordinates would remove this; tuile does not do that yet.
  const Case cases[] = {{"1e4", {1e4f, 1e4f, 1e4f}, 1.f, 0.01, 0.03},
                        {"1e5", {1e5f, 1e5f, 1e5f}, 1.f, 0.03, 0.15},
                        {"2^-13", {0, 0, 0}, 1.f / 8192.f, 1e-4, 1e-3}};
  for (const Est& e : {mis_sa, light_area, bsdf_only}) {
    const RenderOptions o = options(e, 64, 21);
    const RenderResult ref = render_scene(room({0, 0, 0}, 1.f, res), o);
    expect_clean(ref, name_of(o));
    for (const Case& c : cases) {
      const RenderResult r = render_scene(room(c.t, c.s, res), o);
      expect_clean(r, std::string(c.name) + " " + name_of(o));
      const ImageDiff d = image_diff(ref, r, res);
      std::printf("[ room %s ] %s: mean rel diff %.3g, worst block %.3g (%.2f SE)\n", c.name, name_of(o).c_str(),
                  d.rel_mean, d.worst_block, d.worst_z);
      EXPECT_LT(d.rel_mean, c.max_rel_mean) << c.name << " " << name_of(o);
      // a block may differ by the stated geometric tolerance or by noise (4.5 SE over 16
      // blocks and three estimators: a false alarm below 1e-3), not by more
      EXPECT_TRUE(d.worst_block < c.max_block || d.worst_z < 4.5)
          << c.name << " " << name_of(o) << ": worst block " << d.worst_block << ", " << d.worst_z << " SE";
    }
  }
}

// The plane scene moved by 1e5 m along x and z: every estimator still matches the exact image.
TEST(StressFarAndSmall, ExactPlaneAt1e5) {
  const float o5 = 1e5f;
  PlaneScene p = plane_scene({o5, 0.5f, o5}, 90, 16);
  set_floor(p, 2, o5, o5);
  add_source_quad(p, {o5 - 0.5f, 1, o5 - 0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 6);
  for (const Est& e : {light_sa, light_area, mis_sa, mis_area, mis_one, bsdf_only}) {
    const RenderOptions o = options(e, e.strategy == Strategy::bsdf ? 256 : 64, 22);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
  }
}

// =========================================================================================
// 6. MIS at extreme pdfs through the light kernels: for sources whose pdfs reach 1e30
//    (a sphere of radius 1e-15), 1e16 (a triangle of side 1e-8), ~1e-12 (a point 1e-6 under
//    a large source, area pdf) and 0 (behind a source), the pdf a sample was drawn with
//    equals the pdf MIS evaluates for the same direction, and the two weights are finite
//    and sum to 1 for every heuristic.
TEST(StressMis, ExtremePdfsThroughLightKernels) {
  auto planar = [](int32_t type, vec3f p0, vec3f e1, vec3f e2) {
    LightGeom<float> g;
    g.type = type;
    g.p0 = p0;
    g.e1 = e1;
    g.e2 = e2;
    g.n = normalize(cross(e1, e2));
    g.area = length(cross(e1, e2)) * (type == lt_triangle ? 0.5f : 1.f);
    g.two_sided = 0;
    light_geom_derive(g);
    return g;
  };
  LightGeom<float> sph;
  sph.type = lt_sphere;
  sph.p0 = {0, 1, 0};
  sph.e1 = {1e-15f, 0, 0};
  sph.e2 = {0, 0, 0};
  sph.n = {0, 0, 0};
  sph.area = 4 * 3.14159265f * 1e-30f;
  sph.two_sided = 0;
  light_geom_derive(sph);
  struct C {
    const char* name;
    LightGeom<float> g;
    vec3f x;
  };
  const C cases[] = {
      {"sphere r=1e-15", sph, {0.3f, 0, 0.2f}},
      {"triangle side 1e-8", planar(lt_triangle, {0.1f, 1, 0}, {0, 0, 1e-8f}, {1e-8f, 0, 0}), {0, 0, 0}},
      {"quad 1e-6 above", planar(lt_parallelogram, {-1, 1e-6f, -0.5f}, {1, 0, 0}, {0, 0, 1}), {-0.2f, 0, 0}},
      {"quad grazing", planar(lt_parallelogram, {5, 1e-3f, -0.5f}, {1, 0, 0}, {0, 0, 1}), {0, 0, 0}},
      {"quad behind", planar(lt_parallelogram, {-0.5f, 1, -0.5f}, {0, 0, 1}, {1, 0, 0}), {0, 0, 0}},
  };
  const vec3f n{0, 1, 0};
  double q_min = INFINITY, q_max = 0;
  for (const C& c : cases)
    for (LightPoint mode : {LightPoint::area, LightPoint::solid_angle})
      for (int i = 0; i < 32; ++i)
        for (int j = 0; j < 32; ++j) {
          const float u1 = (i + 0.5f) / 32, u2 = (j + 0.5f) / 32;
          const LightPointSample<float> s = sample_light_point<kind_all>(mode, c.g, c.x, u1, u2);
          ASSERT_TRUE(std::isfinite(s.pdf_sa) && s.pdf_sa >= 0) << c.name;
          ASSERT_TRUE(std::isfinite(s.wi.x) && std::isfinite(s.wi.y) && std::isfinite(s.wi.z)) << c.name;
          if (s.valid) {
            const float again = pdf_light_point_sa(mode, c.g, c.x, s.wi, s.dist);
            EXPECT_NEAR(again, s.pdf_sa, 1e-5f * s.pdf_sa) << c.name << " mode " << int(mode);
            q_min = std::min(q_min, double(s.pdf_sa));
            q_max = std::max(q_max, double(s.pdf_sa));
          }
          const float q_l = s.valid ? s.pdf_sa : 0.f;
          const float q_b = std::max(0.f, dot(n, s.wi)) / 3.14159265f;
          for (Heuristic h : {Heuristic::balance, Heuristic::power, Heuristic::cutoff, Heuristic::maximum}) {
            const float wl = mis_weight(h, q_l, q_b, MisParams{}), wb = mis_weight(h, q_b, q_l, MisParams{});
            ASSERT_TRUE(std::isfinite(wl) && std::isfinite(wb) && wl >= 0 && wb >= 0) << c.name;
            ASSERT_NEAR(wl + wb, 1.f, 1e-6f) << c.name << " q " << q_l << " " << q_b;
          }
        }
  EXPECT_GT(q_max, 1e28);  // the sphere's pdfs are ~3e29
  EXPECT_GT(q_min, 0.0);
}

// A sphere source of radius 1e-15 m and radiance 1e29 (pdfs ~1e30) lights the floor with
// E = L pi r^2 cos / d^2: the rendered image matches, with no rejected sample.
TEST(StressMis, SphereWithPdf1e30RendersExactly) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 16);
  Sphere s;
  s.center = {0, 1, 0};
  s.radius = 1e-15f;
  s.emission = {1e29f, 1e29f, 1e29f};
  p.scene.spheres.push_back(s);
  finalize_scene(p.scene);
  ASSERT_EQ(p.scene.lights.size(), 1u);
  // exact pixel values by 8 x 8 midpoint quadrature of the smooth floor radiance
  SceneViews v = build_views(p.scene, LightPick::power);
  const int res = p.scene.camera.width;
  std::vector<double> exact(static_cast<size_t>(res) * res);
  for (int py = 0; py < res; ++py)
    for (int px = 0; px < res; ++px) {
      double sum = 0;
      for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j) {
          vec3f o, d;
          camera_ray(v.camera, px + (i + 0.5f) / 8, py + (j + 0.5f) / 8, o, d);
          const double t = -double(o.y) / d.y, x = o.x + t * d.x, z = o.z + t * d.z;
          const double d2 = x * x + 1 + z * z;
          sum += 0.5 / 3.14159265358979 * 1e29 * 3.14159265358979 * 1e-30 / d2 * (1 / std::sqrt(d2));
        }
      exact[static_cast<size_t>(py) * res + px] = sum / 64;
    }
  for (const Est& e : {light_sa, mis_sa}) {
    const RenderOptions o = options(e, 16, 23);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o), 0.01);
  }
  // area sampling of a sphere 1e-15 across whose centre is at y = 1 (float spacing 1e-7):
  // the sampled points collapse to the centre; it must stay finite and clean
  const RenderOptions o = options(light_area, 16, 23);
  const RenderResult r = render_scene(p.scene, o);
  expect_clean(r, name_of(o));
  std::printf("[ sphere 1e-15 area sampling ] %s\n", show(compare(r, exact)).c_str());
}

// =========================================================================================
// 7. 10^7 samples in one pixel, and the film's sums in double.
TEST(StressOnePixel, FilmSumsInDoubleLoseNothing) {
  Film film;
  film.reset(1, 1);
  const uint64_t n = 10000000;
  const float v = 0.1f;
  for (uint64_t i = 0; i < n; ++i) {
    film.sum[0] += v;
    film.sum_sq[0] += double(v) * double(v);
  }
  film.samples = n;
  const std::vector<float> m = film.mean();
  EXPECT_EQ(m[0], v);  // the mean of 10^7 copies of 0.1f is 0.1f to the last bit
  EXPECT_NEAR(film.sum[0] / double(n), double(v), 1e-12);
  const std::vector<float> var = film.variance_of_mean();
  EXPECT_TRUE(var[0] >= 0.f && var[0] < 1e-15f) << var[0];  // a constant has no variance
  // for contrast, a float accumulator is off by far more than 1e-6
  float f = 0;
  for (uint64_t i = 0; i < n; ++i) f += v;
  EXPECT_GT(std::fabs(f / float(n) - v) / v, 1e-3f);
}

TEST(StressOnePixel, TenMillionSamplesMatchExactTo1e6) {
  PlaneScene p = plane_scene({0.2f, 0.5f, 0.1f}, 1, 1);
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  finalize_scene(p.scene);
  const double exact = exact_image(p, 12)[0];
  // Area sampling: its per-sample values carry no systematic float error. (The float
  // solid-angle map of a rectangle is biased by about 1e-6 relative here, measured:
  // 3.8e-7 at 2^20 samples, 1.2e-6 at 2^23; noted in docs/stress.md.)
  Est e = light_sa;
  e.point = LightPoint::area;
  e.pick = LightPick::all;
  RenderOptions o = options(e, 10000000, 31, SamplerKind::sobol);
  o.threads = 1;
  Accel accel(p.scene);
  // one pixel is one tile, which one thread renders: split the sample range in two halves
  // rendered concurrently into two films, then add their double sums
  Film films[2];
  RenderStats stats[2];
  std::thread worker([&] {
    Renderer r(p.scene, accel, o);
    films[1].reset(1, 1);
    stats[1] = r.render(films[1], 5000000, 10000000);
  });
  {
    Renderer r(p.scene, accel, o);
    films[0].reset(1, 1);
    stats[0] = r.render(films[0], 0, 5000000);
  }
  worker.join();
  const uint64_t n = films[0].samples + films[1].samples;
  EXPECT_EQ(n, 10000000u);
  EXPECT_EQ(rejected(stats[0]) + rejected(stats[1]), 0u);
  RenderStats st = stats[0];
  st.seconds = std::max(stats[0].seconds, stats[1].seconds);
  const double mean = (films[0].sum[0] + films[1].sum[0]) / double(n);
  std::printf("[ one pixel ] 1e7 spp in %.2f s: mean %.10g exact %.10g rel %.3g\n", st.seconds, mean, exact,
              (mean - exact) / exact);
  EXPECT_LT(std::fabs(mean - exact) / exact, 1e-6);
}

// =========================================================================================
// 8. Solid-angle sampling at its limits, through whole renders: sources of ~1e-10 sr,
//    sources at the 1e-4 sr and 6.22 sr thresholds of the fallback rule (just inside and
//    just outside), triangles and rectangles. Area, solid-angle and MIS agree with exact.
namespace {
void check_estimators(const PlaneScene& p, const std::string& what) {
  const std::vector<double> exact = exact_image(p, 6);
  ASSERT_GT(mean_of(exact), 0.0) << what;
  for (const Est& e : {light_area, light_sa, mis_sa, mis_one}) {
    const RenderOptions o = options(e, 128, 41);
    expect_exact(render_scene(p.scene, o), exact, 3.0, what + " " + name_of(o));
  }
}
// A square (or a right triangle of the same area) of side s facing down at height 1
// above the point (0, 0, 0); the camera sees a 2 cm patch of floor around it.
PlaneScene small_source(float s, bool triangle, float L) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 2.3f, 8);
  const vec3f p0{-0.5f * s, 1, -0.5f * s};
  if (triangle) {
    const float a = s * std::sqrt(2.f);
    add_source_triangle(p, p0, p0 + vec3f{a, 0, 0}, p0 + vec3f{0, 0, a}, L);
  } else {
    add_source_quad(p, p0, {s, 0, 0}, {0, 0, s}, L);
  }
  finalize_scene(p.scene);
  return p;
}
float omega_at(const Scene& s, vec3f x) {
  SceneViews v = build_views(s, LightPick::power);
  const LightGeom<float> g = gather_light(v.lights, 0);
  return light_solid_angle(g, x);
}
}  // namespace

TEST(StressSolidAngle, TinySources1e10sr) {
  for (bool tri : {false, true}) {
    const PlaneScene p = small_source(1e-5f, tri, 1e10f);
    const float om = omega_at(p.scene, {0, 0, 0});
    EXPECT_GT(om, 0.5e-10f);
    EXPECT_LT(om, 2e-10f);
    check_estimators(p, tri ? "triangle 1e-10 sr" : "rectangle 1e-10 sr");
  }
}

TEST(StressSolidAngle, AtTheMinimumThreshold) {
  for (bool tri : {false, true})
    for (float target : {0.8e-4f, 1.25e-4f}) {
      const PlaneScene p = small_source(std::sqrt(target), tri, 1.f / target);
      // the whole visible patch is on one side of the threshold
      for (vec3f x : {vec3f{0, 0, 0}, vec3f{0.01f, 0, 0.01f}, vec3f{-0.01f, 0, 0.01f}})
        EXPECT_EQ(omega_at(p.scene, x) >= min_sa_sample_omega, target > min_sa_sample_omega) << omega_at(p.scene, x);
      check_estimators(p, std::string(tri ? "triangle" : "rectangle") + " omega " + std::to_string(target));
    }
}

// Near-hemispherical: a large source 1 mm above the floor, the camera between them at a
// distance from the source's edge where the source subtends 6.20 or 6.24 sr.
TEST(StressSolidAngle, NearHemisphericalAtTheMaximumThreshold) {
  const float h = 1e-3f;
  for (bool tri : {false, true})
    for (float target : {6.20f, 6.24f}) {
      auto build = [&](float delta) {
        PlaneScene p = plane_scene({-delta, 0.5f * h, 0}, 90, 16);
        set_floor(p, 3);
        if (tri) add_source_triangle(p, {0, h, -1}, {0, h, 1}, {-2, h, 0}, 1.f);
        else add_source_quad(p, {-2, h, -1}, {2, 0, 0}, {0, 0, 2}, 1.f);
        finalize_scene(p.scene);
        return p;
      };
      float lo = 0, hi = 0.5f;  // bisection on the distance inside the edge
      for (int it = 0; it < 40; ++it) {
        const float mid = 0.5f * (lo + hi);
        const PlaneScene p = build(mid);
        (omega_at(p.scene, {-mid, 0, 0}) < target ? lo : hi) = mid;
      }
      const PlaneScene p = build(lo);
      for (float dx : {-0.5f * h, 0.5f * h})
        EXPECT_EQ(omega_at(p.scene, {-lo + dx, 0, 0}) <= max_sa_sample_omega, target < max_sa_sample_omega);
      const std::string what = std::string(tri ? "triangle" : "rectangle") + " omega " + std::to_string(target);
      const std::vector<double> exact = exact_image(p, 6);
      // Area sampling 1 mm under a 2 m source has a variance ~1/h^2: at affordable counts it
      // misses the peak (an accident, not a bias), so it is only checked to be clean; so is
      // solid-angle sampling above 6.22 sr, where the fallback rule switches to area.
      for (const Est& e : {light_area, light_sa, mis_sa, mis_one}) {
        const RenderOptions o = options(e, 128, 41);
        const RenderResult r = render_scene(p.scene, o);
        const bool area_like = e.point == LightPoint::area || (e.strategy == Strategy::light && target > max_sa_sample_omega);
        if (area_like) {
          expect_clean(r, what + " " + name_of(o));
          std::printf("[ hemispherical, area-like ] %s %s: %s\n", what.c_str(), name_of(o).c_str(),
                      show(compare(r, exact)).c_str());
        } else {
          expect_exact(r, exact, 3.0, what + " " + name_of(o));
        }
      }
    }
}

// =========================================================================================
// 9. Odd cameras and empty scenes.
namespace {
// A closed cube [-1, 1]^3 whose six faces emit L inwards and reflect with albedo rho:
// with direct lighting, every point inside sees L + rho L (rho/pi times pi L).
Scene furnace(float L, float rho) {
  Scene s;
  s.source = "test:furnace";
  s.materials.push_back(diffuse_material(Rgb{rho, rho, rho}, -1));
  Mesh m;
  m.name = "furnace";
  m.material = 0;
  m.emission = {L, L, L};
  add_quad(m, {-1, -1, 1}, {0, 2, 0}, {2, 0, 0});
  add_quad(m, {-1, -1, -1}, {2, 0, 0}, {0, 2, 0});
  add_quad(m, {1, -1, -1}, {0, 0, 2}, {0, 2, 0});
  add_quad(m, {-1, -1, -1}, {0, 2, 0}, {0, 0, 2});
  add_quad(m, {-1, 1, -1}, {2, 0, 0}, {0, 0, 2});
  add_quad(m, {-1, -1, -1}, {0, 0, 2}, {2, 0, 0});
  s.meshes.push_back(m);
  s.camera.width = s.camera.height = 16;
  s.camera.fov_deg = 100;
  camera_look_at(s.camera, {0.1f, -0.2f, 0.3f}, {0.5f, 0.3f, 1}, {0, 1, 0});
  finalize_scene(s);
  return s;
}
}  // namespace

TEST(StressCamera, InsideAFurnaceOfLights) {
  const Scene s = furnace(1.f, 0.5f);
  ASSERT_EQ(s.lights.size(), 6u);
  const std::vector<double> exact(256, 1.5);
  for (const Est& e : {light_sa, light_area, mis_sa, mis_area, mis_one, bsdf_only})
    for (LightPick pk : {LightPick::power, LightPick::all}) {
      Est e2 = e;
      e2.pick = pk;
      const RenderOptions o = options(e2, 64, 51);
      const RenderResult r = render_scene(s, o);
      expect_clean(r, name_of(o));
      const Cmp c = compare(r, exact);
      EXPECT_TRUE(std::fabs(c.rel()) < 1e-3 || std::fabs(c.z()) < 3.0) << name_of(o) << ": " << show(c);
    }
}

// Inside a sphere light (one-sided, emitting outwards): every strategy must give the same
// image; with pbrt's convention the inside is black (no emission towards the inside).
TEST(StressCamera, InsideASphereLightStrategiesAgree) {
  Scene s;
  s.source = "test:inside-sphere";
  s.materials.push_back(diffuse_material(Rgb{0.5f, 0.5f, 0.5f}, -1));
  Sphere sp;
  sp.center = {0, 0, 0};
  sp.radius = 1;
  sp.material = 0;
  sp.emission = {1, 1, 1};
  s.spheres.push_back(sp);
  s.camera.width = s.camera.height = 8;
  camera_look_at(s.camera, {0, 0, 0}, {0, 0, 1}, {0, 1, 0});
  finalize_scene(s);
  std::vector<double> means;
  for (const Est& e : {light_sa, light_area, bsdf_only, mis_sa}) {
    const RenderOptions o = options(e, 16, 52);
    const RenderResult r = render_scene(s, o);
    expect_clean(r, name_of(o));
    double m = 0;
    for (float v : r.mean) m += v;
    means.push_back(m / r.mean.size());
  }
  for (size_t i = 1; i < means.size(); ++i) EXPECT_NEAR(means[i], means[0], 1e-6) << "estimator " << i;
  EXPECT_EQ(means[0], 0.0) << "pbrt: a one-sided emitter seen from behind is black";
}

// A camera lying on the floor, looking up at a large source: it sees only the source's
// emission, never the floor it stands on.
TEST(StressCamera, OnASurface) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 60, 8);
  set_floor(p, 3);
  add_source_quad(p, {-3, 1, -3}, {6, 0, 0}, {0, 0, 6}, 2.f);
  camera_look_at(p.scene.camera, {0.25f, 0, 0.125f}, {0.25f, 1, 0.125f}, {0, 0, 1});
  finalize_scene(p.scene);
  for (const Est& e : {mis_sa, light_area, bsdf_only}) {
    const RenderOptions o = options(e, 8, 53);
    const RenderResult r = render_scene(p.scene, o);
    expect_clean(r, name_of(o));
    for (size_t i = 0; i < r.mean.size(); ++i) ASSERT_NEAR(r.mean[i], 2.f, 1e-6f) << name_of(o) << " value " << i / 3;
  }
}

TEST(StressCamera, OnePixelImage) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 40, 1);
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 8);
  for (const Est& e : {light_sa, mis_area, bsdf_only}) {
    const RenderOptions o = options(e, 4096, 54);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
  }
}

TEST(StressCamera, ZeroSamplesGiveABlackImage) {
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 8);
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  finalize_scene(p.scene);
  Accel accel(p.scene);
  Renderer r(p.scene, accel, options(mis_sa, 0, 1));
  Film film;
  film.reset(8, 8);
  const RenderStats st = r.render(film, 0, 0);
  EXPECT_EQ(film.samples, 0u);
  EXPECT_EQ(st.samples, 0u);
  EXPECT_EQ(st.rays_camera, 0u);
  for (float v : film.mean()) ASSERT_EQ(v, 0.f);
  for (float v : film.variance_of_mean()) ASSERT_EQ(v, 0.f);
  EXPECT_EQ(st.worst_ratio, 0.0);
}

TEST(StressCamera, NoLightAndZeroRadiance) {
  // no emitter at all; an "emitter" of radiance 0; a point light of intensity 0
  for (int k = 0; k < 3; ++k) {
    PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 8);
    if (k == 1) add_emitter(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 0.f);
    if (k == 2) {
      Light l;
      l.type = LightType::point;
      l.p0 = {0, 1, 0};
      p.scene.lights.push_back(l);
    }
    finalize_scene(p.scene);
    EXPECT_EQ(p.scene.lights.size(), k == 2 ? 1u : 0u);
    for (const Est& e : {mis_sa, light_area, bsdf_only, mis_one}) {
      const RenderOptions o = options(e, 4, 55);
      const RenderResult r = render_scene(p.scene, o);
      expect_clean(r, name_of(o));
      for (float v : r.mean) ASSERT_EQ(v, 0.f) << k << " " << name_of(o);
    }
  }
  // a zero-radiance source beside a real one: power selection never picks it
  PlaneScene p = plane_scene({0, 0.5f, 0}, 90, 8);
  add_source_quad(p, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 2.f);
  Light dark;
  dark.type = LightType::point;
  dark.p0 = {0, 1, 0};
  p.scene.lights.push_back(dark);
  finalize_scene(p.scene);
  const std::vector<double> exact = exact_image(p, 6);
  for (LightPick pk : {LightPick::power, LightPick::uniform, LightPick::all}) {
    Est e = mis_sa;
    e.pick = pk;
    const RenderOptions o = options(e, 64, 56);
    expect_exact(render_scene(p.scene, o), exact, 3.0, name_of(o));
  }
}

// =========================================================================================
// 10. Every scene of scenes/stress renders at low resolution without a non-finite or
//     rejected sample, through the library and through `tuile render --stats`.
namespace {
std::vector<std::string> stress_scenes() {
  std::vector<std::string> v;
  for (const auto& e : fs::directory_iterator(source_dir() + "/scenes/stress"))
    if (e.path().extension() == ".pbrt") v.push_back(e.path().string());
  std::sort(v.begin(), v.end());
  return v;
}
}  // namespace

TEST(StressScenes, EachRendersFinite) {
  const std::vector<std::string> files = stress_scenes();
  ASSERT_GE(files.size(), 8u);
  for (const std::string& f : files) {
    Scene s = load_scene(f);
    s.camera.width = s.camera.height = 32;
    for (const Est& e : {mis_sa, light_area, mis_one, bsdf_only}) {
      const RenderOptions o = options(e, 4, 61);
      const RenderResult r = render_scene(s, o);
      expect_clean(r, f + " " + name_of(o));
      double m = 0;
      for (float v : r.mean) m += v;
      if (e.strategy != Strategy::bsdf) {
        EXPECT_GT(m, 0.0) << f << " is black";
      }
    }
  }
}

TEST(StressScenes, CliStatsReportZeroRejected) {
  for (const std::string& f : stress_scenes()) {
    const std::string exr = tmp_path("stress_cli.exr");
    std::string out;
    const std::string cmd = std::string(TUILE_BINARY) + " render " + f +
                            " --res 32x32 --spp 4 --quiet --stats --threads 2 -o " + exr;
    ASSERT_EQ(run_command(cmd, out), 0) << cmd << "\n" << out;
    EXPECT_NE(out.find("rejected_nonfinite camera=0 light=0 bsdf=0"), std::string::npos) << f << "\n" << out;
    // every number printed is finite
    for (const char* key : {"worst_accident ", "mean_variance_of_mean "}) {
      const size_t k = out.find(key);
      ASSERT_NE(k, std::string::npos) << out;
      EXPECT_TRUE(std::isfinite(std::strtod(out.c_str() + k + std::strlen(key), nullptr))) << out;
    }
  }
}

// `--spp 0` is currently read as "not given": the file's spp (or 16) is used. It must at
// least not crash and must write a finite image.
TEST(StressScenes, CliSppZero) {
  // --spp 0 is a clear error (exit 1, a message naming the flag), not a silent default
  const std::string exr = tmp_path("stress_spp0.exr");
  std::string out;
  const std::string cmd = "sh -c '" + std::string(TUILE_BINARY) +
                          " render built-in:cornell --res 8x8 --spp 0 --quiet -o " + exr + " 2>&1'";
  const int rc = run_command(cmd, out);
  EXPECT_NE(rc, 0) << out;
  EXPECT_NE(out.find("--spp must be >= 1"), std::string::npos) << out;
}
