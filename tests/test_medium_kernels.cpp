// The homogeneous-medium kernels (kernels/medium/homogeneous.h) against closed forms: the
// Henyey-Greenstein pdf integrates to 1, its samples follow its CDF (chi-square) with mean
// cosine -g, free flights through a medium whose extinction differs per channel are unbiased
// per channel (the wine of living-room-3, sigma_a = 250 / 1000 / 1000, and a scattering
// medium), transmittance through one and several media, stiff inputs, and every SIMD lane
// equal to the scalar reference. Seeds are fixed; the statistical thresholds are stated.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "chi2.h"
#include "medium/homogeneous.h"
#include "test_scale.h"

using namespace tuile;

namespace {

constexpr double kMediumPi = 3.14159265358979323846;
const float kHgAsymmetries[] = {-0.9f, 0.f, 0.5f, 0.99f};

// Henyey-Greenstein's CDF in c = dot(wo, wi): (1 - g^2) / (2g) (1 / (1 - g) - 1 / sqrt(1 + g^2 + 2 g c)).
double hg_cdf(double c, double g) {
  if (std::abs(g) < 1e-3) return 0.5 * (c + 1);
  return (1 - g * g) / (2 * g) * (1 / (1 - g) - 1 / std::sqrt(1 + g * g + 2 * g * c));
}

vec3f random_direction(std::mt19937& rng) {
  std::normal_distribution<float> n;
  for (;;) {
    const vec3f v{n(rng), n(rng), n(rng)};
    if (length(v) > 1e-3f) return normalize(v);
  }
}

}  // namespace

// 2 pi times the integral of HG over c in [-1, 1] (midpoint rule, 4e6 cells: the g = 0.99
// peak is (1 - g)^2 = 1e-4 wide in c, 200 cells) is 1 to 1e-4 (5e-4 at g = 0.99, below);
// and HG is its CDF's derivative.
TEST(Phase, HenyeyGreensteinIntegratesToOne) {
  for (float g : kHgAsymmetries) {
    const int n = 4000000;
    double sum = 0;
    for (int i = 0; i < n; ++i) sum += hg_phase(float(-1 + (2.0 * i + 1) / n), g);
    // (float's 1 + g^2 + 2 g c cancels near the g = 0.99 peak, where it is (1 - g)^2 = 1e-4: its
    // rounding, 2^-24 of the terms' size 2, is 1.2e-3 of it there, and without fused
    // multiply-adds the integral came out 1.03e-4 short; 5e-4 there, 1e-4 elsewhere)
    EXPECT_NEAR(sum * 2.0 / n * 2 * kMediumPi, 1.0, std::abs(g) > 0.95f ? 5e-4 : 1e-4) << "g " << g;
    for (double c : {-0.999, -0.5, 0.0, 0.7, 0.999}) {
      const double h = 1e-5, d = (hg_cdf(c + h, g) - hg_cdf(c - h, g)) / (2 * h);
      // (float's rounding of 1 + g^2 + 2 g c, ~2.4e-7, relative to its value: 1e-4 at c = -0.999, g = 0.99)
      const double dd = 1 + double(g) * g + 2.0 * g * c;
      EXPECT_NEAR(2 * kMediumPi * hg_phase(float(c), g), d, (1e-4 + 4e-7 / dd) * d + 1e-6) << "g " << g << " c " << c;
    }
  }
}

