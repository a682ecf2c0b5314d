// Lane types: every kernel is written once, templated on T = float (the scalar
// reference) or T = vfloat (one xsimd batch, the width of the build machine).
// The helpers below give both the same spelling: sel, any, all, gathers, casts.
#pragma once
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>
#include <type_traits>
// GCC 12's AVX-512 intrinsic headers warn about their own _mm512_undefined_* values once
// inlined (GCC bug 105593, fixed in GCC 13); silence that inside these headers only.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>
#include <xsimd/xsimd.hpp>
#pragma GCC diagnostic pop
#else
#include <xsimd/xsimd.hpp>
#endif

// The per-lane stage kernels are flattened (every call inlined), so that the compiler
// schedules a whole lane's chain of maps at once. Not under AddressSanitizer, where instrumenting the flattened
// bodies takes GCC tens of minutes.
#if defined(__SANITIZE_ADDRESS__)
#define TUILE_FLATTEN
#else
#define TUILE_FLATTEN [[gnu::flatten]]
#endif
// A function the flattened stages call instead of inlining: long, rarely taken paths (an
// environment map's binary searches), whose copies in every flattened stage and lane type
// cost compile time and code size for nothing.
#define TUILE_OUT_OF_LINE [[gnu::noinline]]

namespace tuile {

using vfloat = xsimd::batch<float>;
using vint = xsimd::batch<int32_t>;
using vuint = xsimd::batch<uint32_t>;
using vmask = xsimd::batch_bool<float>;
inline constexpr int simd_width = static_cast<int>(vfloat::size);

// a * b + c, fused (one rounding) where the build has FMA instructions, in the scalar
// reference and in every SIMD lane alike, and a * b + c rounded twice where it has not:
// either way the lanes equal the reference (the build disables implicit contraction).
// (xsimd 8's fma of AVX-512 batches multiplies and adds separately: intrinsics here.)
#if defined(__FMA__)
inline float mul_add(float a, float b, float c) noexcept { return __builtin_fmaf(a, b, c); }
inline vfloat mul_add(const vfloat& a, const vfloat& b, const vfloat& c) noexcept {
#if defined(__AVX512F__)
  return _mm512_fmadd_ps(a, b, c);
#elif defined(__AVX__)
  return _mm256_fmadd_ps(a, b, c);
#else
  return _mm_fmadd_ps(a, b, c);
#endif
}
#else
inline float mul_add(float a, float b, float c) noexcept { return a * b + c; }
inline vfloat mul_add(const vfloat& a, const vfloat& b, const vfloat& c) noexcept { return a * b + c; }
#endif

using std::abs;
using std::sqrt;
using std::min;
using std::max;
using std::fma;
using std::sin;
using std::cos;
using std::acos;
using std::asin;
using std::atan2;
using std::log;
using std::exp;
using std::floor;
using xsimd::abs;
using xsimd::sqrt;
using xsimd::min;
using xsimd::max;
using xsimd::fma;
using xsimd::sin;
using xsimd::cos;
using xsimd::acos;
using xsimd::asin;
using xsimd::atan2;
using xsimd::log;
using xsimd::exp;
using xsimd::floor;

template <class T> struct lane_traits;
template <> struct lane_traits<float> {
  using mask = bool;
  using i32 = int32_t;
  using u32 = uint32_t;
  static constexpr int width = 1;
};
template <> struct lane_traits<vfloat> {
  using mask = vmask;
  using i32 = vint;
  using u32 = vuint;
  static constexpr int width = simd_width;
};
template <class T> using mask_t = typename lane_traits<T>::mask;
template <class T> using i32_t = typename lane_traits<T>::i32;
template <class T> using u32_t = typename lane_traits<T>::u32;

// select
inline float sel(bool m, float a, float b) noexcept { return m ? a : b; }
inline int32_t sel(bool m, int32_t a, int32_t b) noexcept { return m ? a : b; }
inline uint32_t sel(bool m, uint32_t a, uint32_t b) noexcept { return m ? a : b; }
inline vfloat sel(const vmask& m, const vfloat& a, const vfloat& b) noexcept { return xsimd::select(m, a, b); }
inline vint sel(const xsimd::batch_bool<int32_t>& m, const vint& a, const vint& b) noexcept {
  return xsimd::select(m, a, b);
}
inline vuint sel(const xsimd::batch_bool<uint32_t>& m, const vuint& a, const vuint& b) noexcept {
  return xsimd::select(m, a, b);
}

inline bool sel_mask(bool m, bool a, bool b) noexcept { return m ? a : b; }
inline vmask sel_mask(const vmask& m, const vmask& a, const vmask& b) noexcept { return (m && a) || (!m && b); }

inline bool any(bool m) noexcept { return m; }
inline bool all(bool m) noexcept { return m; }
inline bool none(bool m) noexcept { return !m; }
inline bool any(const vmask& m) noexcept { return xsimd::any(m); }
inline bool all(const vmask& m) noexcept { return xsimd::all(m); }
inline bool none(const vmask& m) noexcept { return !xsimd::any(m); }

// conversions between float lanes and integer lanes of the same width
inline int32_t to_i32(float x) noexcept { return static_cast<int32_t>(x); }
inline vint to_i32(const vfloat& x) noexcept { return xsimd::batch_cast<int32_t>(x); }
inline float to_f32(int32_t x) noexcept { return static_cast<float>(x); }
inline vfloat to_f32(const vint& x) noexcept { return xsimd::batch_cast<float>(x); }
inline float u32_to_f32(uint32_t x) noexcept { return static_cast<float>(x); }
inline vfloat u32_to_f32(const vuint& x) noexcept {
  // exact for values below 2^24, which is all the samplers produce
  return xsimd::batch_cast<float>(xsimd::bitwise_cast<vint>(x));
}
inline bool f_mask_from_i(bool m) noexcept { return m; }
inline vmask f_mask_from_i(const xsimd::batch_bool<int32_t>& m) noexcept {
  return xsimd::bitwise_cast<vfloat>(xsimd::select(m, vint(0x3f800000), vint(0))) != vfloat(0.f);
}
inline bool i_mask_from_f(bool m) noexcept { return m; }
inline xsimd::batch_bool<int32_t> i_mask_from_f(const vmask& m) noexcept {
  return xsimd::bitwise_cast<vint>(xsimd::select(m, vfloat(1.f), vfloat(0.f))) != vint(0);
}

// loads and stores of the lane type from/to plain arrays
inline void store(float* p, float v) noexcept { *p = v; }
inline void store(float* p, const vfloat& v) noexcept { v.store_unaligned(p); }
inline void store(int32_t* p, int32_t v) noexcept { *p = v; }
inline void store(int32_t* p, const vint& v) noexcept { v.store_unaligned(p); }
inline void store(uint32_t* p, uint32_t v) noexcept { *p = v; }
inline void store(uint32_t* p, const vuint& v) noexcept { v.store_unaligned(p); }
// gather: v[i] = base[index[i]]
inline float gather(const float* base, int32_t i) noexcept { return base[i]; }
// xsimd 8's gather is element by element through out-of-line templates: use the
// hardware gather where the build has one.
inline vfloat gather(const float* base, const vint& i) noexcept {
#if defined(__AVX512F__)
  static_assert(simd_width == 16);
  return _mm512_i32gather_ps(static_cast<__m512i>(i), base, 4);
#elif defined(__AVX2__)
  static_assert(simd_width == 8);
  return _mm256_i32gather_ps(base, static_cast<__m256i>(i), 4);
#else
  alignas(64) int32_t idx[simd_width];
  alignas(64) float out[simd_width];
  i.store_aligned(idx);
  for (int l = 0; l < simd_width; ++l) out[l] = base[idx[l]];
  return vfloat::load_aligned(out);
#endif
}
// scatter: base[index[i]] = v[i] where m is set (indices distinct)
inline void scatter(float* base, int32_t i, float v, bool m) noexcept {
  if (m) base[i] = v;
}
inline void scatter(float* base, const vint& i, const vfloat& v, const vmask& m) noexcept {
#if defined(__AVX512F__)
  _mm512_mask_i32scatter_ps(base, static_cast<__mmask16>(m), static_cast<__m512i>(i), v, 4);
#else
  alignas(64) int32_t idx[simd_width];
  alignas(64) float val[simd_width], on[simd_width];
  i.store_aligned(idx);
  v.store_aligned(val);
  xsimd::select(m, vfloat(1.f), vfloat(0.f)).store_aligned(on);
  for (int l = 0; l < simd_width; ++l)
    if (on[l] != 0.f) base[idx[l]] = val[l];
#endif
}
inline int32_t gather(const int32_t* base, int32_t i) noexcept { return base[i]; }
inline vint gather(const int32_t* base, const vint& i) noexcept {
#if defined(__AVX512F__)
  static_assert(simd_width == 16);
  return _mm512_i32gather_epi32(static_cast<__m512i>(i), base, 4);
#elif defined(__AVX2__)
  static_assert(simd_width == 8);
  return _mm256_i32gather_epi32(base, static_cast<__m256i>(i), 4);
#else
  alignas(64) int32_t idx[simd_width];
  alignas(64) int32_t out[simd_width];
  i.store_aligned(idx);
  for (int l = 0; l < simd_width; ++l) out[l] = base[idx[l]];
  return vint::load_aligned(out);
#endif
}

// Lookups in a table of at most small_table_size entries whose array is padded to that
// size: two vector loads and a permute instead of a gather (the same values). Tables of
// at most medium_table_size entries, padded to it: eight loads, four permutes of 32
// entries each and three blends (lookup_medium), still cheaper than a gather.
inline constexpr int small_table_size = 32, medium_table_size = 128;
inline float lookup_small(const float* base, int32_t i) noexcept { return base[i]; }
inline int32_t lookup_small(const int32_t* base, int32_t i) noexcept { return base[i]; }
inline float lookup_medium(const float* base, int32_t i) noexcept { return base[i]; }
inline int32_t lookup_medium(const int32_t* base, int32_t i) noexcept { return base[i]; }
#if defined(__AVX512F__)
inline vfloat lookup_small(const float* base, const vint& i) noexcept {
  return _mm512_permutex2var_ps(_mm512_loadu_ps(base), i, _mm512_loadu_ps(base + 16));
}
inline vint lookup_small(const int32_t* base, const vint& i) noexcept {
  return _mm512_permutex2var_epi32(_mm512_loadu_si512(base), i, _mm512_loadu_si512(base + 16));
}
inline vint lookup_medium(const int32_t* base, const vint& i) noexcept {
  const __m512i x = i;
  auto quarter = [&](int q) {  // entries 32 q .. 32 q + 31 by the index's low 5 bits
    return _mm512_permutex2var_epi32(_mm512_loadu_si512(base + 32 * q), x, _mm512_loadu_si512(base + 32 * q + 16));
  };
  const __mmask16 b5 = _mm512_test_epi32_mask(x, _mm512_set1_epi32(32));
  const __mmask16 b6 = _mm512_test_epi32_mask(x, _mm512_set1_epi32(64));
  return _mm512_mask_blend_epi32(b6, _mm512_mask_blend_epi32(b5, quarter(0), quarter(1)),
                                 _mm512_mask_blend_epi32(b5, quarter(2), quarter(3)));
}
inline vfloat lookup_medium(const float* base, const vint& i) noexcept {
  return _mm512_castsi512_ps(lookup_medium(reinterpret_cast<const int32_t*>(base), i));
}
#else
inline vfloat lookup_small(const float* base, const vint& i) noexcept { return gather(base, i); }
inline vint lookup_small(const int32_t* base, const vint& i) noexcept { return gather(base, i); }
inline vfloat lookup_medium(const float* base, const vint& i) noexcept { return gather(base, i); }
inline vint lookup_medium(const int32_t* base, const vint& i) noexcept { return gather(base, i); }
#endif

template <class T> inline i32_t<T> lane_iota_i32() noexcept {
  if constexpr (std::is_same_v<T, float>) return 0;
  else {
    alignas(64) int32_t v[simd_width];
    for (int i = 0; i < simd_width; ++i) v[i] = i;
    return vint::load_aligned(v);
  }
}

// Bit l set where lane l of the mask is.
inline uint32_t lane_bits(bool m) noexcept { return m ? 1u : 0u; }
inline uint32_t lane_bits(const vmask& m) noexcept {
#if defined(__AVX512F__)
  return static_cast<__mmask16>(m);
#elif defined(__AVX__)
  return static_cast<uint32_t>(_mm256_movemask_ps(m));
#else
  return static_cast<uint32_t>(_mm_movemask_ps(m));
#endif
}

// Compaction: writes the lanes of v whose bit is set, in lane order, to dst[0..popcount).
// AVX-512 compresses in a register and stores the whole batch (the memory form of
// vcompressps is microcoded on Zen 4): dst must have room for a whole batch, and the
// lanes past popcount are left with garbage.
inline void compress_store(float* dst, float v, uint32_t bits) noexcept {
  if (bits) *dst = v;
}
inline void compress_store(int32_t* dst, int32_t v, uint32_t bits) noexcept {
  if (bits) *dst = v;
}
#if defined(__AVX512F__)
inline void compress_store(float* dst, const vfloat& v, uint32_t bits) noexcept {
  _mm512_storeu_ps(dst, _mm512_maskz_compress_ps(static_cast<__mmask16>(bits), v));
}
inline void compress_store(int32_t* dst, const vint& v, uint32_t bits) noexcept {
  _mm512_storeu_si512(dst, _mm512_maskz_compress_epi32(static_cast<__mmask16>(bits), v));
}
#else
template <class V, class S> inline void compress_store_lanes(S* dst, const V& v, uint32_t bits) noexcept {
  alignas(64) S tmp[simd_width];
  v.store_aligned(tmp);
  for (int k = 0; bits; ++k, bits &= bits - 1) dst[k] = tmp[std::countr_zero(bits)];
}
inline void compress_store(float* dst, const vfloat& v, uint32_t bits) noexcept { compress_store_lanes(dst, v, bits); }
inline void compress_store(int32_t* dst, const vint& v, uint32_t bits) noexcept { compress_store_lanes(dst, v, bits); }
#endif

// The inverse of compress_store: lane l of the result is the next value of src[0..) where
// bit l is set, 0 where it is not (reads popcount(bits) values).
// expand_index: lane l is first + (number of set bits below l) where bit l is set, else -1.
template <class T> inline T expand_load(const float* src, uint32_t bits) noexcept;
template <class T> inline i32_t<T> expand_index(int32_t first, uint32_t bits) noexcept;
template <> inline float expand_load<float>(const float* src, uint32_t bits) noexcept { return bits ? *src : 0.f; }
template <> inline int32_t expand_index<float>(int32_t first, uint32_t bits) noexcept { return bits ? first : -1; }
#if defined(__AVX512F__)
template <> inline vfloat expand_load<vfloat>(const float* src, uint32_t bits) noexcept {
  return _mm512_maskz_expandloadu_ps(static_cast<__mmask16>(bits), src);
}
template <> inline vint expand_index<vfloat>(int32_t first, uint32_t bits) noexcept {
  return _mm512_mask_expand_epi32(_mm512_set1_epi32(-1), static_cast<__mmask16>(bits),
                                  _mm512_add_epi32(_mm512_set1_epi32(first), lane_iota_i32<vfloat>()));
}
#else
template <> inline vfloat expand_load<vfloat>(const float* src, uint32_t bits) noexcept {
  alignas(64) float tmp[simd_width];
  for (int l = 0, k = 0; l < simd_width; ++l) tmp[l] = (bits >> l) & 1u ? src[k++] : 0.f;
  return vfloat::load_aligned(tmp);
}
template <> inline vint expand_index<vfloat>(int32_t first, uint32_t bits) noexcept {
  alignas(64) int32_t tmp[simd_width];
  for (int l = 0, k = first; l < simd_width; ++l) tmp[l] = (bits >> l) & 1u ? k++ : -1;
  return vint::load_aligned(tmp);
}
#endif

inline float finite_or_zero(float x) noexcept { return std::isfinite(x) ? x : 0.f; }
inline vfloat finite_or_zero(const vfloat& x) noexcept {
  return xsimd::select(xsimd::abs(x) <= vfloat(3.4028234e38f), x, vfloat(0.f));
}
inline bool is_finite(float x) noexcept { return std::isfinite(x); }
inline vmask is_finite(const vfloat& x) noexcept { return xsimd::abs(x) <= vfloat(3.4028234e38f); }

// 1 / x and 1 / sqrt(x) for positive finite x, from the hardware's 14-bit estimate
// (vrcp14 / vrsqrt14) refined by one Newton step, pipelined where division and square root
// are not (a 16-lane vdivps or vsqrtps occupies the divider for about 10 cycles). Builds
// without AVX-512 divide exactly. Scalar and SIMD use the same instructions, so they agree
// bit for bit on one machine; across vendors they need not: the estimates are specified
// only to a relative error |e| <= 2^-14, and processors return different bits.
//
// Error after the Newton step, with r0 = (1 + e) / x (resp. (1 + e) / sqrt(x)):
//   rcp:   r1 = r0 (2 - x r0) = (1 - e^2) / x, plus 2 roundings (fma, product);
//   rsqrt: r1 = r0 (1.5 - 0.5 x r0^2) = (1 - 1.5 e^2 - 0.5 e^3) / sqrt(x), plus 4 roundings.
// For |e| <= 2^-13 (the documented bound doubled) e^2 <= 2^-26 = ulp / 8, so both results
// are within 3 ulps (rcp) and 3.5 ulps (rsqrt) of the exact value on any processor. Every
// accuracy a test checks must hold within those bounds, not for one vendor's bits: the test
// builds prove it by replacing the estimate (TUILE_ESTIMATES, set by the CMake option of
// that name):
//   0 (default) the hardware estimate;
//   1, -1       the hardware estimate times 1 + 2^-14, resp. 1 - 2^-14: another vendor's
//               estimate at the far end of the documented error, both ways;
//   2           exact IEEE division and square root (as builds without AVX-512);
//   3           one of 0, 1, -1, 2 chosen when the program starts, by the environment
//               variable TUILE_ESTIMATE_MODE (hardware, plus, minus, exact; hardware when
//               unset): the precision checks compile their sources once and run them three
//               times (CMakeLists.txt: the tests estimates_plus/..., estimates_minus/..., estimates_exact/...),
//               with the same arithmetic as the builds of 1, -1 and 2.
#ifndef TUILE_ESTIMATES
#define TUILE_ESTIMATES 0
#endif
static_assert(TUILE_ESTIMATES == 0 || TUILE_ESTIMATES == 1 || TUILE_ESTIMATES == -1 || TUILE_ESTIMATES == 2 ||
                  TUILE_ESTIMATES == 3,
              "TUILE_ESTIMATES is 0 (hardware), 1 or -1 (perturbed by +-2^-14), 2 (exact) or 3 (chosen at start-up)");
#if TUILE_ESTIMATES == 3
struct EstimateMode {
  float scale = 1.f;   // what the hardware estimate is multiplied by
  bool exact = false;  // exact IEEE division and square root instead
};
// Read once, at the first use. A value other than the four stops the program: a precision
// check that ran with the wrong estimates would prove nothing.
inline EstimateMode estimate_mode_from_environment() noexcept {
  const char* s = std::getenv("TUILE_ESTIMATE_MODE");
  const std::string_view m = s ? s : "hardware";
  if (m == "hardware") return {};
  if (m == "plus") return {1.f + 0x1p-14f, false};
  if (m == "minus") return {1.f - 0x1p-14f, false};
  if (m == "exact") return {1.f, true};
  std::fprintf(stderr, "TUILE_ESTIMATE_MODE is hardware, plus, minus or exact, not '%s'\n", s);
  std::abort();
}
inline const EstimateMode& estimate_mode() noexcept {
  static const EstimateMode m = estimate_mode_from_environment();
  return m;
}
#define TUILE_EXACT_AT_RUN_TIME(exact_value) \
  if (estimate_mode().exact) return exact_value
#else
#define TUILE_EXACT_AT_RUN_TIME(exact_value)
#endif
#if defined(__AVX512F__) && TUILE_ESTIMATES != 2
#define TUILE_HW_ESTIMATES 1
inline constexpr float estimate_scale = TUILE_ESTIMATES == 1 ? 1.f + 0x1p-14f : TUILE_ESTIMATES == -1 ? 1.f - 0x1p-14f : 1.f;
template <class T> inline T perturb_estimate(const T& r) noexcept {
#if TUILE_ESTIMATES == 3
  return r * T(estimate_mode().scale);
#else
  if constexpr (TUILE_ESTIMATES == 0) return r;
  else return r * T(estimate_scale);
#endif
}
#else
#define TUILE_HW_ESTIMATES 0
#endif

inline float rcp_nr(float x) noexcept {
#if TUILE_HW_ESTIMATES
  TUILE_EXACT_AT_RUN_TIME(1.f / x);
  const float r = perturb_estimate(_mm_cvtss_f32(_mm_rcp14_ss(_mm_setzero_ps(), _mm_set_ss(x))));
  return r * mul_add(-x, r, 2.f);
#else
  return 1.f / x;
#endif
}
inline vfloat rcp_nr(const vfloat& x) noexcept {
#if TUILE_HW_ESTIMATES
  TUILE_EXACT_AT_RUN_TIME(vfloat(1.f) / x);
  const vfloat r = perturb_estimate(vfloat(_mm512_rcp14_ps(x)));
  return r * mul_add(-x, r, vfloat(2.f));
#else
  return vfloat(1.f) / x;
#endif
}
inline float rsqrt_nr(float x) noexcept {
#if TUILE_HW_ESTIMATES
  TUILE_EXACT_AT_RUN_TIME(1.f / std::sqrt(x));
  const float r = perturb_estimate(_mm_cvtss_f32(_mm_rsqrt14_ss(_mm_setzero_ps(), _mm_set_ss(x))));
  return r * mul_add(-((0.5f * x) * r), r, 1.5f);  // no r * r: it overflows for x near the smallest floats
#else
  return 1.f / std::sqrt(x);
#endif
}
inline vfloat rsqrt_nr(const vfloat& x) noexcept {
#if TUILE_HW_ESTIMATES
  TUILE_EXACT_AT_RUN_TIME(vfloat(1.f) / xsimd::sqrt(x));
  const vfloat r = perturb_estimate(vfloat(_mm512_rsqrt14_ps(x)));
  return r * mul_add(-((vfloat(0.5f) * x) * r), r, vfloat(1.5f));
#else
  return vfloat(1.f) / xsimd::sqrt(x);
#endif
}

// Zeroes zmm16-zmm31 before foreign code runs. vzeroupper (which GCC emits at function
// exits) does not clear them, and while they hold data some cores run the code that
// follows with a penalty (Embree's coherent camera packets after the Sobol' kernels, which
// use all 32 registers; bench/results.md has the figures).
inline void clear_high_vector_registers() noexcept {
#if defined(__AVX512F__) && defined(__GNUC__)
  asm volatile(
      "vpxord %%xmm16, %%xmm16, %%xmm16\n\tvpxord %%xmm17, %%xmm17, %%xmm17\n\t"
      "vpxord %%xmm18, %%xmm18, %%xmm18\n\tvpxord %%xmm19, %%xmm19, %%xmm19\n\t"
      "vpxord %%xmm20, %%xmm20, %%xmm20\n\tvpxord %%xmm21, %%xmm21, %%xmm21\n\t"
      "vpxord %%xmm22, %%xmm22, %%xmm22\n\tvpxord %%xmm23, %%xmm23, %%xmm23\n\t"
      "vpxord %%xmm24, %%xmm24, %%xmm24\n\tvpxord %%xmm25, %%xmm25, %%xmm25\n\t"
      "vpxord %%xmm26, %%xmm26, %%xmm26\n\tvpxord %%xmm27, %%xmm27, %%xmm27\n\t"
      "vpxord %%xmm28, %%xmm28, %%xmm28\n\tvpxord %%xmm29, %%xmm29, %%xmm29\n\t"
      "vpxord %%xmm30, %%xmm30, %%xmm30\n\tvpxord %%xmm31, %%xmm31, %%xmm31" ::
          : "xmm16", "xmm17", "xmm18", "xmm19", "xmm20", "xmm21", "xmm22", "xmm23", "xmm24", "xmm25", "xmm26",
            "xmm27", "xmm28", "xmm29", "xmm30", "xmm31");
#endif
}

} // namespace tuile
