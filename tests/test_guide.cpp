// Path guiding (--guide: kernels/wave/guide.h, src/render/guide.h). The guide's sampling
// and its density agree (E[1 / p] over its samples is the sphere's 4 pi, and the density
// integrates to 1), its samples go where its records came from, and every lane gives the
// scalar reference's bits; a record's filter shares it among the cells around its
// direction (its neighbours on the sphere, across the square's folds); a guided render has
// the unguided render's mean (a two-sample z-test per image quarter, seeds apart: a light
// stage whose MIS weight left the guide out of the BSDF's density, or a BSDF stage whose
// throughput did, fails it), and so has a guided render in a fog, where the guide learns at
// the medium's points too; it gives the same bits on any thread count, and
// resumed by a new renderer (which learns the guide again from the samples before it); the
// options it cannot combine with are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "render/guide.h"
#include "render/options.h"
#include "media_util.h"
#include "render_util.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// A guide whose one region learned light from around d0 (and a little from everywhere).
Guide learned_guide(const Vec3<float>& d0) {
  const float lo[3] = {-1, -1, -1}, hi[3] = {1, 1, 1};
  Guide g(lo, hi, 4, 0.5f);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(0, 1);
  for (int i = 0; i < 200000; ++i) {
    const float x = U(rng) * 0.2f, y = U(rng) * 0.2f, z = U(rng) * 0.2f;
    // most records near d0, some over the whole sphere
    Vec3<float> d = d0;
    if (i % 4 == 0) {
      const float cz = 1 - 2 * U(rng), ph = 6.2831853f * U(rng), r = std::sqrt(std::max(0.f, 1 - cz * cz));
      d = Vec3<float>(r * std::cos(ph), r * std::sin(ph), cz);
    }
    g.record(x, y, z, guide_class<float>(Vec3<float>(0.f, 1.f, 0.f)), d.x, d.y, d.z, 1.f);
  }
  g.rebuild(1);
  return g;
}

TEST(Guide, SamplesAsItsDensitySaysWhereItsRecordsCameFrom) {
  const Vec3<float> d0 = normalize(Vec3<float>(0.3f, 0.8f, -0.5f));
  const Guide g = learned_guide(d0);
  const GuideView& v = g.view();
  ASSERT_GT(g.distributions(), 0);
  const int d = guide_dist<float>(v, Vec3<float>(0.1f, 0.1f, 0.1f), Vec3<float>(0.f, 1.f, 0.f));
  ASSERT_GE(d, 0);
  // a point of another orientation (a wall) learned nothing there
  EXPECT_EQ(guide_dist<float>(v, Vec3<float>(0.1f, 0.1f, 0.1f), Vec3<float>(1.f, 0.f, 0.f)), -1);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0, 1);
  const int n = scaled(200000);
  double inv = 0, inv2 = 0, near = 0;
  for (int i = 0; i < n; ++i) {
    const Vec3<float> w = guide_sample<float>(v, d, U(rng), U(rng));
    const double p = guide_pdf<float>(v, d, w);
    ASSERT_GT(p, 0);
    inv += 1 / p;
    inv2 += 1 / (p * p);
    near += dot(w, d0) > 0.9f;
  }
  // E[1 / p] = the sphere's 4 pi where the sampler and the density agree (every direction
  // has a density: the guide's floor); 5 sigma
  const double m = inv / n, sd = std::sqrt((inv2 / n - m * m) / n);
  EXPECT_NEAR(m, 4 * M_PI, 5 * sd) << "sigma " << sd;
  // three quarters of the records came from d0's cell: so do most samples
  EXPECT_GT(near / n, 0.6);
  // the density integrates to 1 over the sphere (uniform directions; 5 sigma)
  double I = 0, I2 = 0;
  for (int i = 0; i < n; ++i) {
    const float cz = 1 - 2 * U(rng), ph = 6.2831853f * U(rng), r = std::sqrt(std::max(0.f, 1 - cz * cz));
    const double f = 4 * M_PI * guide_pdf<float>(v, d, Vec3<float>(r * std::cos(ph), r * std::sin(ph), cz));
    I += f;
    I2 += f * f;
  }
  const double mi = I / n, si = std::sqrt((I2 / n - mi * mi) / n);
  EXPECT_NEAR(mi, 1.0, 5 * si);
}

