// Equiangular sampling along a ray (Kulla & Fajardo 2012, "Importance sampling techniques
// for path tracing in participating media"), lane-generic (T = float, the scalar reference,
// or a SIMD batch; from +, -, *, /, sqrt and lanes/lane_math.h, so every lane gives the
// scalar reference's bits). A distance s along the unit direction d from x, in [lo, hi], is
// drawn with density proportional to 1 / |x + s d - c|^2, towards a point c:
//   p(s) = h / ((theta_b - theta_a) (h^2 + (s - delta)^2)),
// with delta = dot(c - x, d) the foot of c on the ray, h its distance from the ray, and
// theta_a, theta_b the angles at c of the stretch's ends (atan((lo - delta) / h), ...). The
// inverse 1 / r^2 a light sample carries from a point near c is this density's, so a
// stretch of medium that passes a small source has bounded light samples, where the free
// flight's density (which does not know the source) lets the points near the source weigh
// 1 / r^2 each. wave/equiangular.h draws the segment light samples with it.
#pragma once
#include "lanes/lane_math.h"
#include "lanes/vec.h"

namespace tuile {

template <class T> struct EquiangularFrame {
  T delta, h, theta_a, theta_b;
  mask_t<T> ok;  // a stretch of positive angle
};

// The frame of the stretch [lo, hi] of the ray x + s d (d unit) towards c. hi may be large
// (a ray that meets nothing) but finite. A ray through c keeps h at a relative 2^-20 of
// |c - x|, so that the density stays finite.
template <class T>
inline EquiangularFrame<T> equiangular_frame(const Vec3<T>& x, const Vec3<T>& d, const Vec3<T>& c, const T& lo,
                                             const T& hi) noexcept {
  const Vec3<T> v = c - x;
  const T l2 = dot(v, v);
  EquiangularFrame<T> f;
  f.delta = dot(v, d);
  f.h = sqrt(max(l2 - f.delta * f.delta, l2 * T(0x1p-40f) + T(1e-30f)));
  f.theta_a = lane_math::atan2(lo - f.delta, f.h);
  f.theta_b = lane_math::atan2(hi - f.delta, f.h);
  f.ok = f.theta_b > f.theta_a && hi > lo;
  return f;
}

// The density of s in the frame's stretch (0 where the frame is not ok).
template <class T> inline T equiangular_pdf(const EquiangularFrame<T>& f, const T& s) noexcept {
  const T r = s - f.delta;
  const T den = (f.theta_b - f.theta_a) * mul_add(r, r, f.h * f.h);
  return sel(f.ok && den > T(0.f), f.h / sel(den > T(0.f), den, T(1.f)), T(0.f));
}

// The distance for u in [0, 1): theta uniform between the ends, s = delta + h tan theta,
// kept inside the stretch.
template <class T> inline T equiangular_sample(const EquiangularFrame<T>& f, const T& lo, const T& hi, const T& u) noexcept {
  const T theta = mul_add(u, f.theta_b - f.theta_a, f.theta_a);
  T sn, cs;
  lane_math::sincos(theta, sn, cs);
  const T s = f.delta + f.h * sn / max(cs, T(1e-30f));
  return min(max(s, lo), hi);
}

}  // namespace tuile