// Samples against the CDF: F(c) of each sample is uniform (50 cells) and the azimuth around
// wo is uniform (16 cells); N = 200 000 per g, fail at p < 1e-4 each (8 tests: a family-wise
// false alarm of 8e-4 over random seeds). The sample's pdf is HG at its cosine, and the mean
// cosine is -g (forward scattering leaves along -wo) within 5 standard errors.
TEST(Phase, HenyeyGreensteinSamplesFollowTheirDensity) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const int N = int(test::scaled(200000u, 20000u));
  for (float g : kHgAsymmetries) {
    const vec3f wo = random_direction(rng);
    vec3f t, b;
    make_basis(wo, t, b);
    std::vector<double> cells_c(50, 0), cells_p(16, 0);
    double sum_c = 0, sum_c2 = 0;
    for (int k = 0; k < N; ++k) {
      const PhaseSample<float> s = sample_hg(wo, g, U(rng), U(rng));
      ASSERT_NEAR(length(s.wi), 1.f, 1e-5f);
      const float c = dot(wo, s.wi);
      // (the cosine recomputed from the rounded wi errs by ~4e-7, and HG's log-slope in c is
      // 3 |g| / (1 + g^2 + 2 g c): 3e4 at the g = 0.99 peak)
      const float slope = 3 * std::abs(g) / std::max(1 + g * g + 2 * g * c, 1e-6f);
      ASSERT_NEAR(s.pdf, hg_phase(c, g), (2e-4f + 4e-7f * slope) * s.pdf) << "g " << g;
      const double f = hg_cdf(std::clamp(double(c), -1.0, 1.0), g);
      cells_c[size_t(std::clamp(int(f * 50), 0, 49))] += 1;
      double phi = std::atan2(double(dot(b, s.wi)), double(dot(t, s.wi)));
      if (phi < 0) phi += 2 * kMediumPi;
      cells_p[size_t(std::clamp(int(phi / (2 * kMediumPi) * 16), 0, 15))] += 1;
      sum_c += c;
      sum_c2 += double(c) * c;
    }
    const test::Chi2 a = test::chi2_test(cells_c, std::vector<double>(50, N / 50.0));
    const test::Chi2 p = test::chi2_test(cells_p, std::vector<double>(16, N / 16.0));
    EXPECT_GT(a.p, 1e-4) << "g " << g << " chi2 " << a.chi2;
    EXPECT_GT(p.p, 1e-4) << "g " << g << " chi2 " << p.chi2;
    const double mean = sum_c / N, se = std::sqrt(std::max(sum_c2 / N - mean * mean, 1e-12) / N);
    EXPECT_NEAR(mean, -g, 5 * se + 1e-6) << "g " << g;
  }
}

// Free flights are unbiased per channel, whatever the other channels' extinction: the mean
// weight of the passes is e^(-sigma_c tmax), of the collisions 1 - e^(-sigma_c tmax), and of
// the collisions times t the mean free path's share (1 - e^(-s tmax) (1 + s tmax)) / s, to 5
// standard errors + 1e-4 relative (a false alarm below 1e-5 per check).
TEST(Medium, FreeFlightsAreUnbiasedPerChannel) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const Rgb3<float> media[] = {{250.f, 1000.f, 1000.f}, {1.1f, 0.7f, 2.3f}, {0.f, 5.f, 1e-6f}};
  const int N = int(test::scaled(400000u, 40000u));
  for (const Rgb3<float>& st : media)
    for (float tmax : {0.001f, 0.01f, 0.5f, INFINITY}) {
      double w[3][3] = {}, w2[3][3] = {};  // [pass, collide, collide * t][channel]
      for (int k = 0; k < N; ++k) {
        const FreeFlight<float> f = sample_free_flight(st, tmax, U(rng), U(rng));
        ASSERT_TRUE(std::isfinite(f.weight.r) && std::isfinite(f.weight.g) && std::isfinite(f.weight.b));
        const float wc[3] = {f.weight.r, f.weight.g, f.weight.b};
        for (int c = 0; c < 3; ++c) {
          const double v[3] = {f.scattered ? 0.0 : wc[c], f.scattered ? wc[c] : 0.0, f.scattered ? double(wc[c]) * f.t : 0.0};
          for (int q = 0; q < 3; ++q) {
            w[q][c] += v[q];
            w2[q][c] += v[q] * v[q];
          }
        }
      }
      const float sc[3] = {st.r, st.g, st.b};
      for (int c = 0; c < 3; ++c) {
        const double s = sc[c], tr = std::isinf(tmax) ? (s > 0 ? 0.0 : 1.0) : std::exp(-s * tmax);
        const double st_t = std::isinf(tmax) ? (s > 0 ? 1 / s : 0.0) : (s > 0 ? (1 - tr * (1 + s * tmax)) / s : 0.0);
        const double expect[3] = {tr, 1 - tr, st_t};
        for (int q = 0; q < 3; ++q) {
          const double mean = w[q][c] / N, se = std::sqrt(std::max(w2[q][c] / N - mean * mean, 0.0) / N);
          EXPECT_NEAR(mean, expect[q], 5 * se + 1e-4 * expect[q] + 1e-9)
              << "sigma_t " << st.r << " " << st.g << " " << st.b << " tmax " << tmax << " channel " << c << " quantity " << q;
        }
      }
    }
}

