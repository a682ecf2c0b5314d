// Optimal MIS weights (--heuristic optimal, wave/optimal_mis.h): the 2x2 solve against a
// long-double reference; the estimator's algebra (equal densities give the balance
// heuristic; a failed or occluded sample adds nothing under multi-sample MIS); zero variance
// where BSDF sampling is proportional to the integrand; the moments carried across passes
// and checkpoints; the options it refuses. (Unbiasedness and 1/spp: tests/test_render_exact.cpp;
// every SIMD lane of the stages it reads: tests/test_lanes.cpp.)
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <random>
#include <string>

#include "render/checkpoint.h"
#include "render/passes.h"
#include "render/render.h"
#include "render_util.h"
#include "scene/pbrt.h"
#include "scene/sky_map.h"
#include "wave/optimal_mis.h"

using namespace tuile;
using namespace tuile::test;

namespace {

// The reference: long double, Cramer's rule where A is well conditioned, the pseudo-inverse
// along the larger eigenvector where it is (numerically) of rank one.
void reference_alpha(const double* m, long double* al, long double* ab) {
  const long double a = m[opt_a_ll], h = m[opt_a_lb], c = m[opt_a_bb];
  const long double mean = (a + c) / 2, half = (a - c) / 2, radius = std::sqrt(half * half + h * h);
  const long double l1 = mean + radius, l2 = (a * c - h * h) / l1;
  for (int ch = 0; ch < 3; ++ch) {
    const long double bl = m[opt_b_l + ch], bb = m[opt_b_b + ch];
    if (l2 > 1e-9L * l1) {
      const long double det = a * c - h * h;
      al[ch] = (c * bl - h * bb) / det;
      ab[ch] = (a * bb - h * bl) / det;
    } else {
      long double vx = a >= c ? 1 : 0, vy = a >= c ? 0 : 1;
      if (h != 0) {
        const long double len = std::sqrt(h * h + (l1 - a) * (l1 - a));
        vx = h / len;
        vy = (l1 - a) / len;
      }
      const long double p = (vx * bl + vy * bb) / l1;
      al[ch] = p * vx;
      ab[ch] = p * vy;
    }
  }
}

// Adds one sample's moments (r_L, r_B, and u in channel ch times ch + 1) as the stages do.
void add_sample(double* m, double rl, double rb, double u) {
  m[opt_a_ll] += rl * rl;
  m[opt_a_lb] += rl * rb;
  m[opt_a_bb] += rb * rb;
  for (int ch = 0; ch < 3; ++ch) {
    m[opt_b_l + ch] += (ch + 1) * u * rl;
    m[opt_b_b + ch] += (ch + 1) * u * rb;
  }
}

// Moments of n random samples.
void random_moments(std::mt19937& rng, int n, double scale_l, double scale_b, double* m) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int j = 0; j < opt_moments; ++j) m[j] = 0;
  for (int s = 0; s < n; ++s) {
    const double pl = scale_l * U(rng), pb = scale_b * U(rng), f = U(rng) * (pl + 2 * pb);
    const double q = pl + pb;
    add_sample(m, pl / q, pb / q, f / q);
  }
}

void expect_alpha_near(const double* m, const std::string& what) {
  float al[3], ab[3];
  solve_optimal_alpha(m, al, ab);
  long double rl[3], rb[3];
  reference_alpha(m, rl, rb);
  // the condition number of A (below 1e9: the full solve): double's solve loses about
  // cond * 2^-53 of the alphas' size, float rounds them to 2^-24
  const long double a = m[opt_a_ll], h = m[opt_a_lb], c = m[opt_a_bb];
  const long double l1 = (a + c) / 2 + std::sqrt((a - c) * (a - c) / 4 + h * h), l2 = (a * c - h * h) / l1;
  const long double cond = l2 > 1e-9L * l1 ? l1 / l2 : 1;
  const long double tol = 1e-6L + 1e-14L * cond;
  for (int ch = 0; ch < 3; ++ch) {
    const long double size = std::fabs(rl[ch]) + std::fabs(rb[ch]) + 1e-30L;
    EXPECT_LT(std::fabs(al[ch] - rl[ch]) / size, tol) << what << " channel " << ch << ": " << al[ch] << " vs " << static_cast<double>(rl[ch]);
    EXPECT_LT(std::fabs(ab[ch] - rb[ch]) / size, tol) << what << " channel " << ch << ": " << ab[ch] << " vs " << static_cast<double>(rb[ch]);
  }
}

}  // namespace

