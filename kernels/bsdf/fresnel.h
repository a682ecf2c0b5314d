// Fresnel reflectance of dielectric and conductor interfaces, and Snell refraction,
// lane-generic (T = float, the scalar reference, vfloat or the twins; masks, no branches).
// Reads: cosines and relative indices of refraction per lane. Writes: reflectances in [0, 1],
// refracted directions and their validity mask. Assumes unit vectors, eta > 0, finite input.
// Only +, -, *, /, sqrt, min, max and selects: correctly rounded, so every lane gives the
// scalar reference's bits.
// Sources: the Fresnel equations (Born & Wolf; pbrt-v4 4th ed. section 9.3: FrDielectric's
// conventions), the conductor form in real arithmetic (Lagarde 2013, "Memo on Fresnel
// equations", the form pbrt-v3/v4 FrConductor use), rewritten so that a^2 does not lose
// its digits to cancellation when k dominates.
#pragma once
#include "bsdf/bsdf.h"
#include "lanes/lane_math.h"

namespace tuile {

// Unpolarised Fresnel reflectance of a dielectric interface (pbrt-v4 FrDielectric): eta is
// the index below over the index above (relative to +z); cos_i is the cosine of the
// incident direction with +z, negative when it arrives from below (the indices swap). Total
// internal reflection gives 1.
template <class T> inline T fresnel_dielectric(const T& cos_i, const T& eta) noexcept {
  const T c0 = min(max(cos_i, T(-1.f)), T(1.f));
  const T e = sel(c0 < T(0.f), T(1.f) / eta, eta);
  const T c = abs(c0);
  const T sin2_t = ((T(1.f) - c) * (T(1.f) + c)) / (e * e);
  const auto tir = sin2_t >= T(1.f);
  const T cos_t = sqrt(max(T(1.f) - sin2_t, T(0.f)));
  const T ec = e * c, et = e * cos_t;
  // Denominators vanish only with c = cos_t = 0, which is total internal reflection.
  const T d_parl = sel(tir, T(1.f), ec + cos_t), d_perp = sel(tir, T(1.f), c + et);
  const T r_parl = (ec - cos_t) / d_parl, r_perp = (c - et) / d_perp;
  return sel(tir, T(1.f), T(0.5f) * mul_add(r_parl, r_parl, r_perp * r_perp));
}

// 1 - fresnel_dielectric(cos_i, eta), from the transmission coefficients
// 1 - r^2 = 4 a b / (a + b)^2 directly: no cancellation where R is close to 1 (grazing
// microfacets), so the transmitted lobe keeps its relative accuracy. 0 under total
// internal reflection.
template <class T> inline T fresnel_dielectric_transmittance(const T& cos_i, const T& eta) noexcept {
  const T c0 = min(max(cos_i, T(-1.f)), T(1.f));
  const T e = sel(c0 < T(0.f), T(1.f) / eta, eta);
  const T c = abs(c0);
  const T sin2_t = ((T(1.f) - c) * (T(1.f) + c)) / (e * e);
  const auto tir = sin2_t >= T(1.f);
  const T cos_t = sqrt(max(T(1.f) - sin2_t, T(0.f)));
  const T ec = e * c, et = e * cos_t;
  const T s_parl = ec + cos_t, s_perp = c + et;
  const auto ok = !tir && s_parl > T(0.f) && s_perp > T(0.f);
  const T t_parl = (T(4.f) * ec * cos_t) / sel(ok, s_parl * s_parl, T(1.f));
  const T t_perp = (T(4.f) * c * et) / sel(ok, s_perp * s_perp, T(1.f));
  return sel(ok, min(T(0.5f) * (t_parl + t_perp), T(1.f)), T(0.f));
}

// Unpolarised Fresnel reflectance of a conductor with complex index eta + i k (relative to
// the medium the light comes from), |cos_i| used (pbrt-v4 FrComplex). With
// a^2 + b^2 = sqrt((eta^2 - k^2 - sin^2)^2 + 4 eta^2 k^2) and a^2 = (a^2 + b^2 + t0) / 2,
// written as 2 eta^2 k^2 / (a^2 + b^2 - t0) where t0 < 0 so that no digits cancel.
// eta and k are clamped to 1e5: their squares' products stay far inside float's range
// (beyond ~1e9, (eta^2 - k^2)^2 overflows and the formula gives NaN), and at 1e5 the
// reflectance already differs from 1 by less than 1e-4 (1 - F ~ 4 eta / (eta^2 + k^2)).
template <class T> inline T fresnel_complex(const T& cos_i, const T& eta_in, const T& k_in) noexcept {
  const T eta = min(eta_in, T(1e5f)), k = min(k_in, T(1e5f));
  const T c = min(abs(cos_i), T(1.f));
  const T cos2 = c * c;
  const T sin2 = (T(1.f) - c) * (T(1.f) + c);
  const T eta2 = eta * eta, k2 = k * k;
  const T t0 = eta2 - k2 - sin2;
  const T ek = T(4.f) * eta2 * k2;
  const T a2pb2 = sqrt(mul_add(t0, t0, ek));
  const T den = a2pb2 - t0;
  const T a2 = sel(t0 >= T(0.f), T(0.5f) * (a2pb2 + t0), sel(den > T(0.f), T(0.5f) * ek / sel(den > T(0.f), den, T(1.f)), T(0.f)));
  const T a = sqrt(a2);
  const T t1 = a2pb2 + cos2;
  const T t2 = T(2.f) * c * a;
  const T rs = sel(t1 + t2 > T(0.f), (t1 - t2) / sel(t1 + t2 > T(0.f), t1 + t2, T(1.f)), T(1.f));
  const T t3 = mul_add(cos2, a2pb2, sin2 * sin2);
  const T t4 = t2 * sin2;
  const T rp = sel(t3 + t4 > T(0.f), rs * (t3 - t4) / sel(t3 + t4 > T(0.f), t3 + t4, T(1.f)), rs);
  return min(max(T(0.5f) * (rp + rs), T(0.f)), T(1.f));
}

template <class T> inline Rgb3<T> fresnel_complex(const T& cos_i, const Rgb3<T>& eta, const Rgb3<T>& k) noexcept {
  return {fresnel_complex(cos_i, eta.r, k.r), fresnel_complex(cos_i, eta.g, k.g), fresnel_complex(cos_i, eta.b, k.b)};
}

// Refraction of wi (pointing away from the surface, on either side of n) through a surface
// with normal n and relative index eta = index on the side opposite to n over the index on
// n's side (pbrt-v4 Refract). Returns false where light is totally internally reflected
// (wt is then -wi). etap gets the relative index actually used (1 / eta from behind n).
template <class T>
inline mask_t<T> refract(const Vec3<T>& wi, const Vec3<T>& n, const T& eta, Vec3<T>& wt, T& etap) noexcept {
  const T c0 = dot(n, wi);
  const auto behind = c0 < T(0.f);
  etap = sel(behind, T(1.f) / eta, eta);
  const T c = abs(c0);
  const Vec3<T> nn = sel(behind, -n, n);
  const T sin2_t = ((T(1.f) - c) * (T(1.f) + c)) / (etap * etap);
  const auto ok = sin2_t < T(1.f);
  const T cos_t = sqrt(max(T(1.f) - sin2_t, T(0.f)));
  const T inv = T(1.f) / etap;
  const Vec3<T> t = nn * (c * inv - cos_t) - wi * inv;
  wt = sel(ok, t, -wi);
  return ok;
}

// Mirror reflection of w about the unit normal n.
template <class T> inline Vec3<T> reflect(const Vec3<T>& w, const Vec3<T>& n) noexcept {
  return n * (T(2.f) * dot(w, n)) - w;
}

}  // namespace tuile
