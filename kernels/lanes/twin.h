// Twin<V>: two lane batches as one lane type (vfloat2 = two vfloat, vfloat4 = two
// vfloat2), for latency-bound kernels that run several independent chains at once, and
// for_lane_batches, which walks a range widest batch first.
#pragma once
#include "lanes/simd.h"

namespace tuile {

// Two batches as one lane type, for latency-bound kernels (the solid-angle light stage is a
// chain of square roots, divisions and polynomials: one batch at a time leaves the core
// waiting). Every operation is issued for both halves back to back, so the two dependency
// chains overlap. Half a is lanes [0, W), half b lanes [W, 2W).
template <class V> struct Twin {
  static constexpr std::size_t size = 2 * V::size;
  V a, b;
  Twin() = default;
  Twin(const V& x, const V& y) : a(x), b(y) {}
  template <class S, class = std::enable_if_t<std::is_arithmetic_v<S>>> Twin(S s) : a(V(s)), b(V(s)) {}
};
using vfloat2 = Twin<vfloat>;
using vint2 = Twin<vint>;
using vmask2 = Twin<vmask>;
using vimask2 = Twin<xsimd::batch_bool<int32_t>>;

// Twin<vfloat> (two batches) and Twin<Twin<vfloat>> (four): the lane types of the
// latency-bound stages.
template <class V> struct lane_traits<Twin<V>> {
  using mask = Twin<typename lane_traits<V>::mask>;
  using i32 = Twin<typename lane_traits<V>::i32>;
  using u32 = Twin<typename lane_traits<V>::u32>;
  static constexpr int width = 2 * lane_traits<V>::width;
};
using vfloat4 = Twin<vfloat2>;

#define TUILE_TWIN_BINARY(op)                                                                                 \
  template <class V> inline auto operator op(const Twin<V>& x, const Twin<V>& y) noexcept {                  \
    return Twin<decltype(x.a op y.a)>(x.a op y.a, x.b op y.b);                                                \
  }                                                                                                           \
  template <class V, class S, class = std::enable_if_t<std::is_arithmetic_v<S>>>                              \
  inline auto operator op(const Twin<V>& x, S s) noexcept {                                                   \
    return x op Twin<V>(s);                                                                                   \
  }                                                                                                           \
  template <class V, class S, class = std::enable_if_t<std::is_arithmetic_v<S>>>                              \
  inline auto operator op(S s, const Twin<V>& y) noexcept {                                                   \
    return Twin<V>(s) op y;                                                                                   \
  }
TUILE_TWIN_BINARY(+)
TUILE_TWIN_BINARY(-)
TUILE_TWIN_BINARY(*)
TUILE_TWIN_BINARY(/)
TUILE_TWIN_BINARY(<)
TUILE_TWIN_BINARY(<=)
TUILE_TWIN_BINARY(>)
TUILE_TWIN_BINARY(>=)
TUILE_TWIN_BINARY(==)
TUILE_TWIN_BINARY(!=)
TUILE_TWIN_BINARY(&&)
TUILE_TWIN_BINARY(||)
TUILE_TWIN_BINARY(&)
TUILE_TWIN_BINARY(|)
#undef TUILE_TWIN_BINARY
// shifts of integer lanes by one count for every lane
template <class V> inline Twin<V> operator>>(const Twin<V>& x, int s) noexcept { return {x.a >> s, x.b >> s}; }
template <class V> inline Twin<V> operator<<(const Twin<V>& x, int s) noexcept { return {x.a << s, x.b << s}; }
template <class V> inline Twin<V> operator-(const Twin<V>& x) noexcept { return {-x.a, -x.b}; }
template <class V> inline Twin<V> operator!(const Twin<V>& x) noexcept { return {!x.a, !x.b}; }
template <class V> inline Twin<V>& operator+=(Twin<V>& x, const Twin<V>& y) noexcept {
  x.a += y.a;
  x.b += y.b;
  return x;
}

#define TUILE_TWIN_UNARY(fn) \
  template <class V> inline Twin<V> fn(const Twin<V>& x) noexcept { return {fn(x.a), fn(x.b)}; }
TUILE_TWIN_UNARY(abs)
TUILE_TWIN_UNARY(sqrt)
TUILE_TWIN_UNARY(floor)
TUILE_TWIN_UNARY(finite_or_zero)
TUILE_TWIN_UNARY(exp)
TUILE_TWIN_UNARY(log)
TUILE_TWIN_UNARY(rcp_nr)
TUILE_TWIN_UNARY(rsqrt_nr)
#undef TUILE_TWIN_UNARY
template <class V> inline Twin<V> mul_add(const Twin<V>& x, const Twin<V>& y, const Twin<V>& z) noexcept {
  return {mul_add(x.a, y.a, z.a), mul_add(x.b, y.b, z.b)};
}
template <class V> inline Twin<V> min(const Twin<V>& x, const Twin<V>& y) noexcept { return {min(x.a, y.a), min(x.b, y.b)}; }
template <class V> inline Twin<V> max(const Twin<V>& x, const Twin<V>& y) noexcept { return {max(x.a, y.a), max(x.b, y.b)}; }
template <class V> inline auto is_finite(const Twin<V>& x) noexcept {
  return Twin<decltype(is_finite(x.a))>(is_finite(x.a), is_finite(x.b));
}
template <class M, class V> inline Twin<V> sel(const Twin<M>& m, const Twin<V>& x, const Twin<V>& y) noexcept {
  return {sel(m.a, x.a, y.a), sel(m.b, x.b, y.b)};
}
template <class M> inline Twin<M> sel_mask(const Twin<M>& m, const Twin<M>& x, const Twin<M>& y) noexcept {
  return {sel_mask(m.a, x.a, y.a), sel_mask(m.b, x.b, y.b)};
}
template <class M> inline bool any(const Twin<M>& m) noexcept { return any(m.a || m.b); }
template <class M> inline bool all(const Twin<M>& m) noexcept { return all(m.a && m.b); }
template <class M> inline bool none(const Twin<M>& m) noexcept { return !any(m); }
template <class V> inline auto to_i32(const Twin<V>& x) noexcept { return Twin<decltype(to_i32(x.a))>(to_i32(x.a), to_i32(x.b)); }
template <class V> inline auto to_f32(const Twin<V>& x) noexcept { return Twin<decltype(to_f32(x.a))>(to_f32(x.a), to_f32(x.b)); }
template <class M> inline auto f_mask_from_i(const Twin<M>& m) noexcept {
  return Twin<decltype(f_mask_from_i(m.a))>(f_mask_from_i(m.a), f_mask_from_i(m.b));
}
template <class M> inline auto i_mask_from_f(const Twin<M>& m) noexcept {
  return Twin<decltype(i_mask_from_f(m.a))>(i_mask_from_f(m.a), i_mask_from_f(m.b));
}
template <class V> inline void store(float* p, const Twin<V>& v) noexcept {
  store(p, v.a);
  store(p + V::size, v.b);
}
template <class V> inline void store(int32_t* p, const Twin<V>& v) noexcept {
  store(p, v.a);
  store(p + V::size, v.b);
}
template <class I> inline auto gather(const float* base, const Twin<I>& i) noexcept {
  return Twin<decltype(gather(base, i.a))>(gather(base, i.a), gather(base, i.b));
}
template <class I> inline Twin<I> gather(const int32_t* base, const Twin<I>& i) noexcept { return {gather(base, i.a), gather(base, i.b)}; }
template <class I> inline auto lookup_small(const float* base, const Twin<I>& i) noexcept {
  return Twin<decltype(lookup_small(base, i.a))>(lookup_small(base, i.a), lookup_small(base, i.b));
}
template <class I> inline Twin<I> lookup_small(const int32_t* base, const Twin<I>& i) noexcept {
  return {lookup_small(base, i.a), lookup_small(base, i.b)};
}
template <class I> inline auto lookup_medium(const float* base, const Twin<I>& i) noexcept {
  return Twin<decltype(lookup_medium(base, i.a))>(lookup_medium(base, i.a), lookup_medium(base, i.b));
}
template <class I> inline Twin<I> lookup_medium(const int32_t* base, const Twin<I>& i) noexcept {
  return {lookup_medium(base, i.a), lookup_medium(base, i.b)};
}

// Runs f(std::type_identity<T>{}, k) for batches k of lanes [k0, count) of lane type T
// while they fit, then of each narrower half down to vfloat (count a multiple of
// simd_width): the latency-bound stages take the widest twin first. Returns the end.
template <class T, class F> inline int for_lane_batches(int k0, int count, F&& f) {
  int k = k0;
  for (; k + lane_traits<T>::width <= count; k += lane_traits<T>::width) f(std::type_identity<T>{}, k);
  if constexpr (std::is_same_v<T, vfloat>) return k;
  else return for_lane_batches<decltype(T::a)>(k, count, f);
}

// Lane-type generic forms of what differs between float, vfloat and the twins.
template <class T> inline T load(const float* p) noexcept {
  if constexpr (std::is_same_v<T, float>) return *p;
  else if constexpr (std::is_same_v<T, vfloat>) return vfloat::load_unaligned(p);
  else return T(load<decltype(T::a)>(p), load<decltype(T::a)>(p + lane_traits<T>::width / 2));
}
template <class T> inline i32_t<T> load_i32(const int32_t* p) noexcept {
  if constexpr (std::is_same_v<T, float>) return *p;
  else if constexpr (std::is_same_v<T, vfloat>) return vint::load_unaligned(p);
  else return i32_t<T>(load_i32<decltype(T::a)>(p), load_i32<decltype(T::a)>(p + lane_traits<T>::width / 2));
}
template <class T> inline T lane_iota() noexcept {
  if constexpr (std::is_same_v<T, float>) return 0.f;
  else if constexpr (std::is_same_v<T, vfloat>) {
    alignas(64) float v[simd_width];
    for (int i = 0; i < simd_width; ++i) v[i] = static_cast<float>(i);
    return vfloat::load_aligned(v);
  } else {
    using H = decltype(T::a);
    const H lo = lane_iota<H>();
    return T(lo, lo + H(static_cast<float>(lane_traits<H>::width)));
  }
}
// number of set lanes
inline int count(bool m) noexcept { return m ? 1 : 0; }
inline int count(const vmask& m) noexcept { return std::popcount(lane_bits(m)); }
template <class M> inline int count(const Twin<M>& m) noexcept { return count(m.a) + count(m.b); }
// -1 (all bits) where the mask is set, else 0: Embree's valid arrays
inline void store_valid(int32_t* p, bool m) noexcept { *p = m ? -1 : 0; }
inline void store_valid(int32_t* p, const vmask& m) noexcept {
  xsimd::select(i_mask_from_f(m), vint(-1), vint(0)).store_unaligned(p);
}
template <class M> inline void store_valid(int32_t* p, const Twin<M>& m) noexcept {
  store_valid(p, m.a);
  store_valid(p + M::size, m.b);
}

}  // namespace tuile