// Transmittance: exp(-sigma_t d) per channel to 3e-7 relative (plus the float product's
// rounding), through one medium and
// through several (the product of the segments' equals exp(-sum sigma_i d_i)), infinite
// distances give 0 (1 where sigma_t is 0).
TEST(Medium, TransmittanceThroughOneAndSeveralMedia) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (int k = 0; k < 2000; ++k) {
    double total[3] = {0, 0, 0}, prod[3] = {1, 1, 1};
    const int segments = 1 + k % 4;
    for (int sgm = 0; sgm < segments; ++sgm) {
      const Rgb3<float> st{std::pow(10.f, 6 * U(rng) - 4), std::pow(10.f, 6 * U(rng) - 4), U(rng) < 0.1f ? 0.f : U(rng)};
      const float d = std::pow(10.f, 4 * U(rng) - 4);
      const Rgb3<float> t = transmittance(st, d);
      const float sc[3] = {st.r, st.g, st.b}, tc[3] = {t.r, t.g, t.b};
      for (int c = 0; c < 3; ++c) {
        const double e = std::exp(-double(sc[c]) * d);
        // (3e-7 for exp, and the float product sigma d's rounding: 6e-8 of it, relative)
        ASSERT_NEAR(tc[c], e, (3e-7 + 6e-8 * double(sc[c]) * d) * e + 1e-37) << sc[c] << " " << d;
        total[c] += double(sc[c]) * d;
        prod[c] *= tc[c];
      }
    }
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(prod[c], std::exp(-total[c]), (1e-6 + 6e-8 * total[c]) * std::exp(-total[c]) + 1e-37);
  }
  const Rgb3<float> inf = transmittance(Rgb3<float>{1.f, 0.f, 1e-6f}, INFINITY);
  EXPECT_EQ(inf.r, 0.f);
  EXPECT_EQ(inf.g, 1.f);
  EXPECT_EQ(inf.b, 0.f);
}

// Stiff inputs: sigma_t from 1e-6 to 1e6 per channel, g = +-0.999 and +-1e-4 (the isotropic
// branch), segments from 1e-9 to infinite, u at 0 and just below 1: finite outputs,
// non-negative weights and pdfs, unit directions.
TEST(Medium, StiffCasesStayFinite) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const float sig[] = {0.f, 1e-6f, 1.f, 1e6f};
  const float us[] = {0.f, 0.5f, 0.99999994f};
  for (float g : {-0.999f, -1e-4f, 1e-4f, 0.999f})
    for (float u1 : us)
      for (float u2 : us) {
        const PhaseSample<float> s = sample_hg(random_direction(rng), g, u1, u2);
        ASSERT_TRUE(std::isfinite(s.pdf) && s.pdf > 0) << g << " " << u1;
        ASSERT_NEAR(length(s.wi), 1.f, 1e-5f) << g << " " << u1 << " " << u2;
      }
  for (float a : sig)
    for (float b : sig)
      for (float tmax : {1e-9f, 1.f, 1e9f, INFINITY})
        for (float u1 : us)
          for (float u2 : us) {
            const FreeFlight<float> f = sample_free_flight(Rgb3<float>{a, b, 1e6f}, tmax, u1, u2);
            ASSERT_TRUE(std::isfinite(f.weight.r) && std::isfinite(f.weight.g) && std::isfinite(f.weight.b)) << a << " " << b;
            ASSERT_TRUE(f.weight.r >= 0 && f.weight.g >= 0 && f.weight.b >= 0);
            ASSERT_TRUE(f.t >= 0 && f.t <= tmax);
          }
}

