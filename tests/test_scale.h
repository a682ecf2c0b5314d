// The one knob of the statistical tests' size: TUILE_TEST_SCALE (a CMake cache variable, 1
// unless set). CI's sanitizer tree sets 32, where the instrumented renders run ten or more
// times slower; the native and portable trees keep 1, the full size.
//
// A test that uses it draws scaled(n) samples instead of n (or renders at a scaled
// resolution), and computes its confidence from the samples it drew, never from a widened
// tolerance: a z-test divides by the standard error of the smaller sample, a chi-square
// test pools cells to the expected counts of the smaller sample and takes its degrees of
// freedom from them, a fixed-error bound is the same multiple of sigma / sqrt(scaled n). The
// false-alarm probability of each test stays what its comment states; only its power falls.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>

#ifndef TUILE_TEST_SCALE
#define TUILE_TEST_SCALE 1
#endif

namespace tuile::test {

inline constexpr uint32_t test_scale = TUILE_TEST_SCALE;
static_assert(test_scale >= 1, "TUILE_TEST_SCALE is at least 1");

// n samples (or passes, or pixels per side) divided by the knob, at least lo (a floor
// where a heavy-tailed estimator needs that many for its standard error to be honest), and
// never more than n.
template <class T> constexpr T scaled(T n, T lo = T(1)) {
  return std::max(std::min(lo, n), static_cast<T>(n / static_cast<T>(test_scale)));
}
// How much a standard error grows when n becomes scaled(n, lo): sqrt(n / scaled(n, lo)).
template <class T> inline double sigma_growth(T n, T lo = T(1)) {
  return std::sqrt(static_cast<double>(n) / static_cast<double>(scaled(n, lo)));
}

}  // namespace tuile::test
