// Sampling math: warps from [0,1)^2 to directions and points, with their pdfs.
// Reads: uniform numbers u1, u2 and plain geometry (points, edges, radii) per lane.
// Writes: directions (unit), points, barycentrics, pdfs, validity masks.
// Assumes: T = float (the scalar reference) or vfloat; no -ffast-math. Every function is
// branch-free over lanes (masks + sel) and returns finite values for any finite input;
// where a sample can fail it returns a mask and writes a harmless direction and pdf 0.
// This file: the cosine-weighted hemisphere, points on triangles and spheres, the cone of
// a sphere, and the rule for when solid-angle sampling is safe; sample/spherical.h holds
// the spherical triangles, rectangles and parallelograms.
// Sources: Shirley & Chiu 1997 (concentric disk) + Malley's method; Heitz 2019 (low-
// distortion triangle map); uniform cone sampling (pbrt, 4th ed.). Elementary functions
// come from lanes/lane_math.h (the same bits in every lane and the scalar reference).
#pragma once
#include "lanes/lane_math.h"
#include "lanes/simd.h"
#include "lanes/vec.h"

namespace tuile {


// Solid-angle sampling is used only for sources subtending min_sa_sample_omega <= Omega <=
// max_sa_sample_omega; outside that range the renderer samples the light by area. The rule
// depends on Omega alone, so MIS can re-apply it from (x, light) when evaluating the pdf.
//
// Measured (tests/test_sampling.cpp, SolidAngleThresholds): the float maps against the same
// maps in double (textbook Urena; textbook Arvo), oblique sources at distance 1. "pdf" is the
// worst relative error of 1/pdf against the exact solid angle, "pos" the worst distance on
// the source between the float and double sample points, over the source's size (worst
// over a 48 x 48 grid of (u1, u2)):
//     Omega (sr)     1e-2     1e-3     3e-4     1e-4     3e-5     1e-5     1e-6     1e-8
//     rect  pdf    6e-08    5e-07    3e-06    1e-05    2e-05    6e-05    8e-04    8e-03
//     rect  pos    9e-07    3e-06    7e-06    2e-05    5e-05    8e-05    6e-04    6e-02
//     tri   pdf    4e-08    1e-07    4e-08    8e-08    1e-08    1e-07    6e-08    2e-07
//     tri   pos    6e-07    1e-05    3e-05    8e-05    7e-04    2e-03    8e-03    3e-01
// Urena's S = sum(gamma_i) - 2 pi has an absolute error of ~1e-7 sr (ulps of O(1) angles), so
// its relative pdf error grows as 1/Omega; Arvo's map keeps its pdf (Van Oosterom-Strackee)
// but its sample points drift as the angular size approaches float direction precision.
// Requiring both errors below 1e-4 puts the limit at 1e-4 sr: the triangle's points fail it
// at 3e-5 sr (pbrt-v4 uses 3e-4 for triangles). Area sampling of such small sources is
// accurate to a few ulps and has almost no variance (the integrand is nearly constant).
// Above 6.22 sr (99% of the hemisphere; pbrt-v4's value) the receiver lies almost in the
// source's plane: directions are almost all grazing, the solid-angle pdf gains nothing over
// the area pdf, and the sub-triangle construction degenerates (alpha - A/2 -> 0).
inline constexpr float min_sa_sample_omega = 1e-4f;
inline constexpr float max_sa_sample_omega = 6.22f;

template <class T> inline mask_t<T> solid_angle_sampling_safe(const T& omega) noexcept {
  return omega >= T(min_sa_sample_omega) && omega <= T(max_sa_sample_omega);
}

namespace sampling_detail {

template <class T> inline T safe_sqrt(const T& x) noexcept { return sqrt(max(x, T(0.f))); }

// v / |v|, or fallback where |v| is 0 or not finite.
template <class T> inline Vec3<T> normalize_or(const Vec3<T>& v, const Vec3<T>& fallback) noexcept {
  const T l2 = dot(v, v);
  const mask_t<T> ok = l2 > T(0.f) && is_finite(l2);
  const T inv = T(1.f) / sqrt(sel(ok, l2, T(1.f)));
  return sel(ok, v * inv, fallback);
}

template <class T> inline mask_t<T> finite3(const Vec3<T>& v) noexcept {
  return is_finite(v.x) && is_finite(v.y) && is_finite(v.z);
}

// Make an output safe: invalid lanes get direction fallback and pdf 0.
template <class T>
inline mask_t<T> finish(mask_t<T> valid, Vec3<T>& dir, T& pdf, const Vec3<T>& fallback) noexcept {
  valid = valid && finite3(dir) && is_finite(pdf) && pdf > T(0.f);
  dir = sel(valid, dir, fallback);
  pdf = sel(valid, pdf, T(0.f));
  return valid;
}

} // namespace sampling_detail

// ---------------------------------------------------------------------------------------
// 1. Cosine-weighted hemisphere, local frame with z up (Shirley-Chiu disk, then Malley).
template <class T> inline Vec3<T> sample_cosine_hemisphere(const T& u1, const T& u2) noexcept {
  const T a = T(2.f) * u1 - T(1.f), b = T(2.f) * u2 - T(1.f);
  const mask_t<T> a_major = abs(a) > abs(b);
  const T r = sel(a_major, a, b);
  const T num = sel(a_major, b, a);
  const T den = sel(r == T(0.f), T(1.f), r);
  T s, c;
  lane_math::sincos_reduced(T(0.785398163397448309616f) * (num * rcp_nr(den)), s, c);
  // a major: phi = t; b major: phi = pi/2 - t, so cos and sin swap.
  const T x = r * sel(a_major, c, s);
  const T y = r * sel(a_major, s, c);
  const T z = sampling_detail::safe_sqrt(T(1.f) - x * x - y * y);
  return {x, y, z};
}

template <class T> inline T pdf_cosine_hemisphere(const T& cos_theta) noexcept {
  return max(cos_theta, T(0.f)) * T(inv_pi_f);
}

// Uniform direction on the unit sphere (z = 1 - 2 u1, phi = 2 pi u2); density 1 / (4 pi).
template <class T> inline Vec3<T> sample_uniform_sphere(const T& u1, const T& u2) noexcept {
  const T z = T(1.f) - T(2.f) * u1;
  const T r = sampling_detail::safe_sqrt(T(1.f) - z * z);
  T s, c;
  lane_math::sincos_2pi(u2, s, c);
  return {r * c, r * s, z};
}
inline constexpr float inv_4pi_f = 0.0795774715459476678844f;

// ---------------------------------------------------------------------------------------
// 2. Uniform point on a triangle p0 + b1 e1 + b2 e2 (Heitz 2019: area-preserving, keeps
// stratification with little distortion). pdf_area = 1 / area.
template <class T> inline void sample_triangle_area(const T& u1, const T& u2, T& b1, T& b2) noexcept {
  const mask_t<T> upper = u2 > u1;
  const T h1 = u1 * T(0.5f), h2 = u2 * T(0.5f);
  b1 = sel(upper, h1, u1 - h2);
  b2 = sel(upper, u2 - h1, h2);
}

template <class T> inline T pdf_triangle_area(const Vec3<T>& e1, const Vec3<T>& e2) noexcept {
  const T area = T(0.5f) * length(cross(e1, e2));
  return sel(area > T(0.f), T(1.f) / sel(area > T(0.f), area, T(1.f)), T(0.f));
}

// ---------------------------------------------------------------------------------------
// 5. Spheres.
//
// Cone of directions from x towards a sphere: 1 - cos(theta_max) is computed as
// sin^2 / (1 + cos) so that tiny, distant spheres keep their solid angle.
template <class T>
inline T sphere_cone_one_minus_cos(const Vec3<T>& x, const Vec3<T>& center, const T& radius, mask_t<T>& outside) noexcept {
  const Vec3<T> d = center - x;
  const T dist2 = dot(d, d);
  const T r2 = radius * radius;
  outside = dist2 > r2 && is_finite(dist2) && radius > T(0.f);
  const T sin2 = min(r2 / sel(outside, dist2, T(1.f)), T(1.f));
  const T cos_max = sqrt(T(1.f) - sin2);
  return sel(outside, sin2 / (T(1.f) + cos_max), T(0.f));
}

template <class T> inline T sphere_cone_solid_angle(const Vec3<T>& x, const Vec3<T>& center, const T& radius) noexcept {
  mask_t<T> outside;
  return T(two_pi_f) * sphere_cone_one_minus_cos(x, center, radius, outside);
}

// 1 / Omega of the cone, 0 when x is inside the sphere (the caller checks the direction hits it).
template <class T> inline T pdf_sphere_cone(const Vec3<T>& x, const Vec3<T>& center, const T& radius) noexcept {
  const T omega = sphere_cone_solid_angle(x, center, radius);
  return sel(omega > T(0.f), T(1.f) / sel(omega > T(0.f), omega, T(1.f)), T(0.f));
}

template <class T>
inline mask_t<T> sample_sphere_cone(const Vec3<T>& x, const Vec3<T>& center, const T& radius, const T& u1, const T& u2,
                                    Vec3<T>& dir, T& pdf_sa) noexcept {
  using namespace sampling_detail;
  mask_t<T> outside;
  const T omc_max = sphere_cone_one_minus_cos(x, center, radius, outside);
  const Vec3<T> w = normalize_or(center - x, Vec3<T>(T(0.f), T(0.f), T(1.f)));
  Vec3<T> t, b;
  make_basis(w, t, b);
  const T omc = u1 * omc_max;
  const T cos_t = T(1.f) - omc;
  const T sin_t = safe_sqrt(omc * (T(2.f) - omc));
  T sp, cp;
  lane_math::sincos_2pi(u2, sp, cp);
  dir = normalize_or(t * (sin_t * cp) + b * (sin_t * sp) + w * cos_t, w);
  const T omega = T(two_pi_f) * omc_max;
  pdf_sa = T(1.f) / sel(omega > T(0.f), omega, T(1.f));
  return finish(outside && omega > T(0.f), dir, pdf_sa, w);
}

// Uniform point on the sphere's surface; pdf_area = 1 / (4 pi r^2).
template <class T> inline Vec3<T> sample_sphere_area(const Vec3<T>& center, const T& radius, const T& u1, const T& u2) noexcept {
  const T z = T(1.f) - T(2.f) * u1;
  const T rxy = T(2.f) * sampling_detail::safe_sqrt(u1 * (T(1.f) - u1));
  T sp, cp;
  lane_math::sincos_2pi(u2, sp, cp);
  return center + Vec3<T>(rxy * cp, rxy * sp, z) * radius;
}

template <class T> inline T pdf_sphere_area(const T& radius) noexcept {
  const T a = radius * radius;
  return sel(a > T(0.f), T(inv_four_pi_f) / sel(a > T(0.f), a, T(1.f)), T(0.f));
}

}  // namespace tuile