TEST(OptimalMis, SolveMatchesALongDoubleReference) {
  std::mt19937 rng(1);
  double m[opt_moments];
  // well conditioned systems of many scales
  for (int t = 0; t < 500; ++t) {
    const double sl = std::ldexp(1.0, static_cast<int>(rng() % 40) - 20), sb = std::ldexp(1.0, static_cast<int>(rng() % 40) - 20);
    random_moments(rng, 2 + static_cast<int>(rng() % 60), sl, sb, m);
    expect_alpha_near(m, "random " + std::to_string(t));
  }
  // singular: every sample with the same ratio p_L / p_B (A of rank one, b in its range): the
  // pseudo-inverse's smallest solution, and A alpha = b holds
  for (double ratio : {1.0, 0.25, 3.0, 1e-6, 1e6}) {
    for (int j = 0; j < opt_moments; ++j) m[j] = 0;
    const double rl = ratio / (ratio + 1), rb = 1 / (ratio + 1);
    for (int s = 0; s < 10; ++s) add_sample(m, rl, rb, 0.1 * (s + 1));
    expect_alpha_near(m, "rank one, ratio " + std::to_string(ratio));
    float al[3], ab[3];
    solve_optimal_alpha(m, al, ab);
    for (int ch = 0; ch < 3; ++ch) {
      const double res_l = m[opt_a_ll] * al[ch] + m[opt_a_lb] * ab[ch] - m[opt_b_l + ch];
      EXPECT_LT(std::fabs(res_l), 1e-5 * std::fabs(m[opt_b_l + ch]) + 1e-12) << "ratio " << ratio;
    }
  }
  // near singular, both sides of the 1e-9 threshold: a second technique barely different
  for (double eps : {1e-3, 1e-5, 1e-7}) {
    for (int j = 0; j < opt_moments; ++j) m[j] = 0;
    for (int s = 0; s < 8; ++s) {
      const double rl = 0.5 + eps * (s % 2 ? 1 : -1);
      add_sample(m, rl, 1 - rl, 0.3 + 0.01 * s);
    }
    expect_alpha_near(m, "near singular " + std::to_string(eps));
  }
  // nothing to solve: zeros, NaN, infinity give alpha = 0 (the balance heuristic)
  for (double bad : {0.0, std::nan(""), static_cast<double>(INFINITY)}) {
    for (int j = 0; j < opt_moments; ++j) m[j] = j < 3 ? bad : 1.0;
    float al[3] = {9, 9, 9}, ab[3] = {9, 9, 9};
    solve_optimal_alpha(m, al, ab);
    for (int ch = 0; ch < 3; ++ch) {
      EXPECT_EQ(al[ch], 0.f) << bad;
      EXPECT_EQ(ab[ch], 0.f) << bad;
    }
  }
}

