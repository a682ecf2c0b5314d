// Whole-render properties: determinism across threads and tile sizes, agreement of all
// strategies on a scene with occlusion, finite output, AOVs, camera conventions.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "wave/generate.h"
#include "scene/image_io.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {
Scene cornell(int res) {
  Scene s = builtin_scene("cornell");
  s.camera.width = s.camera.height = res;
  finalize_scene(s);
  return s;
}
}  // namespace

// Tiles of 16 and 32 order their lanes in 4x4 blocks, tiles of 7 and the partial tiles at
// the image's edges in rows: the lane order changes nothing either.
TEST(Render, BitIdenticalForThreadsAndTileSizes) {
  Scene s = load_scene("built-in:two-panels");
  s.camera.width = 97;  // tiles that do not divide the image
  s.camera.height = 61;
  std::vector<std::vector<float>> images;
  for (auto [threads, tile] : {std::pair{1, 16}, std::pair{2, 16}, std::pair{2, 32}, std::pair{1, 7}}) {
    RenderOptions o;
    o.est.spp = 8;
    o.threads = threads;
    o.tile = tile;
    o.est.mode = MisMode::one;
    RenderResult r = render_scene(s, o);
    images.push_back(r.mean);
    // also through the EXR writer: bit-identical files
    const std::string path = ::testing::TempDir() + "det_" + std::to_string(threads) + "_" + std::to_string(tile) + ".exr";
    write_exr(path, r.film.width, r.film.height, r.mean);
    int w, h;
    const std::vector<float> back = read_exr(path, w, h);
    ASSERT_EQ(std::memcmp(back.data(), r.mean.data(), back.size() * sizeof(float)), 0);
  }
  for (size_t i = 1; i < images.size(); ++i)
    ASSERT_EQ(std::memcmp(images[0].data(), images[i].data(), images[0].size() * sizeof(float)), 0) << "config " << i;
}

// A renderer keeps its tile buffers from one render to the next: after a render of other
// samples (other values in every buffer) it gives the bits and counts a fresh one gives,
// with partial tiles, both techniques, the MIS weight AOV and rejected-sample counters.
TEST(Render, ReusedRendererGivesTheSameBits) {
  Scene s = load_scene("built-in:two-panels");
  s.camera.width = 97;
  s.camera.height = 61;
  for (bool bounce_against_emitters : {false, true}) {
    RenderOptions o;
    o.est.spp = 4;
    o.threads = 2;
    o.est.aov_mis_weight = true;
    o.bounce = bounce_against_emitters ? BounceTrace::emitters : BounceTrace::scene;
    Accel accel(s);
    Renderer fresh(s, accel, o), reused(s, accel, o);
    Film a, b, other;
    const RenderStats sa = fresh.render(a, 0, 4);
    const RenderStats so = reused.render(other, 5, 9);
    const RenderStats sb = reused.render(b, 0, 4);
    auto same = [](const auto& x, const auto& y) {
      return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(x[0])) == 0;
    };
    EXPECT_TRUE(same(a.sum, b.sum)) << bounce_against_emitters;
    EXPECT_TRUE(same(a.sum_sq, b.sum_sq)) << bounce_against_emitters;
    EXPECT_TRUE(same(a.w_sum, b.w_sum)) << bounce_against_emitters;
    EXPECT_TRUE(same(a.w_cnt, b.w_cnt)) << bounce_against_emitters;
    EXPECT_TRUE(same(a.max_sample, b.max_sample)) << bounce_against_emitters;
    EXPECT_FALSE(same(a.sum, other.sum));  // the first render did leave other values behind
    // the counters are this render's alone
    EXPECT_EQ(sb.rays_camera, sa.rays_camera);
    EXPECT_EQ(sb.rays_shadow, sa.rays_shadow);
    EXPECT_EQ(sb.rays_bounce, sa.rays_bounce);
    EXPECT_EQ(sb.rays_bounce_visibility, sa.rays_bounce_visibility);
    EXPECT_EQ(sb.rejected_light + sb.rejected_bsdf + sb.rejected_camera,
              sa.rejected_light + sa.rejected_bsdf + sa.rejected_camera);
    EXPECT_GT(so.rays_shadow, 0u);
    EXPECT_EQ(bounce_against_emitters, sa.rays_bounce_visibility > 0);
  }
}