namespace {
template <class T> void medium_lanes_equal_scalar(uint32_t seed) {
  constexpr int W = lane_traits<T>::width;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  alignas(64) float in[10][W], out[12][W];
  for (int it = 0; it < 500; ++it) {
    for (int l = 0; l < W; ++l) {
      const vec3f wo = random_direction(rng);
      in[0][l] = wo.x, in[1][l] = wo.y, in[2][l] = wo.z;
      in[3][l] = U(rng) < 0.1f ? 0.f : 1.998f * U(rng) - 0.999f;  // g
      in[4][l] = U(rng), in[5][l] = U(rng);
      in[6][l] = std::pow(10.f, 8 * U(rng) - 4), in[7][l] = U(rng) < 0.2f ? 0.f : std::pow(10.f, 8 * U(rng) - 4);
      in[8][l] = U(rng) < 0.2f ? INFINITY : std::pow(10.f, 6 * U(rng) - 4);  // tmax
      in[9][l] = U(rng);
    }
    T v[10];
    for (int q = 0; q < 10; ++q) v[q] = load<T>(in[q]);
    const PhaseSample<T> s = sample_hg(Vec3<T>{v[0], v[1], v[2]}, v[3], v[4], v[5]);
    const FreeFlight<T> f = sample_free_flight(Rgb3<T>{v[6], v[7], v[6] * T(0.5f)}, v[8], v[9], v[4]);
    const Rgb3<T> tr = transmittance(Rgb3<T>{v[6], v[7], v[6] * T(0.5f)}, v[8]);
    const T outs[12] = {s.wi.x, s.wi.y, s.wi.z, s.pdf, f.t, sel(f.scattered, T(1.f), T(0.f)), f.weight.r, f.weight.g,
                        f.weight.b, tr.r, tr.g, hg_phase(v[4] * T(2.f) - T(1.f), v[3])};
    for (int q = 0; q < 12; ++q) store(out[q], outs[q]);
    for (int l = 0; l < W; ++l) {
      float x[10];
      for (int q = 0; q < 10; ++q) x[q] = in[q][l];
      const PhaseSample<float> ss = sample_hg(vec3f{x[0], x[1], x[2]}, x[3], x[4], x[5]);
      const FreeFlight<float> fs = sample_free_flight(Rgb3<float>{x[6], x[7], x[6] * 0.5f}, x[8], x[9], x[4]);
      const Rgb3<float> ts = transmittance(Rgb3<float>{x[6], x[7], x[6] * 0.5f}, x[8]);
      const float ref[12] = {ss.wi.x, ss.wi.y, ss.wi.z, ss.pdf, fs.t, fs.scattered ? 1.f : 0.f, fs.weight.r, fs.weight.g,
                             fs.weight.b, ts.r, ts.g, hg_phase(x[4] * 2.f - 1.f, x[3])};
      for (int q = 0; q < 12; ++q)
        ASSERT_EQ(std::memcmp(&ref[q], &out[q][l], 4), 0) << "output " << q << " lane " << l << ": " << ref[q] << " vs " << out[q][l];
    }
  }
}
}  // namespace

TEST(Medium, EveryLaneEqualsScalar) {
  medium_lanes_equal_scalar<vfloat>(19);
  medium_lanes_equal_scalar<vfloat2>(23);
}