// The estimator's algebra on one shading point, with arbitrary alphas: where both techniques
// have the same density (r_L = r_B = 1/2, one sample each), a pixel sample adds exactly what
// the balance heuristic adds (u_light + u_bsdf), to rounding; a failed or occluded sample adds
// nothing under multi-sample MIS; and the moments are r r^T and u r.
TEST(OptimalMis, EqualDensitiesGiveTheBalanceHeuristic) {
  auto tb = std::make_unique<TileBuffers>();
  tb->points.count = 1;
  tb->points.lane[0] = 0;
  tb->points.choose_light[0] = 0.f;
  tb->lanes.pixel[0] = 0;
  Estimator est;
  est.strategy = Strategy::mis;
  est.heuristic = Heuristic::optimal;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(-3.f, 3.f);
  for (int t = 0; t < 100; ++t) {
    optimal_tile_start(*tb, 1, nullptr);
    for (int ch = 0; ch < 3; ++ch) {
      tb->opt.alpha_l[ch][0] = U(rng);
      tb->opt.alpha_b[ch][0] = U(rng);
    }
    const float p = std::fabs(U(rng)) + 0.1f, ul = std::fabs(U(rng)), ub = std::fabs(U(rng));
    tb->radiance.r[0] = tb->radiance.g[0] = tb->radiance.b[0] = 0.f;
    // the light sample, lit: u = f / (p + p), densities p and p
    tb->tech.valid[0] = -1;
    tb->shadow[0].tfar[0] = 1.f;
    tb->tech.cr[0] = tb->tech.cg[0] = tb->tech.cb[0] = ul;
    tb->tech.pl[0] = tb->tech.pb[0] = p;
    optimal_light_pass(*tb, est, 1.f, 1.f);
    // the BSDF sample, which met the source
    optimal_bsdf_clear(*tb);
    tb->opt.hit[0] = 1;
    tb->opt.pl[0] = p;
    tb->tech.pdf[0] = p;
    tb->tech.delta[0] = 0;
    tb->opt.ur[0] = tb->opt.ug[0] = tb->opt.ub[0] = ub;
    tb->opt.wb[0] = 0.5f;
    optimal_bsdf_pass(*tb, est, 1.f, 1.f, true, false);
    // (the stages themselves added u; here the point starts at 0, so it holds the rest)
    EXPECT_NEAR(tb->radiance.r[0] + (ul + ub), ul + ub, 2e-6 * (1 + std::fabs(tb->opt.alpha_l[0][0]) + std::fabs(tb->opt.alpha_b[0][0])));
    EXPECT_NEAR(tb->opt.sum[opt_a_ll][0], 0.5, 1e-7);
    EXPECT_NEAR(tb->opt.sum[opt_a_lb][0], 0.5, 1e-7);
    EXPECT_NEAR(tb->opt.sum[opt_a_bb][0], 0.5, 1e-7);
    EXPECT_NEAR(tb->opt.sum[opt_b_l][0], 0.5 * (ul + ub), 1e-5 * (ul + ub + 1));
    // failed samples of both techniques: nothing added, A gains 1 / n^2 on the diagonal
    const float before = tb->radiance.r[0];
    tb->tech.valid[0] = 0;
    optimal_light_pass(*tb, est, 1.f, 1.f);
    optimal_bsdf_clear(*tb);
    optimal_bsdf_pass(*tb, est, 1.f, 1.f, true, false);
    EXPECT_EQ(tb->radiance.r[0], before);
    EXPECT_NEAR(tb->opt.sum[opt_a_ll][0], 1.5, 1e-7);
    EXPECT_NEAR(tb->opt.sum[opt_a_bb][0], 1.5, 1e-7);
  }
}

namespace {

std::filesystem::path optimal_scratch() {
  const auto d = std::filesystem::temp_directory_path() / ("tuile_test_optimal_mis_" + std::to_string(::getpid()));
  std::filesystem::create_directories(d);
  return d;
}

// A grey floor filling the view under a sky of uniform radiance 1 given as a map: the light
// technique samples the map's directions uniformly over the sphere (its compensated
// distribution is uniform), the BSDF technique cosine-weighted, proportional to the
// integrand rho / pi L cos. Exact radiance rho L = 0.5 in every pixel.
Scene uniform_sky_floor() {
  const auto dir = optimal_scratch();
  RgbImage img;
  img.width = img.height = 8;
  img.rgb.assign(8 * 8 * 3, 1.f);
  write_pfm((dir / "uniform.pfm").string(), img);
  Scene s = load_pbrt_string(
      "LookAt 0 5 0  0 0 0  0 0 1\nCamera \"perspective\" \"float fov\" 20\n"
      "Film \"rgb\" \"integer xresolution\" 24 \"integer yresolution\" 24\n"
      "WorldBegin\nLightSource \"infinite\" \"string filename\" \"uniform.pfm\"\n"
      "Material \"diffuse\" \"rgb reflectance\" [0.5 0.5 0.5]\n"
      "Shape \"trianglemesh\" \"point3 P\" [-10 0 -10 10 0 -10 10 0 10 -10 0 10] \"integer indices\" [0 1 2 0 2 3]\n",
      "floor.pbrt", dir.string());
  finalize_scene(s);
  return s;
}

RenderOptions optimal_options(uint32_t spp) {
  RenderOptions o;
  o.est.strategy = Strategy::mis;
  o.est.heuristic = Heuristic::optimal;
  o.est.sampler = SamplerKind::independent;
  o.est.spp = spp;
  o.est.seed = 3;
  o.threads = 2;
  return o;
}

}  // namespace

