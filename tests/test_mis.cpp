// MIS weights (Veach & Guibas 1995): every heuristic's weights of two techniques sum to
// one over pdf ratios from 1e-30 to 1e30, zeros and infinities; they match the textbook
// formulas; every SIMD lane equals the scalar reference.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "mis.h"

using namespace tuile;

namespace {
const Heuristic all_h[] = {Heuristic::balance, Heuristic::power, Heuristic::cutoff, Heuristic::maximum};

std::vector<float> extreme_values() {
  std::vector<float> v = {0.f, 1e-38f, 1e-30f, 1e-20f, 1e-10f, 1e-3f, 0.1f, 0.5f, 1.f, 2.f, 10.f, 1e3f, 1e10f, 1e20f, 1e30f,
                          3e38f, INFINITY};
  return v;
}
}  // namespace

TEST(Mis, WeightsSumToOneEverywhere) {
  for (Heuristic h : all_h)
    for (float beta : {1.f, 2.f, 3.f, 0.5f})
      for (float a : extreme_values())
        for (float b : extreme_values()) {
          MisParams p;
          p.beta = beta;
          p.alpha = 0.1f;
          const float wa = mis_weight(h, a, b, p), wb = mis_weight(h, b, a, p);
          ASSERT_TRUE(std::isfinite(wa) && std::isfinite(wb)) << int(h) << " " << a << " " << b;
          ASSERT_GE(wa, 0.f);
          ASSERT_LE(wa, 1.f);
          ASSERT_NEAR(wa + wb, 1.f, 1e-6f) << "heuristic " << int(h) << " beta " << beta << " q " << a << " " << b;
        }
}

TEST(Mis, NanInputsGiveFiniteWeights) {
  for (Heuristic h : all_h) {
    const float w = mis_weight(h, NAN, 1.f, MisParams{});
    EXPECT_TRUE(std::isfinite(w));
    EXPECT_EQ(w, 0.f);
  }
}

TEST(Mis, MatchesTextbookFormulas) {
  MisParams p;
  const float qa = 3.f, qb = 1.f;
  EXPECT_NEAR(mis_weight(Heuristic::balance, qa, qb, p), 3.f / 4.f, 1e-6f);
  EXPECT_NEAR(mis_weight(Heuristic::power, qa, qb, p), 9.f / 10.f, 1e-6f);
  p.beta = 3.f;
  EXPECT_NEAR(mis_weight(Heuristic::power, qa, qb, p), 27.f / 28.f, 1e-5f);
  p.alpha = 0.5f;  // 1 < 0.5 * 3: b is cut off
  EXPECT_EQ(mis_weight(Heuristic::cutoff, qa, qb, p), 1.f);
  EXPECT_EQ(mis_weight(Heuristic::cutoff, qb, qa, p), 0.f);
  p.alpha = 0.2f;  // both above the cutoff: balance among them
  EXPECT_NEAR(mis_weight(Heuristic::cutoff, qa, qb, p), 0.75f, 1e-6f);
  EXPECT_EQ(mis_weight(Heuristic::maximum, qa, qb, p), 1.f);
  EXPECT_EQ(mis_weight(Heuristic::maximum, qb, qa, p), 0.f);
  // limits: a zero-density technique gets nothing, the other everything
  EXPECT_EQ(mis_weight(Heuristic::power, 0.f, 1.f, p), 0.f);
  EXPECT_EQ(mis_weight(Heuristic::power, 1.f, 0.f, p), 1.f);
  EXPECT_EQ(mis_weight(Heuristic::balance, 1e30f, 1e-30f, p), 1.f);
}

TEST(Mis, EveryLaneEqualsScalar) {
  const std::vector<float> v = extreme_values();
  alignas(64) float a[simd_width], b[simd_width], out[simd_width];
  for (Heuristic h : all_h)
    for (float beta : {2.f, 1.5f}) {
      MisParams p;
      p.beta = beta;
      for (size_t start = 0; start < v.size() * v.size(); start += simd_width) {
        for (int l = 0; l < simd_width; ++l) {
          const size_t k = (start + l) % (v.size() * v.size());
          a[l] = v[k / v.size()];
          b[l] = v[k % v.size()];
        }
        mis_weight(h, vfloat::load_aligned(a), vfloat::load_aligned(b), p).store_aligned(out);
        for (int l = 0; l < simd_width; ++l) {
          const float s = mis_weight(h, a[l], b[l], p);
          // exp/log of the batch may differ from libm by an ulp for non-integer beta
          if (beta == 2.f) ASSERT_EQ(out[l], s) << a[l] << " " << b[l];
          else ASSERT_NEAR(out[l], s, 4e-7f * std::max(1.f, s)) << a[l] << " " << b[l];
        }
      }
    }
}
