// --bdpt (src/render/bdpt.h): bidirectional path tracing renders the path tracer's mean.
// The room of tests/caustic_room.h holds what its strategies and weights must get right: a
// smooth glass sphere and a mirror (delta vertices on both subpaths, which no join may
// use: their caustics on the walls come from the camera subpath meeting the light and from
// the light subpath joined to the camera alone), a smooth coat over a diffuse base (a delta
// and a rough lobe at one vertex), a glass slab whose faces under its smooth top are rough
// glass (joins through a rough transmission, whose adjoint carries no 1 / eta^2) and the
// light, one-sided, on the ceiling; then the same with shading normals (a faceted ball with
// vertex normals), a sphere source and the triangle filter (splats over several pixels),
// and with a two-sided source. The means are compared over independent seeds, quarter by
// quarter and channel by channel, against the path tracer's (without light paths); sources
// at infinity against the exact image of a floor under a sun and a sky, and in a room open
// to a sky with a map and a sun. Also: the same bits on any thread count, and what it
// refuses.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <random>
#include <stdexcept>
#include <vector>

#include "app/cli.h"
#include "caustic_room.h"
#include "media_util.h"
#include "output_files.h"
#include "render/bdpt.h"
#include "render/bdpt_mis.h"
#include "render/options.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

RenderOptions bdpt_options(bool bdpt, uint32_t spp, uint32_t seed, int depth = 6) {
  RenderOptions o = independent_options(Strategy::mis, LightPick::power, MisMode::multi, depth, spp, seed);
  o.est.bdpt = bdpt;
  return o;
}

}  // namespace

// The weights bdpt runs (from each subpath vertex's prefix sum, constant time a join) are
// pbrt-v4's walk over the path's vertices, on random densities (zeros among them), delta
// vertices anywhere but at the join, and every split of paths up to 14 vertices.
TEST(Bdpt, WeightsFromPrefixSumsAreTheWalks) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  auto density = [&] { return u(rng) < 0.1f ? 0.f : std::exp(u(rng) * 6.f - 3.f); };
  int checked = 0;
  for (int trial = 0; trial < 4000; ++trial)
    for (int s = 0; s <= 7; ++s)
      for (int t = 1; t <= 7; ++t) {
        if (s + t < 2 || (s == 1 && t == 1)) continue;
        std::vector<BdptPd> l(static_cast<size_t>(s)), c(static_cast<size_t>(t));
        for (BdptPd& v : l) v = {density(), density(), u(rng) < 0.3f};
        for (BdptPd& v : c) v = {density(), density(), u(rng) < 0.3f};
        c[0] = {0.f, 0.f, false};  // the camera
        if (s > 0) l[static_cast<size_t>(s - 1)].delta = false;  // the join's own vertices
        c[static_cast<size_t>(t - 1)].delta = false;
        const float walk = bdpt_mis_walk(l.data(), s, c.data(), t);
        // the prefix sums as the subpaths keep them (the join changes only the last two)
        std::vector<float> pl(static_cast<size_t>(s)), pc(static_cast<size_t>(t), 0.f);
        for (int k = 0; k < s; ++k)
          pl[static_cast<size_t>(k)] = bdpt_prefix(k > 0 ? pl[static_cast<size_t>(k - 1)] : 0.f, l[static_cast<size_t>(k)],
                                                   k > 0 && l[static_cast<size_t>(k - 1)].delta);
        for (int k = 1; k < t; ++k)
          pc[static_cast<size_t>(k)] = bdpt_prefix(pc[static_cast<size_t>(k - 1)], c[static_cast<size_t>(k)], c[static_cast<size_t>(k - 1)].delta);
        auto side = [](const std::vector<BdptPd>& v, const std::vector<float>& p, int n) {
          BdptSide d{n, 0.f, 0.f, 0.f, 0.f, false, false, 0.f};
          if (n >= 1) d.fwd1 = v[static_cast<size_t>(n - 1)].fwd, d.rev1 = v[static_cast<size_t>(n - 1)].rev;
          if (n >= 2) {
            d.fwd2 = v[static_cast<size_t>(n - 2)].fwd;
            d.rev2 = v[static_cast<size_t>(n - 2)].rev;
            d.delta2 = v[static_cast<size_t>(n - 2)].delta;
          }
          if (n >= 3) {
            d.delta3 = v[static_cast<size_t>(n - 3)].delta;
            d.prefix3 = p[static_cast<size_t>(n - 3)];
          }
          return d;
        };
        const float fast = bdpt_mis(side(l, pl, s), side(c, pc, t));
        ASSERT_NEAR(fast, walk, 2e-5f * std::max(walk, 1e-3f)) << "s " << s << " t " << t << " trial " << trial;
        ++checked;
      }
  EXPECT_GT(checked, 100000);
}

