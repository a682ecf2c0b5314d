// pbrt-v4's DielectricBxDF (radiance transport), lane-generic: an interface between two
// dielectrics, index eta below over index above (+z is "outside"; wo.z < 0: the viewer is
// inside). Lanes where the interface is effectively smooth, or eta == 1, are delta lobes:
// specular reflection with probability R / (R + T), refraction with T / (R + T), the
// refracted radiance scaled by 1 / eta'^2 (eta' = the index on wi's side over wo's), and
// eta == 1 a pure pass-through (wi = -wo, weight 1). Rough lanes: the Trowbridge-Reitz
// microfacet BSDF of Walter et al. 2007 with the generalized half vector
// wm ~ wo + eta' wi, reflection f_r = D G F / (4 |cos_o cos_i|) and transmission
// f_t = D G (1 - F) |wi.wm| |wo.wm| / (|cos_o cos_i| (wi.wm + wo.wm / eta')^2) / eta'^2,
// sampled by a visible normal and the Fresnel reflectance of that normal choosing
// reflection or refraction; the refraction Jacobian is
// dwm/dwi = |wi.wm| / (wi.wm + wo.wm / eta')^2.
// Reads: per lane eta, alpha_x, alpha_y; wo, wi local (unit). Writes: BsdfEval/BsdfSample.
// Works in the frame mirrored so that wo.z >= 0, where the relative index is
// eta' = eta (viewer outside) or 1 / eta (inside): the BSDF is the same function there.
// Rough samples take their pdf and weight from the code of eval at the sampled wi (the
// half vector recomputed), so sample().pdf == pdf(wo, sample().wi) bit for bit.
// Sources: Walter et al. 2007 ("Microfacet models for refraction through rough
// surfaces"); pbrt-v4 DielectricBxDF (4th ed. 9.5, 9.7); Heitz 2014/2018.
#pragma once
#include "bsdf/bsdf.h"
#include "bsdf/conductor.h"
#include "bsdf/fresnel.h"
#include "bsdf/microfacet.h"

