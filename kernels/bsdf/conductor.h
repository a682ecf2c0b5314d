// pbrt-v4's ConductorBxDF, lane-generic: a mirror with the conductor's Fresnel reflectance
// where a lane is effectively smooth, else Torrance-Sparrow microfacet reflection
// f = D(wm) F(wo.wm) G(wo, wi) / (4 cos_o cos_i) with the Trowbridge-Reitz distribution,
// sampled by visible normals.
// Reads: per lane alpha_x, alpha_y, the complex index eta + i k per channel; wo, wi in the
// local shading frame (unit, z the shading normal; either side: the BRDF is two-sided like
// pbrt-v4's, mirrored to wo.z >= 0). Writes: BsdfEval / BsdfSample (wi local).
// Delta lanes (smooth): eval and pdf give 0; sample gives the mirror direction, pdf 1 (the
// probability of the lobe, pbrt-v4's convention), weight F. Rough lanes: the sample's pdf
// and weight are computed from the sampled wi by the same code as eval and pdf (the half
// vector recomputed), so sample().pdf == pdf(wo, sample().wi) bit for bit, and weight =
// F G / G1(wo) = f cos_i / pdf up to rounding.
// Sources: pbrt-v4 (4th ed. 9.6, ConductorBxDF); Heitz 2014/2018; Dupuy & Benyoub 2023.
#pragma once
#include "bsdf/bsdf.h"
#include "bsdf/fresnel.h"
#include "bsdf/microfacet.h"