TEST(Bdpt, RendersThePathTracersMean) {
  const Scene s = caustic_room(24);
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(24)), 0),
                              bdpt_options(false, static_cast<uint32_t>(scaled(96)), 0), 24, "bdpt, caustic room");
}

TEST(Bdpt, RendersThePathTracersMeanWithShadingNormalsASphereSourceAndATriangleFilter) {
  const Scene s = caustic_room(24, true, true, true);
  RenderOptions with = bdpt_options(true, static_cast<uint32_t>(scaled(24)), 0),
                without = bdpt_options(false, static_cast<uint32_t>(scaled(96)), 0);
  with.filter = without.filter = default_filter(FilterKind::triangle);
  expect_same_mean_over_seeds(s, with, without, 24, "bdpt, shading normals, triangle filter");
}

TEST(Bdpt, RendersThePathTracersMeanUnderATwoSidedSourceAtDepthThree) {
  Scene s = caustic_room(20, false, false);
  for (Mesh& m : s.meshes)
    if (m.name == "light") {  // lowered into the room, lighting the ceiling too
      m.two_sided = true;
      for (size_t k = 1; k < m.positions.size(); k += 3) m.positions[k] = 1.6f;
    }
  finalize_scene(s);
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(24)), 0, 3),
                              bdpt_options(false, static_cast<uint32_t>(scaled(96)), 0, 3), 24, "bdpt, two-sided source");
}

// Light that enters a glass slab by its smooth top and leaves by its bottom, seen from
// below: the light subpath's throughput carries the entry's etap^2 (the adjoint has no
// 1 / eta^2), and where the bottom is rough glass, so do its joins through that face (to
// the camera and to the camera subpath's vertices). Without either the light subpath's
// share of this image is 2.25 times too dark.
TEST(Bdpt, RendersThePathTracersMeanThroughAGlassSlab) {
  Scene s = glass_slab_scene();
  for (Mesh& m : s.meshes)  // a smaller light of the same power: the light subpaths' share grows
    if (m.emission.r > 0) {
      for (size_t k = 0; k < m.positions.size(); k += 3) {
        m.positions[k] *= 0.3f;
        m.positions[k + 2] *= 0.3f;
      }
      m.emission = {44.f, 44.f, 44.f};
    }
  finalize_scene(s);
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(128)), 0),
                              bdpt_options(false, static_cast<uint32_t>(scaled(512)), 0), 24, "bdpt, glass slab");
  Scene rough = s;
  Material glass;
  glass.kind = MaterialKind::dielectric;
  glass.eta = 1.5f;
  glass.alpha_u.value = glass.alpha_v.value = 0.3f;
  rough.materials[2] = glass;
  finalize_scene(rough);
  expect_same_mean_over_seeds(rough, bdpt_options(true, static_cast<uint32_t>(scaled(128)), 0),
                              bdpt_options(false, static_cast<uint32_t>(scaled(512)), 0), 24, "bdpt, rough glass slab");
}

// Point and spot sources (delta lights: y0 on no surface, no strategy that meets them from
// the camera's side, the spot's falloff in its emission and its joins) beside the area light.
// The room's smooth glass, mirror and coat made rough: their caustics of a point source are
// bdpt's light subpaths' alone (no path tracer's sample meets a point through a delta lobe),
// so with them the path tracer's image is no reference (bdpt's is 2% brighter where the
// glass ball's caustics fall).
TEST(Bdpt, RendersThePathTracersMeanUnderPointAndSpotSources) {
  Scene s = caustic_room(20, false, false);
  for (Material& m : s.materials)
    if (m.kind != MaterialKind::diffuse) m.alpha_u.value = m.alpha_v.value = std::max(m.alpha_u.value, 0.3f);
  s.lights.push_back(point_light({-0.9f, 1.6f, 0.4f}, {0.6f, 0.5f, 0.4f}));
  s.lights.push_back(spot_light({0.8f, 1.8f, 0.8f}, {-0.5f, -1, -0.6f}, std::cos(0.3f), std::cos(0.5f), {2, 2, 2.5f}));
  finalize_scene(s);
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(48)), 0, 4),
                              bdpt_options(false, static_cast<uint32_t>(scaled(192)), 0, 4), 24, "bdpt, point and spot");
}