// Every strategy estimates the same integral: on a closed room with occlusion their
// images agree within their standard errors, in 4x4 blocks and overall.
TEST(Render, AllStrategiesAgreeWithOcclusion) {
  Scene s = cornell(32);
  RenderOptions ref_o;
  ref_o.est.sampler = SamplerKind::independent;
  // The sanitizer tree draws 1/TUILE_TEST_SCALE of the samples (tests/test_scale.h), at
  // least 32 per pixel for the reference and 16 for the others: the z-scores below divide by
  // the standard errors of the samples drawn (5096 spp in all took 35 s instrumented).
  ref_o.est.spp = scaled(1024u, 32u);
  ref_o.est.seed = 100;
  const RenderResult ref = render_scene(s, ref_o);
  const std::vector<float> ref_var = ref.film.variance_of_mean();
  struct C {
    Strategy st;
    LightPick pk;
    LightPoint pt;
    Heuristic h;
    MisMode m;
    uint32_t spp;
  };
  const C combos[] = {{Strategy::light, LightPick::uniform, LightPoint::area, Heuristic::power, MisMode::multi, 256},
                      {Strategy::light, LightPick::all, LightPoint::solid_angle, Heuristic::power, MisMode::multi, 256},
                      {Strategy::bsdf, LightPick::power, LightPoint::area, Heuristic::power, MisMode::multi, 4096},
                      {Strategy::mis, LightPick::area, LightPoint::area, Heuristic::balance, MisMode::one, 512},
                      {Strategy::mis, LightPick::power, LightPoint::solid_angle, Heuristic::cutoff, MisMode::multi, 256},
                      {Strategy::mis, LightPick::uniform, LightPoint::area, Heuristic::maximum, MisMode::multi, 256}};
  for (const C& c : combos) {
    RenderOptions o;
    o.est.strategy = c.st;
    o.est.pick = c.pk;
    o.est.point = c.pt;
    o.est.heuristic = c.h;
    o.est.mode = c.m;
    o.est.sampler = SamplerKind::independent;
    o.est.spp = scaled(c.spp, 16u);
    o.est.seed = 5;
    const RenderResult r = render_scene(s, o);
    const std::vector<float> var = r.film.variance_of_mean();
    double d = 0, v = 0;
    int bad_blocks = 0, blocks = 0;
    for (int by = 0; by < 32; by += 8)
      for (int bx = 0; bx < 32; bx += 8) {
        double bd = 0, bv = 0;
        for (int y = by; y < by + 8; ++y)
          for (int x = bx; x < bx + 8; ++x)
            for (int ch = 0; ch < 3; ++ch) {
              const size_t i = 3 * (static_cast<size_t>(y) * 32 + x) + ch;
              bd += r.mean[i] - ref.mean[i];
              bv += var[i] + ref_var[i];
            }
        d += bd;
        v += bv;
        ++blocks;
        if (bv > 0 && std::fabs(bd) > 4.0 * std::sqrt(bv)) ++bad_blocks;
      }
    const double z = d / std::sqrt(v);
    EXPECT_LT(std::fabs(z), 3.0) << describe(o.est);
    // 16 blocks at 4 sigma: a false alarm is rare; a biased strategy fails many
    EXPECT_LE(bad_blocks, 1) << describe(o.est);
  }
}

TEST(Render, OutputIsFiniteAndAovsAreSane) {
  Scene s = cornell(24);
  RenderOptions o;
  o.est.spp = 16;
  {  // no AOV requested: none computed
    const RenderResult plain = render_scene(s, o);
    for (double c : plain.film.w_cnt) ASSERT_EQ(c, 0.0);
  }
  o.aov_mis_weight = true;
  const RenderResult r = render_scene(s, o);
  for (float v : r.mean) ASSERT_TRUE(std::isfinite(v));
  const std::vector<float> var = r.film.variance_of_mean();
  const std::vector<float> w = r.film.mis_weight();
  double mean = 0;
  for (float v : r.mean) mean += v;
  EXPECT_GT(mean, 0.0);
  for (float v : var) ASSERT_TRUE(std::isfinite(v) && v >= 0.f);
  bool some = false;
  for (float x : w) {
    ASSERT_TRUE(x >= 0.f && x <= 1.f);
    some |= x > 0.f && x < 1.f;
  }
  EXPECT_TRUE(some) << "power-heuristic MIS must give fractional BSDF weights somewhere";
}

// Camera conventions (pbrt-v4): fov on the shorter axis, raster y down, +x as set by LookAt.
TEST(Render, CameraConventions) {
  Scene s;
  s.camera.width = 200;
  s.camera.height = 100;
  s.camera.fov_deg = 90;
  camera_look_at(s.camera, {0, 0, 0}, {0, 0, 1}, {0, 1, 0});
  s.materials.push_back({});
  Mesh m;
  m.name = "wall";
  test::add_quad(m, {-10, -10, 5}, {20, 0, 0}, {0, 20, 0});
  s.meshes.push_back(m);
  finalize_scene(s);
  SceneViews v = build_views(s, LightPick::power);
  vec3f o, d;
  camera_ray(v.camera, 100.f, 0.f, o, d);  // top edge centre: 45 degrees up (shorter axis)
  EXPECT_NEAR(d.y / d.z, 1.0, 1e-6);
  EXPECT_NEAR(d.x, 0.0, 1e-6);
  camera_ray(v.camera, 200.f, 50.f, o, d);  // right edge: x = aspect * tan(45)
  EXPECT_NEAR(d.x / d.z, 2.0, 1e-6);
  camera_ray(v.camera, 100.f, 100.f, o, d);  // bottom: raster y down
  EXPECT_NEAR(d.y / d.z, -1.0, 1e-6);
}