namespace tuile {

namespace bsdf_detail {
// The rough dielectric's value and pdf in the mirrored frame (o.z >= 0), relative index e.
template <class T> struct DielectricTerms {
  mask_t<T> ok, reflect;
  T f, pdf;      // f: the BSDF value (radiance mode); pdf: solid angle, with the lobe choice
  T weight;      // f |cos_i| / pdf, from its analytic form G / G1(wo) (/ e^2 transmitted)
};
template <class T>
inline DielectricTerms<T> dielectric_terms(const TrowbridgeReitz<T>& d, const T& e, const Vec3<T>& o,
                                           const Vec3<T>& i) noexcept {
  DielectricTerms<T> r;
  const T co = o.z, ci = i.z;
  r.reflect = ci > T(0.f);
  const mask_t<T> trans = ci < T(0.f);
  // the generalized half vector, turned to +z
  Vec3<T> h = sel(r.reflect, o + i, o + i * e);
  h = h * sel(h.z < T(0.f), T(-1.f), T(1.f));
  mask_t<T> ok_h;
  const Vec3<T> wm = unit_or(h, Vec3<T>(T(0.f), T(0.f), T(1.f)), ok_h);
  const T dot_o = dot(o, wm), dot_i = dot(i, wm);
  // microfacets facing away from wo or (for the lobe) from wi contribute nothing
  r.ok = ok_h && co > T(0.f) && (r.reflect || trans) && dot_o > T(0.f) &&
         sel_mask(r.reflect, dot_i > T(0.f), dot_i < T(0.f));
  const T F = fresnel_dielectric(dot_o, e);
  // 1 - F for the transmitted lobe from both cosines of the refraction pair (wo.wm, -wi.wm):
  // 1 - r^2 = 4 a b / (a + b)^2 with (a, b) = (e wo.wm, -wi.wm) and (wo.wm, -e wi.wm). It
  // needs no Snell square root (ill-conditioned near the critical angle), and it is
  // symmetric under the swap (wo, wi, e) -> (wi, wo, 1/e): reciprocity holds to rounding.
  const T ct = -dot_i;
  const T a1 = e * dot_o, b2 = e * ct;
  const T s1 = a1 + ct, s2 = dot_o + b2;
  const mask_t<T> pair_ok = ct > T(0.f) && s1 > T(0.f) && s2 > T(0.f);
  const T Ft = sel(pair_ok, T(2.f) * (a1 * ct / sel(pair_ok, s1 * s1, T(1.f)) + dot_o * b2 / sel(pair_ok, s2 * s2, T(1.f))), T(0.f));
  const T D = d.D(wm), G = d.G(o, i), G1o = d.G1(o);
  const T aci = abs(ci);
  const T e2 = e * e;
  // reflection: f = D G F / (4 co ci), pdf = D_wo(wm) / (4 wo.wm) F = D G1o F / (4 co)
  const T fr = D * G * F / (T(4.f) * co * aci);
  const T pr = D * G1o * F / (T(4.f) * co);
  // transmission: s = wi.wm + wo.wm / e (nonzero: (o + e i).wm = |h| > 0 up to sign)
  const T s = mul_add(dot_o, T(1.f) / e, dot_i);
  const T den = s * s;
  const T ft = D * G * Ft * abs(dot_i * dot_o) / (co * aci * den * e2);
  // transmission pdf: D_wo(wm) |dwm/dwi| (1 - F) = (G1o D wo.wm / co) (|wi.wm| / den) (1 - F)
  const T pt = D * G1o * Ft * (dot_o * abs(dot_i)) / (co * den);
  r.ok = r.ok && sel(r.reflect, pr, pt) > T(0.f) && is_finite(sel(r.reflect, pr, pt)) && is_finite(sel(r.reflect, fr, ft));
  r.f = sel(r.ok, sel(r.reflect, fr, ft), T(0.f));
  r.pdf = sel(r.ok, sel(r.reflect, pr, pt), T(0.f));
  const T g = d.G_over_G1(o, i);
  r.weight = sel(r.ok, sel(r.reflect, g, g / e2), T(0.f));
  return r;
}
}  // namespace bsdf_detail

template <class T> struct DielectricBsdf {
  T eta, alpha_x, alpha_y;

  TrowbridgeReitz<T> distribution() const noexcept { return TrowbridgeReitz<T>{alpha_x, alpha_y}.clamped(); }
  // Lanes sampled as delta lobes: effectively smooth, or eta == 1 (pass-through).
  mask_t<T> specular() const noexcept { return effectively_smooth(alpha_x, alpha_y) || eta == T(1.f); }

  BsdfEval<T> eval(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    using namespace bsdf_detail;
    const T sgn = sign_of_z(wo);
    const T e = sel(wo.z < T(0.f), T(1.f) / eta, eta);
    const DielectricTerms<T> t = dielectric_terms(distribution(), e, mirror_z(wo, sgn), mirror_z(wi, sgn));
    const mask_t<T> on = t.ok && !specular();
    const T f = sel(on, t.f, T(0.f));
    return {{f, f, f}, sel(on, t.pdf, T(0.f))};
  }

  T pdf(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    using namespace bsdf_detail;
    const T sgn = sign_of_z(wo);
    const T e = sel(wo.z < T(0.f), T(1.f) / eta, eta);
    const DielectricTerms<T> t = dielectric_terms(distribution(), e, mirror_z(wo, sgn), mirror_z(wi, sgn));
    return sel(t.ok && !specular(), t.pdf, T(0.f));
  }

  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T& u1, const T& u2) const noexcept {
    using namespace bsdf_detail;
    const T sgn = sign_of_z(wo);
    const T e = sel(wo.z < T(0.f), T(1.f) / eta, eta);
    const Vec3<T> o = mirror_z(wo, sgn);
    const mask_t<T> spec = specular();
    const mask_t<T> pass = eta == T(1.f);
    const TrowbridgeReitz<T> d = distribution();

    // rough lanes: a visible normal; reflection or refraction about it by its Fresnel
    // reflectance; then the terms of eval at the sampled direction
    const Vec3<T> wm = d.sample_visible(o, u1, u2);
    const T dot_o = dot(o, wm);
    const T Fm = fresnel_dielectric(dot_o, e);
    const mask_t<T> refl_m = uc < Fm;  // pr / (pr + pt) with pr = F, pt = 1 - F
    Vec3<T> wt;
    T etap;
    const mask_t<T> no_tir = refract(o, wm, e, wt, etap);
    const Vec3<T> ir = sel(refl_m, reflect(o, wm), wt);
    const DielectricTerms<T> t = dielectric_terms(d, e, o, ir);
    const mask_t<T> rough_ok = t.ok && sel_mask(refl_m, t.reflect, !t.reflect && no_tir);

    // delta lanes: mirror with probability R / (R + T), else the refracted direction
    const T R = fresnel_dielectric(o.z, e);
    const T Tr = T(1.f) - R;
    const T p_r = R / (R + Tr);
    const mask_t<T> refl_s = uc < p_r && !pass;
    const T inv_e = T(1.f) / e;
    const T sin2_t = ((T(1.f) - o.z) * (T(1.f) + o.z)) * (inv_e * inv_e);
    const T cos_t = sqrt(max(T(1.f) - sin2_t, T(0.f)));
    const Vec3<T> is_r{-o.x, -o.y, o.z};
    const Vec3<T> is_t = sel(pass, -o, Vec3<T>(-o.x * inv_e, -o.y * inv_e, -cos_t));
    const mask_t<T> spec_ok = o.z > T(0.f) && (refl_s || sin2_t < T(1.f) || pass);
    // weights: reflection R / p_r = R + T; transmission T / p_t / e^2 (1 where eta == 1)
    const T w_r = R + Tr;
    const T w_t = sel(pass, T(1.f), (R + Tr) / (e * e));

    BsdfSample<T> s;
    s.delta = spec;
    s.valid = sel_mask(spec, spec_ok, rough_ok);
    const Vec3<T> wi = sel(spec, sel(refl_s, is_r, is_t), ir);
    s.wi = sel(s.valid, mirror_z(wi, sgn), Vec3<T>(T(0.f), T(0.f), T(1.f)) * sgn);
    s.pdf = sel(s.valid, sel(spec, sel(refl_s, p_r, sel(pass, T(1.f), Tr / (R + Tr))), t.pdf), T(0.f));
    const T w = sel(s.valid, sel(spec, sel(refl_s, w_r, w_t), t.weight), T(0.f));
    s.weight = {w, w, w};
    return s;
  }
};

}  // namespace tuile