// Sources at infinity: a floor seen from above under a distant source and a constant sky,
// direct light alone (depth 1: the camera subpath meeting the sky, the sources' samples from
// the floor, the light subpaths from the bounding sphere's disc joined to the camera). The
// exact image: rho / pi E cos(theta) from the sun, rho L from the sky (nothing above the
// floor hides any of it). Each quarter and channel over 12 seeds within 5 standard errors
// (t statistic, 11 degrees of freedom: 12 tests, a false alarm once in some 3,000 runs; the
// spread is small: the sun's samples are exact, the sky's nearly). With the skies' density
// three times what it is in the escaped rays' weights, z reaches -27. (The light subpaths'
// share of this image is tiny; the next test weighs them.)
TEST(Bdpt, FloorUnderASunAndASkyIsExact) {
  PlaneScene p = plane_scene({0.2f, 0.7f, -0.1f}, 70, 16, 0.6f);
  Light sky;
  sky.type = LightKind::infinite;
  sky.radiance = {0.3f, 0.4f, 0.5f};
  p.scene.lights.push_back(sky);
  const vec3f towards = normalize(vec3f{0.3f, 1, -0.4f});
  p.scene.lights.push_back(distant_light(towards, {2, 2, 2}));
  finalize_scene(p.scene);
  const std::vector<double> sun = floor_pixel_means(p.scene, 8, [&](double, double, double) {
    return 0.6 / 3.14159265358979323846 * 2 * towards.y;
  });
  std::vector<float> exact;
  for (const double e : sun)
    for (const float L : {sky.radiance.r, sky.radiance.g, sky.radiance.b}) exact.push_back(static_cast<float>(e + 0.6 * L));
  const std::vector<double> q = quarter_means(p.scene, exact);
  Accel accel(p.scene);
  RenderOptions o = bdpt_options(true, static_cast<uint32_t>(scaled(16)), 0, 1);
  const int seeds = 12;
  std::vector<std::vector<double>> runs;
  for (int k = 0; k < seeds; ++k) {
    o.est.seed = static_cast<uint32_t>(k + 1);
    runs.push_back(quarter_means(p.scene, render_mean(p.scene, accel, o, o.est.spp)));
  }
  for (size_t i = 0; i < q.size(); ++i) {
    double m = 0, v = 0;
    for (const auto& r : runs) m += r[i] / seeds;
    for (const auto& r : runs) v += (r[i] - m) * (r[i] - m) / (seeds - 1);
    const double se = std::max(std::sqrt(v / seeds), 1e-4 * q[i]);  // (midpoint quadrature ~1e-4)
    const double z = (m - q[i]) / se;
    std::printf("[ bdpt, floor under a sun and a sky ] quarter %zu channel %zu: %.5f, exact %.5f (z %.2f)\n", i / 3, i % 3, m,
                q[i], z);
    EXPECT_LT(std::abs(z), 5.0) << "quarter " << i / 3 << " channel " << i % 3;
  }
}