// The direction's four cells are cells of the grid and its neighbours on the sphere, also
// across the square's edges (where the octahedral map folds it): a wrap that went round to
// the opposite edge (as a periodic texture's) would put a cell with weight on the far side
// of the sphere, and none would put cells outside the grid.
TEST(Guide, BilinearCellsAreTheDirectionsNeighbours) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0, 1);
  auto centre = [](int c) {
    return equal_area_square_to_sphere<float>((static_cast<float>(c % guide_res) + 0.5f) / guide_res,
                                              (static_cast<float>(c / guide_res) + 0.5f) / guide_res);
  };
  double worst = 1;
  for (int i = 0; i < 200000; ++i) {
    // half of them near the equator and the axes' planes, where the square's edges are
    float cz = 1 - 2 * U(rng), ph = 6.2831853f * U(rng);
    if (i % 2) cz = (U(rng) - 0.5f) * 0.05f;
    if (i % 4 == 1) ph = 1.5707963f * std::round(ph / 1.5707963f) + (U(rng) - 0.5f) * 0.05f;
    const float r = std::sqrt(std::max(0.f, 1 - cz * cz));
    const Vec3<float> d(r * std::cos(ph), r * std::sin(ph), cz);
    int cell[4];
    float w[4];
    guide_bilinear_cells(d, cell, w);
    float sum = 0;
    for (int k = 0; k < 4; ++k) {
      ASSERT_GE(cell[k], 0);
      ASSERT_LT(cell[k], guide_cells);
      ASSERT_GE(w[k], 0.f);
      sum += w[k];
      if (w[k] > 1e-4f) worst = std::min(worst, static_cast<double>(dot(centre(cell[k]), d)));
    }
    EXPECT_NEAR(sum, 1.f, 1e-5f);
  }
  // a 16 x 16 grid's cells are about 0.22 radians wide: every cell with weight lies within
  // a diagonal step and a half of d (the worst measured, at the square's corners, is
  // about 0.45 radians)
  EXPECT_GT(worst, std::cos(0.6)) << "the farthest cell with weight is " << std::acos(worst) << " radians away";
}

// The square's edges fold onto themselves mirrored (the point just past the edge at v is the
// point just inside it at 1 - v): two directions either side of a fold are nearly the same,
// so their cells and weights must be nearly the same too. A wrap that clamped without
// mirroring would keep each on its own side.
TEST(Guide, BilinearCellsAgreeAcrossTheSquaresFolds) {
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> U(0, 1);
  const float eps = 1e-4f / guide_res;
  for (int i = 0; i < 4000; ++i) {
    const float v = U(rng), side = (i / 2) % 2 ? 1.f - eps : eps;
    const bool vertical = i % 2;  // the edges u = 0, 1 or v = 0, 1
    const Vec3<float> d1 = vertical ? equal_area_square_to_sphere<float>(side, v) : equal_area_square_to_sphere<float>(v, side);
    const Vec3<float> d2 =
        vertical ? equal_area_square_to_sphere<float>(side, 1.f - v) : equal_area_square_to_sphere<float>(1.f - v, side);
    ASSERT_GT(dot(d1, d2), 0.99999f);  // the fold: the same direction, within eps
    int c1[4], c2[4];
    float w1[4], w2[4];
    guide_bilinear_cells(d1, c1, w1);
    guide_bilinear_cells(d2, c2, w2);
    std::vector<float> m(guide_cells, 0.f);
    for (int k = 0; k < 4; ++k) {
      m[static_cast<size_t>(c1[k])] += w1[k];
      m[static_cast<size_t>(c2[k])] -= w2[k];
    }
    float diff = 0;
    for (float x : m) diff += std::abs(x);
    EXPECT_LT(diff, 0.01f) << "v " << v << (vertical ? " on a vertical edge" : " on a horizontal edge");
  }
}

