// Every scene of scenes/ and of ../shared/scenes renders with no error and a finite,
// non-black image; the shared cornell-box agrees with a high-sample reference made by
// tuile (skipped with a message when ../shared/scenes is absent).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <utility>

#include "render_util.h"
#include "render/light_paths.h"

namespace fs = std::filesystem;
using namespace tuile;
using namespace tuile::test;

namespace {
std::vector<fs::path> pbrt_files(const fs::path& dir) {
  std::vector<fs::path> out;
  if (!fs::exists(dir)) return out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().extension() == ".pbrt" && e.path().string().find("/tools/") == std::string::npos)
      out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

RenderResult small_render(const std::string& path, uint32_t spp, int res, uint32_t seed = 1) {
  Scene s = load_scene(path);
  const float aspect = static_cast<float>(s.camera.width) / static_cast<float>(s.camera.height);
  s.camera.width = res;
  s.camera.height = std::max(1, static_cast<int>(std::lround(res / aspect)));
  RenderOptions o;
  o.est.spp = spp;
  o.est.seed = seed;
  o.est.sampler = SamplerKind::independent;
  // the file's depth, and --light-paths as auto chooses it (sun-window's light comes in
  // through glass alone)
  o.est.max_depth = std::max(1, std::min(s.file_max_depth, 8));
  const LightPathsPay pay = o.est.max_depth >= 2 ? light_paths_pay(s, true) : LightPathsPay::no;
  o.est.light_paths = pay != LightPathsPay::no;
  o.est.light_paths_glossy = pay == LightPathsPay::glossy;
  return render_scene(s, o);
}

void expect_sane(const RenderResult& r, const std::string& what) {
  double sum = 0;
  for (float v : r.mean) {
    ASSERT_TRUE(std::isfinite(v)) << what;
    sum += v;
  }
  EXPECT_GT(sum, 0.0) << what << ": black image";
  EXPECT_EQ(r.stats.rejected_camera + r.stats.rejected_light + r.stats.rejected_bsdf, 0u) << what;
}
}  // namespace

TEST(SceneRender, ProjectScenes) {
  const auto files = pbrt_files(fs::path(TUILE_SOURCE_DIR) / "scenes");
  ASSERT_GE(files.size(), 10u);
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    expect_sane(small_render(f.string(), 2, 32), f.string());
  }
  for (const fs::path& f : pbrt_files(fs::path(TUILE_SOURCE_DIR) / "bench")) {
    SCOPED_TRACE(f.string());
    expect_sane(small_render(f.string(), 2, 32), f.string());
  }
}

TEST(SceneRender, SharedScenes) {
  const fs::path dir = TUILE_SHARED_SCENES;
  if (!fs::exists(dir)) GTEST_SKIP() << "../shared/scenes is absent: shared-scene renders skipped";
  int n = 0;
  for (const char* name : {"cornell-box", "veach-mis", "staircase2", "kitchen"}) {
    const fs::path f = dir / name / "scene-v4.pbrt";
    if (!fs::exists(f)) continue;
    SCOPED_TRACE(f.string());
    expect_sane(small_render(f.string(), 2, 48), f.string());
    ++n;
  }
  EXPECT_GT(n, 0);
}

// The shared cornell-box at 64 spp against a 2048 spp reference rendered by tuile with
// another seed: the image means agree within 3 standard errors and no 8x8 block is off by
// more than 4.5 (the per-block false-alarm rate over the blocks is below 1e-3).
TEST(SceneRender, CornellBoxMatchesHighSampleReference) {
  const fs::path f = fs::path(TUILE_SHARED_SCENES) / "cornell-box" / "scene-v4.pbrt";
  if (!fs::exists(f)) GTEST_SKIP() << f << " is absent: cornell-box integration test skipped";
  const int res = 32;
  const RenderResult ref = small_render(f.string(), 2048, res, 77);
  const RenderResult r = small_render(f.string(), 64, res, 5);
  expect_sane(r, "cornell-box 64 spp");
  const std::vector<float> vr = ref.film.variance_of_mean(), v = r.film.variance_of_mean();
  double d = 0, var = 0;
  double worst = 0;
  const int w = r.film.width, h = r.film.height;
  for (int by = 0; by + 8 <= h; by += 8)
    for (int bx = 0; bx + 8 <= w; bx += 8) {
      double bd = 0, bv = 0;
      for (int y = by; y < by + 8; ++y)
        for (int x = bx; x < bx + 8; ++x)
          for (int c = 0; c < 3; ++c) {
            const size_t i = 3 * (static_cast<size_t>(y) * w + x) + c;
            bd += r.mean[i] - ref.mean[i];
            bv += v[i] + vr[i];
          }
      d += bd;
      var += bv;
      if (bv > 0) worst = std::max(worst, std::fabs(bd) / std::sqrt(bv));
    }
  EXPECT_LT(std::fabs(d) / std::sqrt(var), 3.0);
  EXPECT_LT(worst, 4.5);
}