// BSDF sampling proportional to the integrand: the optimal weights are alpha_B = rho L,
// alpha_L = 0, and every sample after the warm-up gives exactly rho L: a pass rendered
// after one that learnt them has (to rounding) zero variance, where the balance heuristic
// does not.
TEST(OptimalMis, ZeroVarianceWhereBsdfSamplingIsProportionalToTheIntegrand) {
  Scene s = uniform_sky_floor();
  Accel accel(s);
  for (Heuristic h : {Heuristic::optimal, Heuristic::balance}) {
    RenderOptions o = optimal_options(64);
    o.est.heuristic = h;
    Renderer r(s, accel, o);
    Film first, pass;
    first.reset(s.camera.width, s.camera.height);
    pass.reset(s.camera.width, s.camera.height);
    r.render(first, 0, 16);
    r.render(pass, 16, 64, nullptr, nullptr, &first);
    const std::vector<float> m = pass.mean(), v = pass.variance_of_mean();
    double worst_v = 0, worst_m = 0;
    for (size_t i = 0; i < m.size(); ++i) {
      worst_v = std::max(worst_v, static_cast<double>(v[i]));
      worst_m = std::max(worst_m, std::fabs(m[i] - 0.5));
    }
    if (h == Heuristic::optimal) {
      EXPECT_LT(worst_v, 1e-12) << "largest variance of a pixel's mean";
      EXPECT_LT(worst_m, 1e-5) << "largest error of a pixel's mean";
    } else {
      EXPECT_GT(worst_v, 1e-5) << "the balance heuristic has variance here";
    }
  }
}

// The moments go on from pass to pass and through a checkpoint: a render stopped after some
// passes, saved, loaded and resumed gives the bits of the render that ran through.
TEST(OptimalMis, ResumedRenderGivesTheUninterruptedBits) {
  Scene s = uniform_sky_floor();
  Accel accel(s);
  RenderOptions o = optimal_options(24);
  o.est.sampler = SamplerKind::sobol;
  const PassPlan plan{PassSchedule::fixed, 4};
  Film whole;
  whole.reset(s.camera.width, s.camera.height);
  {
    Renderer r(s, accel, o);
    render_passes(r, whole, 24, plan, PassControl{});
  }
  ASSERT_EQ(whole.optimal.size(), 9u * 24 * 24);
  const std::string path = (optimal_scratch() / "resume.checkpoint").string();
  {
    Renderer r(s, accel, o);
    Film part;
    part.reset(s.camera.width, s.camera.height);
    render_passes(r, part, 12, plan, PassControl{});
    save_checkpoint(path, render_fingerprint(s, o, plan), plan, part);
  }
  Checkpoint c = load_checkpoint(path);
  ASSERT_EQ(c.film.samples, 12u);
  ASSERT_EQ(c.film.optimal.size(), 9u * 24 * 24);
  Renderer r(s, accel, o);
  render_passes(r, c.film, 24, plan, PassControl{});
  ASSERT_EQ(c.film.sum.size(), whole.sum.size());
  for (size_t i = 0; i < whole.sum.size(); ++i) ASSERT_EQ(c.film.sum[i], whole.sum[i]) << i;
  for (size_t i = 0; i < whole.optimal.size(); ++i) ASSERT_EQ(c.film.optimal[i], whole.optimal[i]) << i;
}

TEST(OptimalMis, RefusesWhatItDoesNotApplyTo) {
  RenderOptions o = optimal_options(4);
  for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::ris}) {
    o.est.strategy = st;
    EXPECT_THROW(validate(o), std::invalid_argument);
  }
  o.est.strategy = Strategy::mis;
  o.est.mode = MisMode::one;
  o.est.pick = LightPick::all;
  EXPECT_THROW(validate(o), std::invalid_argument);
  o.est.pick = LightPick::power;
  EXPECT_NO_THROW(validate(o));
  EXPECT_EQ(parse_heuristic("optimal"), Heuristic::optimal);
}