// An open room under a sky with an environment map (a bright patch, its frame turned), a
// sun through the open ceiling and the area light: the room's light through the opening
// arrives by every strategy, the light subpaths starting on the disc round the scene. Its
// smooth surfaces made rough, as for point sources: the path tracer has no sample of a
// sun's caustics through a delta lobe, so only then is its image the reference. With the
// light subpaths from the disc carrying 0.7 of their weight, z reaches -15; with the first
// vertex's density from the disc taken as a point's (over d^2), -42.
TEST(Bdpt, RendersThePathTracersMeanUnderASkyAndASun) {
  Scene s = caustic_room(20, false, false);
  s.meshes.erase(std::remove_if(s.meshes.begin(), s.meshes.end(), [](const Mesh& m) { return m.name == "ceiling"; }),
                 s.meshes.end());
  for (Material& m : s.materials)
    if (m.kind != MaterialKind::diffuse) m.alpha_u.value = m.alpha_v.value = std::max(m.alpha_u.value, 0.3f);
  RgbImage img;
  img.width = img.height = 8;
  for (int t = 0; t < 64; ++t)
    for (int c = 0; c < 3; ++c) img.rgb.push_back((t == 19 || t == 27 ? 6.f : 0.2f) * (1.f + 0.2f * static_cast<float>(c)));
  add_map_sky(s, img, {0.5f, 0.5f, 0.5f}, {1, 0.2f, 0});
  s.lights.push_back(distant_light({0.3f, 1, -0.4f}, {1.5f, 1.4f, 1.2f}));
  finalize_scene(s);
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(48)), 0, 4),
                              bdpt_options(false, static_cast<uint32_t>(scaled(192)), 0, 4), 24, "bdpt, sky and sun");
}

// An emitter with an alpha cut-out (a constant 0.5: the rays that meet it pass half the
// time, and its points emit half): the light subpaths' points and the s = 1 joins' weigh
// their emission by the alpha, as the path tracer's light samples do. Without it, z reaches
// 108 on the floor's quarters.
TEST(Bdpt, RendersThePathTracersMeanUnderACutOutEmitter) {
  Scene s = caustic_room(20, false, false);
  for (Mesh& m : s.meshes)
    if (m.name == "light") m.alpha.value = 0.5f;
  finalize_scene(s);
  ASSERT_EQ(bdpt_refusal(s), "");
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(24)), 0),
                              bdpt_options(false, static_cast<uint32_t>(scaled(96)), 0), 24, "bdpt, cut-out emitter");
}

// Media: the caustic room in a fog inside an interface box (the light in it, the glass ball's
// outside fog, the camera outside the box: its joins to vertices in the fog cross the
// interface), then with the camera inside the fog and the glass ball full of a medium that
// absorbs, scatters and emits (its emission gathered along the camera subpath's rays, s = 0).
TEST(Bdpt, RendersThePathTracersMeanInMedia) {
  const Scene s = caustic_fog_room(20, {0.4f, 0.35f, 0.3f});
  ASSERT_EQ(bdpt_refusal(s), "");
  expect_same_mean_over_seeds(s, bdpt_options(true, static_cast<uint32_t>(scaled(32)), 0, 5),
                              bdpt_options(false, static_cast<uint32_t>(scaled(128)), 0, 5), 24, "bdpt, fog");
  Scene in = caustic_fog_room(20, {0.5f, 0.3f, 0.2f}, true);
  in.media.push_back(homogeneous({0.6f, 0.4f, 0.2f}, {0.5f, 0.5f, 0.5f}, -0.3f, {1.5f, 1.f, 0.5f}));
  for (Sphere& sp : in.spheres) sp.medium_inside = 1;
  finalize_scene(in);
  ASSERT_EQ(bdpt_refusal(in), "");
  expect_same_mean_over_seeds(in, bdpt_options(true, static_cast<uint32_t>(scaled(32)), 0, 5),
                              bdpt_options(false, static_cast<uint32_t>(scaled(128)), 0, 5), 24,
                              "bdpt, camera in a fog, an emitting ball");
}

TEST(Bdpt, SameBitsOnAnyThreadCount) {
  expect_same_bits_on_any_thread_count(caustic_room(20), bdpt_options(true, 6, 5), bdpt_options(false, 6, 5), 6);
}

