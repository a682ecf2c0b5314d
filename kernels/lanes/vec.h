// Vec3<T> for T = float or vfloat: the geometry of every kernel, written once.
#pragma once
#include "lanes/twin.h"

namespace tuile {

template <class T> struct Vec3 {
  T x, y, z;
  Vec3() = default;
  constexpr Vec3(T a, T b, T c) : x(a), y(b), z(c) {}
  template <class U, class = std::enable_if_t<!std::is_same_v<U, T>>>
  explicit Vec3(const Vec3<U>& o) : x(T(o.x)), y(T(o.y)), z(T(o.z)) {}
};
using vec3f = Vec3<float>;

template <class T> inline Vec3<T> operator+(const Vec3<T>& a, const Vec3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T> inline Vec3<T> operator-(const Vec3<T>& a, const Vec3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T> inline Vec3<T> operator-(const Vec3<T>& a) { return {-a.x, -a.y, -a.z}; }
template <class T> inline Vec3<T> operator*(const Vec3<T>& a, const T& s) { return {a.x * s, a.y * s, a.z * s}; }
template <class T> inline Vec3<T> operator*(const T& s, const Vec3<T>& a) { return {a.x * s, a.y * s, a.z * s}; }
template <class T> inline Vec3<T> operator*(const Vec3<T>& a, const Vec3<T>& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
template <class T> inline Vec3<T> operator/(const Vec3<T>& a, const T& s) { return {a.x / s, a.y / s, a.z / s}; }
// With fused multiply-adds (mul_add: the same bits in every lane and the reference).
template <class T> inline T dot(const Vec3<T>& a, const Vec3<T>& b) {
  return mul_add(a.x, b.x, mul_add(a.y, b.y, a.z * b.z));
}
// Each component as a product minus a product with one fused step; the rounding of the
// other product stays (Kahan's exact difference of products costs two more operations).
template <class T> inline Vec3<T> cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {mul_add(a.y, b.z, -(a.z * b.y)), mul_add(a.z, b.x, -(a.x * b.z)), mul_add(a.x, b.y, -(a.y * b.x))};
}
template <class T> inline T length_sq(const Vec3<T>& a) { return dot(a, a); }
template <class T> inline T length(const Vec3<T>& a) { return sqrt(dot(a, a)); }
// a / |a| with the reciprocal square root estimate plus a Newton step (rsqrt_nr: within
// 2 ulps, exact 1 / sqrt without AVX-512).
template <class T> inline Vec3<T> normalize(const Vec3<T>& a) { return a * rsqrt_nr(dot(a, a)); }
template <class T> inline Vec3<T> sel(const mask_t<T>& m, const Vec3<T>& a, const Vec3<T>& b) {
  return {sel(m, a.x, b.x), sel(m, a.y, b.y), sel(m, a.z, b.z)};
}
template <class T> inline T max_abs(const Vec3<T>& a) { return max(abs(a.x), max(abs(a.y), abs(a.z))); }

// Orthonormal basis around a unit normal (Duff et al. 2017, branchless form).
template <class T> inline void make_basis(const Vec3<T>& n, Vec3<T>& t, Vec3<T>& b) {
  const T sign = sel(n.z >= T(0.f), T(1.f), T(-1.f));
  const T a = T(-1.f) / (sign + n.z);
  const T c = n.x * n.y * a;
  t = {T(1.f) + sign * n.x * n.x * a, sign * c, -sign * n.x};
  b = {c, sign + n.y * n.y * a, -n.y};
}

template <class T> inline Vec3<T> load3(const float* x, const float* y, const float* z) {
  return {load<T>(x), load<T>(y), load<T>(z)};
}
template <class T> inline void store3(float* x, float* y, float* z, const Vec3<T>& v) {
  store(x, v.x);
  store(y, v.y);
  store(z, v.z);
}
template <class I> inline auto gather3(const float* x, const float* y, const float* z, const I& i) {
  using T = decltype(gather(x, i));
  return Vec3<T>{gather(x, i), gather(y, i), gather(z, i)};
}

} // namespace tuile