// A scene at w x h, 4 spp, rendered with its bounce rays traced against the whole scene
// (first) and against the emitters alone, then an occlusion ray (second).
static std::pair<RenderResult, RenderResult> render_both_bounce_modes(const fs::path& f, int w, int h, uint32_t seed) {
  Scene s = load_scene(f.string());
  s.camera.width = w;
  s.camera.height = h;
  RenderOptions o;
  o.est.spp = 4;
  o.est.seed = seed;
  RenderOptions oe = o;
  o.bounce = BounceTrace::scene;
  oe.bounce = BounceTrace::emitters;
  return {render_scene(s, o), render_scene(s, oe)};
}

// Every project scene (stress cases included: a point next to a light, grazing and tiny
// sources, far origins, degenerate triangles) gives the same image with its bounce rays
// traced against the emitters alone and then an occlusion ray as against the whole scene:
// bit for bit, but for at most one scene with a rounding-level difference.
TEST(SceneRender, ProjectScenesBounceRaysAgainstEmitters) {
  const auto files = pbrt_files(fs::path(TUILE_SOURCE_DIR) / "scenes");
  ASSERT_GE(files.size(), 10u);
  size_t exact = 0;
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    const auto [a, b] = render_both_bounce_modes(f, 48, 32, 0);
    ASSERT_EQ(a.mean.size(), b.mean.size());
    size_t differ = 0;
    double worst = 0;
    for (size_t i = 0; i < a.mean.size(); ++i) {
      differ += a.mean[i] != b.mean[i];
      worst = std::max(worst, std::fabs(double(a.mean[i]) - b.mean[i]) / (std::fabs(double(a.mean[i])) + 1e-3));
    }
    // far-origin (coordinates near 1e5, distances good to ~1%) may differ by a rounding of
    // one bounce hit's distance: measured, 3 of 4608 values, by 0.7% at most
    EXPECT_LE(differ, a.mean.size() / 1000);
    EXPECT_LE(worst, 0.02);
    exact += differ == 0;
  }
  EXPECT_GE(exact + 1, files.size());
}

// The shared scenes with their bounce rays traced against the emitters alone (then an
// occlusion ray to the emitter, or to infinity under a sky; the rays in a medium against
// the whole scene) and against the whole scene: the same image. Where an
// occluder lies within 2^-12 of an emitter's distance the two visibility tests may
// differ, so the test allows a pixel value in 10^4 to differ; the images' means agree
// to 1e-4 relative.
TEST(SceneRender, SharedScenesBounceRaysAgainstEmitters) {
  const fs::path dir = TUILE_SHARED_SCENES;
  if (!fs::exists(dir)) GTEST_SKIP() << "../shared/scenes is absent: shared-scene renders skipped";
  // (staircase2 and living-room-3: media inside glass; dining-room: a sky and a sun)
  for (const char* name : {"cornell-box", "veach-mis", "kitchen", "staircase2", "living-room-3", "dining-room"}) {
    const fs::path f = dir / name / "scene-v4.pbrt";
    if (!fs::exists(f)) continue;
    SCOPED_TRACE(f.string());
    const auto [a, b] = render_both_bounce_modes(f, 64, 48, 9);
    size_t differ = 0;
    double sa = 0, sb = 0;
    for (size_t i = 0; i < a.mean.size(); ++i) {
      differ += a.mean[i] != b.mean[i];
      sa += a.mean[i];
      sb += b.mean[i];
    }
    EXPECT_LE(differ, a.mean.size() / 10000) << name;
    EXPECT_LE(std::fabs(sa - sb), 1e-4 * sa) << name;
    EXPECT_GT(b.stats.rays_bounce_visibility, 0u) << name;
  }
}