// An image of more than 2^20 pixels, 1280 tiles of 32: its splats are added group by group
// (Renderer::trace_light_paths: 1024 tiles a group on 2 threads, all 1280 at once on 160),
// every tile's once and in tile order, so the same bits. (A tile left out of a group, or
// added twice, differs; the order itself rarely shows at 1 spp, where a pixel's few float
// splats sum exactly in double.)
TEST(Bdpt, SameBitsInGroupsOfTilesAsAllAtOnce) {
  Scene s = caustic_room(16, false, false);
  s.camera.width = 1280;
  s.camera.height = 1024;
  finalize_scene(s);
  Accel accel(s);
  RenderOptions o = bdpt_options(true, 1, 3, 2);
  o.est.sampler = SamplerKind::sobol;
  o.tile = 32;
  o.threads = 2;
  const std::vector<float> groups = render_mean(s, accel, o, 1);
  o.threads = 160;
  const std::vector<float> one = render_mean(s, accel, o, 1);
  ASSERT_EQ(groups.size(), one.size());
  size_t differ = 0, lit = 0;
  for (size_t i = 0; i < one.size(); ++i) {
    differ += groups[i] != one[i];
    lit += one[i] > 0.f;
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(lit, one.size() / 2);
}

// The default, auto: bdpt where the scene file asks for pbrt's bdpt, bdpt renders the scene
// and no option of the path tracer's is given; the flag overrides the file either way.
TEST(Bdpt, AutoIsOnWhereTheFileAsksForIt) {
  Scene s = caustic_room(16);
  s.file_integrator = "bdpt";
  s.file_max_depth = 5;
  s.file_regularize = true;
  const RenderFlags plain;
  const RenderOptions o = resolve_options(plain, s);
  EXPECT_TRUE(o.est.bdpt);
  EXPECT_FALSE(o.est.regularize);  // (the file's regularize is the path tracer's)
  EXPECT_FALSE(o.est.light_paths);
  RenderFlags f;
  f.bdpt = "off";
  EXPECT_FALSE(resolve_options(f, s).est.bdpt);
  f = RenderFlags{};
  f.guide = true;
  EXPECT_FALSE(resolve_options(f, s).est.bdpt);
  f = RenderFlags{};
  f.light_paths = "on";
  EXPECT_FALSE(resolve_options(f, s).est.bdpt);
  f = RenderFlags{};
  f.bdpt = "sometimes";
  EXPECT_THROW(resolve_options(f, s), std::invalid_argument);
  Scene path = s;
  path.file_integrator = "path";
  EXPECT_FALSE(resolve_options(plain, path).est.bdpt);
  f = RenderFlags{};
  f.bdpt = "on";
  EXPECT_TRUE(resolve_options(f, path).est.bdpt);
  // a medium: bdpt's, without the segment light samples (its own strategies sample it)
  Scene fog = caustic_fog_room(16, {0.3f, 0.3f, 0.3f}, true);
  fog.file_integrator = "bdpt";
  EXPECT_EQ(bdpt_refusal(fog), "");
  EXPECT_EQ(bdpt_refusal(s), "");
  EXPECT_TRUE(resolve_options(plain, fog).est.bdpt);
  EXPECT_FALSE(resolve_options(plain, fog).est.equiangular);
  // a sky with the camera in the medium: the path tracer renders the file (with a warning)
  Scene fog_sky = fog;
  fog_sky.lights.push_back(distant_light({0.3f, 1, -0.4f}, {1, 1, 1}));
  finalize_scene(fog_sky);
  EXPECT_NE(bdpt_refusal(fog_sky), "");
  EXPECT_FALSE(resolve_options(plain, fog_sky).est.bdpt);
  // a distant source and a sky: bdpt's
  Scene sun = caustic_room(16, false, false);
  sun.lights.push_back(distant_light({0.3f, 1, -0.4f}, {1, 1, 1}));
  finalize_scene(sun);
  sun.file_integrator = "bdpt";
  EXPECT_EQ(bdpt_refusal(sun), "");
  EXPECT_TRUE(resolve_options(plain, sun).est.bdpt);
}

// `tuile info` says what bdpt runs: its pipeline, the sources its light subpaths start from,
// and not the path tracer's picker or pipeline.
TEST(Bdpt, InfoSaysWhatItRuns) {
  tuile::testing::TempDir dir;
  const std::string scene = dir / "bdpt-sky.pbrt";
  std::ofstream(scene) << "LookAt 0 1 4  0 0.5 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 45 ]\n"
                          "Integrator \"bdpt\" \"integer maxdepth\" [ 5 ]\nWorldBegin\n"
                          "LightSource \"infinite\" \"rgb L\" [ 0.2 0.2 0.2 ]\n"
                          "LightSource \"distant\" \"point3 to\" [ 0 -1 0 ] \"rgb L\" [ 1 1 1 ]\n"
                          "LightSource \"point\" \"point3 from\" [ 0 2 0 ] \"rgb I\" [ 1 1 1 ]\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -2 0 -2  2 0 -2  2 0 2  -2 0 2 ] "
                          "\"integer indices\" [ 0 2 1  0 3 2 ]\n";
  const tuile::testing::CmdResult r = tuile::testing::run_command(TUILE_BINARY, "info " + scene);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("bdpt=on"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("pipeline: bdpt"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("bdpt: 3 source(s) with power"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 area, 1 point or spot, 1 distant, 1 sky"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("start on a disc of radius 2.828"), std::string::npos) << r.out;  // (a 4 x 4 m floor: 2 sqrt 2)
  EXPECT_EQ(r.out.find("light picker:"), std::string::npos) << r.out;
  const tuile::testing::CmdResult off = tuile::testing::run_command(TUILE_BINARY, "info " + scene + " --bdpt=off");
  ASSERT_EQ(off.code, 0) << off.out;
  EXPECT_EQ(off.out.find("pipeline: bdpt"), std::string::npos) << off.out;
  EXPECT_NE(off.out.find("light picker:"), std::string::npos) << off.out;
  EXPECT_EQ(r.out.find("media:"), std::string::npos) << r.out;
  // in a medium: the flights said
  const std::string fog = dir / "bdpt-fog.pbrt";
  std::ofstream(fog) << "LookAt 0 1 4  0 0.5 0  0 1 0\n"
                        "MakeNamedMedium \"fog\" \"string type\" \"homogeneous\" \"rgb sigma_a\" [ 0.1 0.1 0.1 ] "
                        "\"rgb sigma_s\" [ 0.5 0.5 0.5 ]\nMediumInterface \"fog\" \"fog\"\n"
                        "Camera \"perspective\" \"float fov\" [ 45 ]\n"
                        "Integrator \"bdpt\" \"integer maxdepth\" [ 5 ]\nWorldBegin\nMediumInterface \"fog\" \"fog\"\n"
                        "LightSource \"point\" \"point3 from\" [ 0 2 0 ] \"rgb I\" [ 1 1 1 ]\n"
                        "Shape \"trianglemesh\" \"point3 P\" [ -2 0 -2  2 0 -2  2 0 2  -2 0 2 ] "
                        "\"integer indices\" [ 0 2 1  0 3 2 ]\n";
  const tuile::testing::CmdResult m = tuile::testing::run_command(TUILE_BINARY, "info " + fog);
  ASSERT_EQ(m.code, 0) << m.out;
  EXPECT_NE(m.out.find("pipeline: bdpt"), std::string::npos) << m.out;
  EXPECT_NE(m.out.find("media: every ray's free flight on both subpaths"), std::string::npos) << m.out;
}

TEST(Bdpt, RefusesWhatItCannotDo) {
  RenderOptions o = bdpt_options(true, 4, 0);
  o.est.guide = true;
  EXPECT_THROW(validate(o), std::invalid_argument);
  o = bdpt_options(true, 4, 0);
  o.est.light_paths = true;
  EXPECT_THROW(validate(o), std::invalid_argument);
  o = bdpt_options(true, 4, 0);
  o.aov_variance = true;
  EXPECT_THROW(validate(o), std::invalid_argument);
  EXPECT_NO_THROW(validate(bdpt_options(true, 4, 0)));
  // a part of the tiles (a distributed render) without its light chunks apart
  const Scene s = caustic_room(16);
  {
    Accel accel(s);
    Renderer r(s, accel, bdpt_options(true, 4, 0));
    Film f;
    f.reset(16, 16);
    const std::vector<int> tiles{0};
    EXPECT_THROW(r.render(f, 0, 4, nullptr, &tiles), std::invalid_argument);
  }
  auto refused = [](Scene sc) {
    finalize_scene(sc);
    Accel accel(sc);
    try {
      Renderer r(sc, accel, bdpt_options(true, 4, 0));
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  // a source at infinity with the camera in a medium
  Scene fog = caustic_fog_room(16, {0.3f, 0.3f, 0.3f}, true);
  fog.lights.push_back(distant_light({0.3f, 1, -0.4f}, {1, 1, 1}));
  EXPECT_NE(refused(fog).find("the camera sits in a medium"), std::string::npos);
  EXPECT_EQ(refused(caustic_fog_room(16, {0.3f, 0.3f, 0.3f}, true)), "");
}