TEST(Guide, EveryLaneGivesTheScalarBits) {
  const Guide g = learned_guide(normalize(Vec3<float>(-0.2f, 0.9f, 0.3f)));
  const GuideView& v = g.view();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(0, 1);
  constexpr int W = simd_width;
  for (int round = 0; round < 200; ++round) {
    alignas(64) float x[W], y[W], z[W], nx[W], ny[W], nz[W], u1[W], u2[W];
    for (int l = 0; l < W; ++l) {
      x[l] = U(rng) * 0.4f - 0.1f, y[l] = U(rng) * 0.4f - 0.1f, z[l] = U(rng) * 0.4f - 0.1f;
      const int axis = static_cast<int>(U(rng) * 3) % 3;
      nx[l] = axis == 0 ? 1.f : 0.1f, ny[l] = axis == 1 ? 1.f : 0.1f, nz[l] = axis == 2 ? -1.f : 0.1f;
      u1[l] = U(rng), u2[l] = U(rng);
    }
    const Vec3<vfloat> X(vfloat::load_aligned(x), vfloat::load_aligned(y), vfloat::load_aligned(z));
    const Vec3<vfloat> N(vfloat::load_aligned(nx), vfloat::load_aligned(ny), vfloat::load_aligned(nz));
    const vint dv = guide_dist<vfloat>(v, X, N);
    alignas(64) int32_t ds[W];
    dv.store_aligned(ds);
    const vint safe = sel(dv >= vint(0), dv, vint(0));
    const Vec3<vfloat> w = guide_sample<vfloat>(v, safe, vfloat::load_aligned(u1), vfloat::load_aligned(u2));
    const vfloat p = guide_pdf<vfloat>(v, safe, w);
    alignas(64) float wx[W], wy[W], wz[W], pp[W];
    w.x.store_aligned(wx), w.y.store_aligned(wy), w.z.store_aligned(wz), p.store_aligned(pp);
    for (int l = 0; l < W; ++l) {
      const int d = guide_dist<float>(v, Vec3<float>(x[l], y[l], z[l]), Vec3<float>(nx[l], ny[l], nz[l]));
      ASSERT_EQ(ds[l], d) << "lane " << l;
      const Vec3<float> ws = guide_sample<float>(v, std::max(d, 0), u1[l], u2[l]);
      EXPECT_EQ(wx[l], ws.x) << "lane " << l;
      EXPECT_EQ(wy[l], ws.y) << "lane " << l;
      EXPECT_EQ(wz[l], ws.z) << "lane " << l;
      EXPECT_EQ(pp[l], guide_pdf<float>(v, std::max(d, 0), ws)) << "lane " << l;
    }
  }
}

