// Elementary functions (sin, cos, atan2, asin) for both lane types, from +, -, *, /,
// sqrt and floor only. Those are correctly rounded in IEEE arithmetic, so every SIMD lane
// gives the same bits as the scalar reference (as long as the compiler does not fuse a*b+c
// differently in the two instantiations: the build uses -ffp-contract=off and writes fused
// steps out as mul_add).
#pragma once
#include <bit>
#include <cstdint>

#include "lanes/simd.h"
#include "lanes/twin.h"

namespace tuile {

inline constexpr float pi_f = 3.14159265358979323846f;
inline constexpr float two_pi_f = 6.28318530717958647692f;
inline constexpr float inv_pi_f = 0.318309886183790671538f;
inline constexpr float inv_four_pi_f = 0.0795774715459476678844f;

// Lane-generic elementary functions (bit-identical for float and vfloat). Calls between
// them are qualified: unqualified, ADL would pick xsimd's own atan2/asin for batches.
namespace lane_math {

// sin and cos for |x| <= pi/4 (Taylor series, truncation error < 1e-11).
template <class T> inline void sincos_reduced(const T& x, T& s, T& c) noexcept {
  const T x2 = x * x;
  T ps = T(-2.5052108385441718775e-8f);
  ps = mul_add(ps, x2, T(2.7557319223985890653e-6f));
  ps = mul_add(ps, x2, T(-1.9841269841269841270e-4f));
  ps = mul_add(ps, x2, T(8.3333333333333333333e-3f));
  ps = mul_add(ps, x2, T(-1.6666666666666666667e-1f));
  s = mul_add(x * x2, ps, x);
  T pc = T(2.0876756987868098979e-9f);
  pc = mul_add(pc, x2, T(-2.7557319223985890653e-7f));
  pc = mul_add(pc, x2, T(2.4801587301587301587e-5f));
  pc = mul_add(pc, x2, T(-1.3888888888888888889e-3f));
  pc = mul_add(pc, x2, T(4.1666666666666666667e-2f));
  pc = mul_add(pc, x2, T(-0.5f));
  c = mul_add(x2, pc, T(1.f));
}

// Rotate (s, c) = (sin r, cos r) by q quarter turns, q an integer-valued float.
template <class T> inline void rotate_quadrant(const T& q, T& s, T& c) noexcept {
  const T m = q - T(4.f) * floor(q * T(0.25f));  // 0, 1, 2, 3
  const mask_t<T> odd = m == T(1.f) || m == T(3.f);
  const T s1 = sel(odd, c, s), c1 = sel(odd, s, c);
  s = sel(m >= T(2.f), -s1, s1);                          // quadrants 2, 3: sin < 0
  c = sel(m == T(1.f) || m == T(2.f), -c1, c1);           // quadrants 1, 2: cos < 0
}

// sin and cos for |x| <= 100 (Cody-Waite reduction by pi/2; the high part of pi/2 has
// 8 significant bits, so q * hi is exact).
template <class T> inline void sincos(const T& x, T& s, T& c) noexcept {
  const T q = floor(x * T(0.636619772367581343076f) + T(0.5f));
  const T r = (x - q * T(1.5703125f)) - q * T(4.83826794897e-4f);
  lane_math::sincos_reduced(r, s, c);
  lane_math::rotate_quadrant(q, s, c);
}

// sin and cos of 2 pi u for any |u| <= 2^20, reduced exactly in turns.
template <class T> inline void sincos_2pi(const T& u, T& s, T& c) noexcept {
  const T u4 = u * T(4.f);
  const T q = floor(u4 + T(0.5f));
  lane_math::sincos_reduced((u4 - q) * T(1.57079632679489661923f), s, c);
  lane_math::rotate_quadrant(q, s, c);
}

// atan(z) for |z| <= tan(pi/8) (Taylor series to z^17, relative error < 1e-8).
template <class T> inline T atan_reduced(const T& z) noexcept {
  const T z2 = z * z;
  T p = T(1.f / 17.f);
  p = mul_add(p, z2, T(-1.f / 15.f));
  p = mul_add(p, z2, T(1.f / 13.f));
  p = mul_add(p, z2, T(-1.f / 11.f));
  p = mul_add(p, z2, T(1.f / 9.f));
  p = mul_add(p, z2, T(-1.f / 7.f));
  p = mul_add(p, z2, T(1.f / 5.f));
  p = mul_add(p, z2, T(-1.f / 3.f));
  return mul_add(z * z2, p, z);
}

// atan2(y, x) in [-pi, pi]; 0 for (0, 0).
template <class T> inline T atan2(const T& y, const T& x) noexcept {
  const T ax = abs(x), ay = abs(y);
  const T mx = max(ax, ay), mn = min(ax, ay);
  // z = r or (r - 1) / (r + 1) with r = mn / mx in [0, 1], in one division
  const mask_t<T> big = mn > T(0.414213562373095048802f) * mx;
  const T z = sel(big, mn - mx, mn) / sel(big, mn + mx, sel(mx > T(0.f), mx, T(1.f)));
  T a = lane_math::atan_reduced(z) + sel(big, T(0.785398163397448309616f), T(0.f));
  a = sel(ay > ax, T(1.57079632679489661923f) - a, a);
  a = sel(x < T(0.f), T(pi_f) - a, a);
  return sel(y < T(0.f), -a, a);
}

// asin(t) for t in [-1, 1] (clamped), accurate near 0 and near +-1.
template <class T> inline T asin(const T& t) noexcept {
  const T tc = min(max(t, T(-1.f)), T(1.f));
  return lane_math::atan2(tc, sqrt((T(1.f) - tc) * (T(1.f) + tc)));
}

// 2^n for integer-valued n in [-126, 127], by building the float's exponent bits.
inline float pow2_int(float n) noexcept { return std::bit_cast<float>((static_cast<int32_t>(n) + 127) << 23); }
inline vfloat pow2_int(const vfloat& n) noexcept {
  return xsimd::bitwise_cast<vfloat>((xsimd::batch_cast<int32_t>(n) + vint(127)) << 23);
}
template <class V> inline Twin<V> pow2_int(const Twin<V>& n) noexcept { return {pow2_int(n.a), pow2_int(n.b)}; }

// exp(x) for -87 <= x <= hi, clamped to that range (0 below -87: e^-87 is 1.6e-38, near the
// smallest normal float), from +, -, *, floor and mul_add: the same bits in every lane
// (xsimd's exp and the C library's differ). Cody-Waite reduction x = n ln2 + r, |r| <= ln2 / 2,
// and the Taylor series of e^r to r^8 (truncation < 3e-10 relative).
template <class T> inline T exp_range(const T& x, float hi) noexcept {
  const T xc = max(min(x, T(hi)), T(-87.f));
  const T n = floor(mul_add(xc, T(1.44269504088896341f), T(0.5f)));
  const T r = mul_add(n, T(-1.42860677e-6f), mul_add(n, T(-0.693145752f), xc));
  T p = T(1.f / 40320.f);
  p = mul_add(p, r, T(1.f / 5040.f));
  p = mul_add(p, r, T(1.f / 720.f));
  p = mul_add(p, r, T(1.f / 120.f));
  p = mul_add(p, r, T(1.f / 24.f));
  p = mul_add(p, r, T(1.f / 6.f));
  p = mul_add(p, r, T(0.5f));
  p = mul_add(p, r, T(1.f));
  p = mul_add(p, r, T(1.f));
  return sel(x >= T(-87.f), p * pow2_int(n), T(0.f));
}

// exp(x) for x <= 0: the coated BSDFs' layer transmittance, the Gaussian pixel filter, the
// hair's interior transmittance and logistic.
template <class T> inline T exp_nonpositive(const T& x) noexcept { return lane_math::exp_range(x, 0.f); }

// exp(x) for any x: 0 below -87, clamped at 88 (e^88 is 1.65e38, near float's largest);
// relative error < 1e-7 over the range (the hair's Mp).
template <class T> inline T exp_clamped(const T& x) noexcept { return lane_math::exp_range(x, 88.f); }

// A positive normal float's biased exponent field (as a float) and its significand with
// the exponent of 1 (in [1, 2)): the bits, read the same way for every lane type.
inline void split_float(float x, float& biased_exp, float& m) noexcept {
  const auto i = std::bit_cast<int32_t>(x);
  biased_exp = static_cast<float>(i >> 23);
  m = std::bit_cast<float>((i & 0x007fffff) | 0x3f800000);
}
inline void split_float(const vfloat& x, vfloat& biased_exp, vfloat& m) noexcept {
  const vint i = xsimd::bitwise_cast<vint>(x);
  biased_exp = xsimd::batch_cast<float>(i >> 23);
  m = xsimd::bitwise_cast<vfloat>((i & vint(0x007fffff)) | vint(0x3f800000));
}
template <class V> inline void split_float(const Twin<V>& x, Twin<V>& biased_exp, Twin<V>& m) noexcept {
  split_float(x.a, biased_exp.a, m.a);
  split_float(x.b, biased_exp.b, m.b);
}

// log(x) for x > 0 (x below the smallest normal float, 1.18e-38, is taken as it; +inf
// and NaN are not expected). x = m 2^e with m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(s),
// s = (m - 1) / (m + 1), |s| <= 0.1716, by its series to s^15 (truncation < 1e-13); e ln2
// in two parts (Cody-Waite). Relative error < 2e-7 away from x = 1, absolute < 1e-7 near it.
template <class T> inline T log_positive(const T& x) noexcept {
  const T xc = max(x, T(1.17549435e-38f));
  T be, m;
  lane_math::split_float(xc, be, m);
  const mask_t<T> big = m > T(1.41421356237309505f);
  m = sel(big, m * T(0.5f), m);
  const T e = be - T(127.f) + sel(big, T(1.f), T(0.f));
  const T s = (m - T(1.f)) / (m + T(1.f));
  const T s2 = s * s;
  T p = T(2.f / 15.f);
  p = mul_add(p, s2, T(2.f / 13.f));
  p = mul_add(p, s2, T(2.f / 11.f));
  p = mul_add(p, s2, T(2.f / 9.f));
  p = mul_add(p, s2, T(2.f / 7.f));
  p = mul_add(p, s2, T(2.f / 5.f));
  p = mul_add(p, s2, T(2.f / 3.f));
  const T logm = mul_add(s * s2, p, s * T(2.f));
  return mul_add(e, T(0.693145752f), mul_add(e, T(1.42860677e-6f), logm));
}

} // namespace lane_math

}  // namespace tuile