namespace tuile {

namespace bsdf_detail {
template <class T> inline Vec3<T> mirror_z(const Vec3<T>& v, const T& sgn) noexcept { return {v.x, v.y, v.z * sgn}; }
template <class T> inline T sign_of_z(const Vec3<T>& wo) noexcept { return sel(wo.z < T(0.f), T(-1.f), T(1.f)); }
template <class T> inline Rgb3<T> scale(const Rgb3<T>& c, const T& s) noexcept { return {c.r * s, c.g * s, c.b * s}; }
template <class T> inline Rgb3<T> sel3(const mask_t<T>& m, const Rgb3<T>& a, const Rgb3<T>& b) noexcept {
  return {sel(m, a.r, b.r), sel(m, a.g, b.g), sel(m, a.b, b.b)};
}
template <class T> inline Rgb3<T> zero3() noexcept { return {T(0.f), T(0.f), T(0.f)}; }
template <class T> inline T max3(const Rgb3<T>& c) noexcept { return max(c.r, max(c.g, c.b)); }
// a / b where m, else 0 (b is not read where m is clear)
template <class T> inline T div_or0(const mask_t<T>& m, const T& a, const T& b) noexcept {
  return sel(m, a / sel(m, b, T(1.f)), T(0.f));
}
template <class T> inline Vec3<T> unit_or(const Vec3<T>& v, const Vec3<T>& fallback, mask_t<T>& ok) noexcept {
  const T l2 = dot(v, v);
  ok = l2 > T(0.f) && l2 < T(INFINITY);
  return sel(ok, v * (T(1.f) / sqrt(sel(ok, l2, T(1.f)))), fallback);
}

// The microfacet reflection lobe of an interface, in the frame mirrored so that wo.z >= 0:
// D, G, pdf_sa of visible-normal sampling, and the half vector's cosine with wo. `ok` is
// clear where the lobe is 0 (wi not above, grazing wo or wi, degenerate half vector).
template <class T> struct ReflectionTerms {
  mask_t<T> ok;
  T cos_o, cos_i, dot_o;  // wo.z, wi.z, wo.wm
  T D, G, G1o;
  T f_over_F;  // D G / (4 cos_o cos_i)
  T pdf;       // D G1(wo) / (4 cos_o): the density of wi = reflect(wo, wm), wm ~ D_wo
};
template <class T>
inline ReflectionTerms<T> reflection_terms(const TrowbridgeReitz<T>& d, const Vec3<T>& wo, const Vec3<T>& wi) noexcept {
  ReflectionTerms<T> r;
  r.cos_o = wo.z;
  r.cos_i = wi.z;
  mask_t<T> ok_h;
  const Vec3<T> wm = unit_or(wo + wi, Vec3<T>(T(0.f), T(0.f), T(1.f)), ok_h);
  r.dot_o = dot(wo, wm);
  r.ok = ok_h && r.cos_o > T(0.f) && r.cos_i > T(0.f) && r.dot_o > T(0.f);
  r.D = d.D(wm);
  r.G = d.G(wo, wi);
  r.G1o = d.G1(wo);
  r.f_over_F = div_or0(r.ok, r.D * r.G, T(4.f) * r.cos_o * r.cos_i);
  r.pdf = div_or0(r.ok, r.D * r.G1o, T(4.f) * r.cos_o);
  r.ok = r.ok && r.pdf > T(0.f);
  return r;
}
}  // namespace bsdf_detail

template <class T> struct ConductorBsdf {
  T alpha_x, alpha_y;
  Rgb3<T> eta, k;

  TrowbridgeReitz<T> distribution() const noexcept { return TrowbridgeReitz<T>{alpha_x, alpha_y}.clamped(); }

  BsdfEval<T> eval(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    using namespace bsdf_detail;
    const T sgn = sign_of_z(wo);
    const Vec3<T> o = mirror_z(wo, sgn), i = mirror_z(wi, sgn);
    const ReflectionTerms<T> t = reflection_terms(distribution(), o, i);
    const mask_t<T> on = t.ok && !effectively_smooth(alpha_x, alpha_y);
    const Rgb3<T> F = fresnel_complex(t.dot_o, eta, k);
    const T s = sel(on, t.f_over_F, T(0.f));
    return {scale(F, s), sel(on, t.pdf, T(0.f))};
  }

  T pdf(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    using namespace bsdf_detail;
    const T sgn = sign_of_z(wo);
    const ReflectionTerms<T> t = reflection_terms(distribution(), mirror_z(wo, sgn), mirror_z(wi, sgn));
    return sel(t.ok && !effectively_smooth(alpha_x, alpha_y), t.pdf, T(0.f));
  }

  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T& u1, const T& u2) const noexcept {
    using namespace bsdf_detail;
    (void)uc;
    const T sgn = sign_of_z(wo);
    const Vec3<T> o = mirror_z(wo, sgn);
    const mask_t<T> smooth = effectively_smooth(alpha_x, alpha_y);
    const TrowbridgeReitz<T> d = distribution();
    // rough lanes: a visible normal, the mirror direction about it, then the terms of
    // eval at that direction (the half vector recomputed from wo and wi)
    const Vec3<T> wm = d.sample_visible(o, u1, u2);
    const Vec3<T> ir = reflect(o, wm);
    const ReflectionTerms<T> t = reflection_terms(d, o, ir);
    const Rgb3<T> Fr = scale(fresnel_complex(t.dot_o, eta, k), d.G_over_G1(o, ir));
    // smooth lanes: the mirror direction
    const Vec3<T> is{-o.x, -o.y, o.z};
    const Rgb3<T> Fs = fresnel_complex(o.z, eta, k);

    BsdfSample<T> s;
    s.delta = smooth;
    s.valid = sel_mask(smooth, o.z > T(0.f), t.ok);
    s.wi = mirror_z(sel(smooth, is, ir), sgn);
    s.pdf = sel(s.valid, sel(smooth, T(1.f), t.pdf), T(0.f));
    s.weight = sel3(s.valid, sel3(smooth, Fs, Fr), zero3<T>());
    s.wi = sel(s.valid, s.wi, Vec3<T>(T(0.f), T(0.f), T(1.f)) * sgn);
    return s;
  }
};

}  // namespace tuile