// A room lit from a spot on its ceiling: a small light facing up at y = 1.2 over an opaque
// plate, whose light reaches the floor and the walls only as the ceiling reflects it (where
// guiding has something to learn), and a large panel facing down. Coated diffuse walls,
// diffuse elsewhere.
Scene spot_room(int res, bool finalize = true) {
  Scene s;
  s.source = "test:spot-room";
  s.materials.push_back(diffuse_material(Rgb{0.7f, 0.7f, 0.7f}));
  Material coat;
  coat.kind = MaterialKind::coated_diffuse;
  coat.reflectance = {0.6f, 0.5f, 0.3f};
  coat.alpha_u.value = coat.alpha_v.value = 0.2f;
  s.materials.push_back(coat);
  auto quad = [&](const char* name, int mat, vec3f p0, vec3f e1, vec3f e2, float L = 0) {
    add_named_quad(s, name, mat, p0, e1, e2, L);
  };
  quad("floor", 0, {-1.5f, 0, -1.5f}, {0, 0, 5}, {3, 0, 0});
  quad("ceiling", 0, {-1.5f, 2, -1.5f}, {3, 0, 0}, {0, 0, 5});
  quad("back", 1, {-1.5f, 0, -1.5f}, {3, 0, 0}, {0, 2, 0});
  quad("left", 1, {-1.5f, 0, -1.5f}, {0, 2, 0}, {0, 0, 5});
  quad("right", 1, {1.5f, 0, -1.5f}, {0, 0, 5}, {0, 2, 0});
  quad("light", 0, {-0.1f, 1.2f, -0.6f}, {0, 0, 0.2f}, {0.2f, 0, 0}, 40);  // facing up
  quad("plate", 0, {-0.3f, 1.19f, -0.8f}, {0.6f, 0, 0}, {0, 0, 0.6f});
  // and a panel as large as the ceiling, just under it, facing down: where light sampling and
  // BSDF sampling have densities alike, so that MIS weights that did not both read the
  // mixture would be far from summing to one
  quad("panel", 0, {-1.5f, 1.95f, -1.5f}, {3, 0, 0}, {0, 0, 5}, 1);
  s.camera.width = s.camera.height = res;
  s.camera.fov_deg = 55;
  camera_look_at(s.camera, {0, 1, 3.4f}, {0, 0.7f, 0}, {0, 1, 0});
  if (finalize) finalize_scene(s);
  return s;
}

RenderOptions guided(bool guide, uint32_t spp, uint32_t seed) {
  RenderOptions o;
  o.est.max_depth = 4;
  o.est.spp = spp;
  o.est.seed = seed;
  o.est.guide = guide;
  o.est.guide_learn = 8;
  o.threads = 2;
  return o;
}

// The guided image g and the unguided u have the same mean: each quarter of the image and
// each channel, |z| < 4.5 (12 tests: a false alarm once in some 12,000 runs).
void expect_same_mean(const Scene& s, const RenderResult& g, const RenderResult& u) {
  const std::vector<float> vg = g.film.variance_of_mean(), vu = u.film.variance_of_mean();
  // each quarter of the image and each channel: |z| < 4.5 (12 tests: a false alarm once in
  // some 12,000 runs)
  const int w = s.camera.width, h = s.camera.height;
  for (int q = 0; q < 4; ++q)
    for (int c = 0; c < 3; ++c) {
      double dm = 0, var = 0, sum = 0;
      for (int y = (q / 2) * h / 2; y < (q / 2 + 1) * h / 2; ++y)
        for (int x = (q % 2) * w / 2; x < (q % 2 + 1) * w / 2; ++x) {
          const size_t i = 3 * (static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x)) + static_cast<size_t>(c);
          dm += static_cast<double>(g.mean[i]) - u.mean[i];
          var += static_cast<double>(vg[i]) + vu[i];
          sum += u.mean[i];
        }
      ASSERT_GT(sum, 0);
      EXPECT_LT(std::abs(dm / std::sqrt(var)), 4.5) << "quarter " << q << " channel " << c << ": " << dm / sum;
    }
}

TEST(Guide, RendersTheUnguidedMean) {
  const Scene s = spot_room(40);
  const uint32_t spp = static_cast<uint32_t>(scaled(512));
  expect_same_mean(s, render_scene(s, guided(true, spp, 1)), render_scene(s, guided(false, spp, 2)));
}

// Volume path guiding: the spot room closed and filled with a fog whose phase function
// leans forward (g = 0.5), the camera inside it. The guide learns distributions for points
// in the medium (guide_medium_class), and the guided render has the unguided one's mean: a
// phase sample whose throughput, or a light sample whose MIS weight, left the guide out of
// the phase function's density fails it, as does a guided direction weighed with a cosine.
TEST(Guide, GuidesInAMediumAndRendersTheUnguidedMean) {
  Scene s = spot_room(32, false);
  s.media.push_back(homogeneous({0.02f, 0.03f, 0.05f}, {0.35f, 0.3f, 0.25f}, 0.5f));
  s.camera_medium = 0;
  Mesh box = media_box({-1.6f, -0.05f, -1.6f}, {1.6f, 2.05f, 3.6f});  // closes the room behind the camera
  box.material = 0;
  s.meshes.push_back(box);
  finalize_scene(s);
  const uint32_t spp = static_cast<uint32_t>(scaled(384));
  Accel accel(s);
  Film film;
  film.reset(s.camera.width, s.camera.height);
  Renderer r(s, accel, guided(true, spp, 1));
  r.render(film, 0, spp);
  ASSERT_NE(r.guide(), nullptr);
  const Guide& g = *r.guide();
  const GuideView& v = g.view();
  int medium = 0, surface = 0;
  for (int n = 0; n < 2 * g.leaves() - 1; ++n) {  // (every inner node has two children)
    if (v.child[n] >= 0) continue;
    for (int c = 0; c < guide_classes; ++c)
      if (v.leaf_dist[n * guide_classes + c] >= 0) (c == guide_medium_class ? medium : surface) += 1;
  }
  std::printf("[ guide in a medium ] %d leaves: %d medium distributions, %d surface ones\n", g.leaves(), medium, surface);
  EXPECT_GT(medium, 0);
  EXPECT_GT(surface, 0);
  RenderResult guided_result;
  guided_result.film = film;
  guided_result.mean = film.mean();
  expect_same_mean(s, guided_result, render_scene(s, guided(false, spp, 2)));
}

TEST(Guide, SameBitsOnAnyThreadsAndResumed) {
  const Scene s = spot_room(24);
  Accel accel(s);
  RenderOptions o = guided(true, 20, 3);
  Film whole;
  whole.reset(24, 24);
  Renderer(s, accel, o).render(whole, 0, 20);
  o.threads = 1;
  Film one;
  one.reset(24, 24);
  Renderer(s, accel, o).render(one, 0, 20);
  // resumed: samples 0..6 by one renderer, 6..20 by another (which learns again from 0..6,
  // in the middle of the iteration [4, 8))
  Film resumed;
  resumed.reset(24, 24);
  Renderer(s, accel, o).render(resumed, 0, 6);
  Renderer(s, accel, o).render(resumed, 6, 20);
  const std::vector<float> a = whole.mean(), b = one.mean(), c = resumed.mean();
  size_t differ_threads = 0, differ_resumed = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    differ_threads += a[i] != b[i];
    differ_resumed += std::abs(a[i] - c[i]) > 1e-5f * std::max(1.f, std::abs(a[i]));
  }
  EXPECT_EQ(differ_threads, 0u);
  // (a resumed film adds its passes' sums in another order: the same samples, rounding apart)
  EXPECT_EQ(differ_resumed, 0u);
  // and guiding changed the image
  Film plain;
  plain.reset(24, 24);
  Renderer(s, accel, guided(false, 20, 3)).render(plain, 0, 20);
  const std::vector<float> p = plain.mean();
  size_t differ_plain = 0;
  for (size_t i = 0; i < a.size(); ++i) differ_plain += a[i] != p[i];
  EXPECT_GT(differ_plain, a.size() / 2);
}

TEST(Guide, RefusesWhatItCannotCombineWith) {
  auto refused = [](auto change) {
    RenderOptions o = guided(true, 4, 0);
    change(o.est);
    EXPECT_THROW(validate(o), std::invalid_argument);
  };
  refused([](Estimator& e) { e.max_depth = 1; });
  refused([](Estimator& e) { e.strategy = Strategy::ris; });
  refused([](Estimator& e) { e.strategy = Strategy::light; });
  refused([](Estimator& e) { e.mode = MisMode::one; });
  refused([](Estimator& e) { e.heuristic = Heuristic::optimal; });
  refused([](Estimator& e) { e.guide_alpha = 1.f; });
  refused([](Estimator& e) { e.guide_alpha = NAN; });
  refused([](Estimator& e) { e.guide_learn = 0; });
  RenderOptions ok = guided(true, 4, 0);
  EXPECT_NO_THROW(validate(ok));
}

}  // namespace
