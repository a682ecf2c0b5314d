// pbrt-v4's "coateddiffuse" material (a dielectric coat, index eta and Trowbridge-Reitz
// roughness alpha, over a Lambertian base of albedo rho, the two separated by a slab of
// thickness `thickness` with unit extinction and single-scattering albedo `albedo`),
// evaluated deterministically instead of by pbrt-v4's stochastic LayeredBxDF random walk.
// Lane-generic; reads per lane eta, alpha_x, alpha_y, rho, thickness, albedo; wo, wi local.
//
// The model, in the frame mirrored so that wo.z >= 0 (two-sided, like pbrt-v4's), with
// F(mu) = fresnel_dielectric(mu, eta) and mu' the cosine of a direction refracted into the
// coat through the macro surface:
//   f = f_coat + f_base,
//   f_coat = the coat's reflection: a delta mirror of weight F(mu_o) on smooth lanes
//            (max alpha < 1e-3), else D G F(wo.wm) / (4 mu_o mu_i) (dielectric.h's lobe);
//   f_base = (1 - F(mu_o)) (1 - F(mu_i)) rho Tr(mu_o') Tr(mu_i') / (pi eta^2 (1 - rho R_i)),
//   Tr(mu') = exp(-sigma thickness / mu'),  sigma = 1 - albedo (per channel),
//   R_i = int_0^1 F_int(mu) exp(-2 sigma thickness / mu) 2 mu dmu,
// F_int the Fresnel reflectance seen from inside the coat (1 beyond the critical angle).
// This is the radiance of light refracted in, attenuated down to the base, reflected
// diffusely, bounced any number of times between base and coat (each bounce returns a
// cosine-distributed fraction rho R_i: the Lambertian base forgets directions, which is
// why the series sums exactly), attenuated up and refracted out, with the 1 / eta^2 of
// radiance leaving a denser medium (Weidlich & Wilkie 2007; the diffuse part of Mitsuba's
// plastic / roughplastic; with thickness 0 R_i is the internal diffuse Fresnel reflectance
// 1 - (1 - F_dr) / eta^2 and a white base reflects exactly 1 - F(mu_o)).
// For a smooth coat with albedo 0 it is exactly the sum of pbrt-v4's random walk (which
// stops at maxDepth = 10 interface events; this model does not). For a rough coat it
// keeps the smooth coat's Fresnel transmittances and refracted directions for the base
// part (an approximation: tests/test_materials.cpp measures it against a random walk
// through the rough interface). albedo > 0 (approximation): light scattered in the slab
// is treated as continuing towards the base, where the Lambertian reflection redistributes
// it anyway, so the slab attenuates by its absorption sigma = 1 - albedo only (exact for
// albedo 0; conserves energy; ignores light the medium scatters back out before reaching
// the base and the medium's own angular spread).
// R_i by Gauss-Legendre quadrature per evaluation: 8 nodes on [0, mu_c] (total internal
// reflection, integrand 2 mu exp(-a / mu)) and 8 nodes on [mu_c, 1] in s with
// mu = mu_c + (1 - mu_c) s^2 (which removes F_int's square-root kink at mu_c).
// Sampling: the coat lobe with probability p_c = F(mu_o) / (F(mu_o) + (1 - F(mu_o)) max(rho))
// (a mirror direction, or a visible normal of the coat's distribution), else a
// cosine-weighted direction; the pdf is the mixture p_c pdf_coat + (1 - p_c) cos / pi (the
// delta part excluded, as everywhere: a mirror sample reports pdf p_c).
// Sources: Weidlich & Wilkie 2007 ("Arbitrarily layered micro-facet surfaces"); Jakob,
// Mitsuba 0.5 plastic/roughplastic; pbrt-v4 LayeredBxDF (4th ed. 14.3); Walter et al. 2007.
#pragma once
#include "bsdf/bsdf.h"
#include "bsdf/conductor.h"
#include "bsdf/dielectric.h"
#include "bsdf/fresnel.h"
#include "bsdf/microfacet.h"
#include "sample/sampling.h"

namespace tuile {

namespace bsdf_detail {

// 2^n for integer-valued n in [-126, 127], by building the float's exponent bits.
inline float pow2_int(float n) noexcept { return std::bit_cast<float>((static_cast<int32_t>(n) + 127) << 23); }
inline vfloat pow2_int(const vfloat& n) noexcept {
  return xsimd::bitwise_cast<vfloat>((xsimd::batch_cast<int32_t>(n) + vint(127)) << 23);
}
template <class V> inline Twin<V> pow2_int(const Twin<V>& n) noexcept { return {pow2_int(n.a), pow2_int(n.b)}; }

// exp(x) for x <= 0 (0 below -87), from +, -, *, floor and mul_add: the same bits in every
// lane (xsimd's exp and the C library's differ). Cody-Waite reduction x = n ln2 + r,
// |r| <= ln2 / 2, and the Taylor series of e^r to r^8 (truncation < 3e-10 relative).
template <class T> inline T exp_nonpositive(const T& x) noexcept {
  const T xc = max(min(x, T(0.f)), T(-87.f));
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
  return sel(x > T(-87.f), p * pow2_int(n), T(0.f));
}

// 8-point Gauss-Legendre on [0, 1]: nodes and weights.
inline constexpr float gl8_x[8] = {0.0198550717512319f, 0.1016667612931866f, 0.2372337950418355f,
                                   0.4082826787521751f, 0.5917173212478249f, 0.7627662049581645f,
                                   0.8983332387068134f, 0.9801449282487681f};
inline constexpr float gl8_w[8] = {0.0506142681451881f, 0.1111905172266872f, 0.1568533229389436f,
                                   0.1813418916891810f, 0.1813418916891810f, 0.1568533229389436f,
                                   0.1111905172266872f, 0.0506142681451881f};

// The coat's internal reflectance R_i (see the header comment) for attenuation
// a = 2 sigma thickness. mu_c and the Fresnel values at the second part's nodes do not
// depend on a: coat_internal_nodes computes them once per lane.
template <class T> struct CoatNodes {
  T mu[16], w[16];  // nodes in mu and weights (including F_int and the 2 mu dmu measure)
};
template <class T> inline CoatNodes<T> coat_internal_nodes(const T& eta) noexcept {
  CoatNodes<T> c;
  const T inv_eta = T(1.f) / eta;
  const T mu_c = sqrt(max(T(1.f) - inv_eta * inv_eta, T(0.f)));
  const T span = T(1.f) - mu_c;
  for (int k = 0; k < 8; ++k) {
    // [0, mu_c]: F_int = 1
    const T m1 = mu_c * T(gl8_x[k]);
    c.mu[k] = m1;
    c.w[k] = T(2.f * gl8_w[k]) * m1 * mu_c;
    // [mu_c, 1], mu = mu_c + span s^2, dmu = 2 span s ds
    const T s = T(gl8_x[k]);
    const T m2 = mul_add(span, s * s, mu_c);
    c.mu[8 + k] = m2;
    const T Fi = fresnel_dielectric(m2, inv_eta);
    c.w[8 + k] = T(2.f * gl8_w[k]) * m2 * (T(2.f) * span * s) * Fi;
  }
  return c;
}
template <class T> inline T coat_internal_reflectance(const CoatNodes<T>& c, const T& a) noexcept {
  T sum = T(0.f);
  for (int k = 0; k < 16; ++k) {
    const T mu = c.mu[k];
    const T att = exp_nonpositive(-a / sel(mu > T(0.f), mu, T(1.f)));
    sum = mul_add(c.w[k], sel(mu > T(0.f), att, T(0.f)), sum);
  }
  return sum;
}

// cos of the refracted direction inside the coat for an outside cosine mu >= 0.
template <class T> inline T refracted_cos(const T& mu, const T& inv_eta) noexcept {
  const T sin2_t = ((T(1.f) - mu) * (T(1.f) + mu)) * (inv_eta * inv_eta);
  return sqrt(max(T(1.f) - sin2_t, T(0.f)));
}

}  // namespace bsdf_detail

template <class T> struct CoatedDiffuseBsdf {
  T eta, alpha_x, alpha_y;
  Rgb3<T> rho;
  T thickness;
  Rgb3<T> albedo;

  TrowbridgeReitz<T> distribution() const noexcept { return TrowbridgeReitz<T>{alpha_x, alpha_y}.clamped(); }

  // The per-lane quantities that do not depend on wi.
  struct Setup {
    T sgn, Fo, p_coat;
    Vec3<T> o;
    Rgb3<T> k;  // (1 - F(mu_o)) Tr(mu_o') rho / (pi eta^2 (1 - rho R_i)) per channel
    Rgb3<T> sigma_d;  // sigma thickness per channel
    mask_t<T> smooth;
  };
  Setup setup(const Vec3<T>& wo) const noexcept {
    using namespace bsdf_detail;
    Setup s;
    s.sgn = sign_of_z(wo);
    s.o = mirror_z(wo, s.sgn);
    s.smooth = effectively_smooth(alpha_x, alpha_y);
    s.Fo = fresnel_dielectric(s.o.z, eta);
    const T dc = thickness;
    s.sigma_d = {(T(1.f) - albedo.r) * dc, (T(1.f) - albedo.g) * dc, (T(1.f) - albedo.b) * dc};
    const CoatNodes<T> nodes = coat_internal_nodes(eta);
    Rgb3<T> Ri;
    Ri.r = coat_internal_reflectance(nodes, T(2.f) * s.sigma_d.r);
    if (all(albedo.r == T(0.f) && albedo.g == T(0.f) && albedo.b == T(0.f))) {
      Ri.g = Ri.r;
      Ri.b = Ri.r;
    } else {
      Ri.g = coat_internal_reflectance(nodes, T(2.f) * s.sigma_d.g);
      Ri.b = coat_internal_reflectance(nodes, T(2.f) * s.sigma_d.b);
    }
    const T inv_eta = T(1.f) / eta;
    const T mo = refracted_cos(s.o.z, inv_eta);
    const T c = (T(1.f) - s.Fo) * (T(inv_pi_f) * inv_eta * inv_eta);
    auto chan = [&](const T& rh, const T& sd, const T& ri) {
      const T tr = exp_nonpositive(-sd / sel(mo > T(0.f), mo, T(1.f)));
      return sel(mo > T(0.f), c * rh * tr / max(T(1.f) - rh * ri, T(1e-6f)), T(0.f));
    };
    s.k = {chan(rho.r, s.sigma_d.r, Ri.r), chan(rho.g, s.sigma_d.g, Ri.g), chan(rho.b, s.sigma_d.b, Ri.b)};
    const T base_w = (T(1.f) - s.Fo) * max3(rho);
    const T den = s.Fo + base_w;
    s.p_coat = sel(den > T(0.f), s.Fo / sel(den > T(0.f), den, T(1.f)), T(1.f));
    return s;
  }

  // f and the mixture pdf for a direction i in the mirrored frame.
  void eval_mirrored(const Setup& s, const Vec3<T>& i, Rgb3<T>& f, T& pdf) const noexcept {
    using namespace bsdf_detail;
    const mask_t<T> up = i.z > T(0.f) && s.o.z > T(0.f);
    const T inv_eta = T(1.f) / eta;
    const T mi = refracted_cos(i.z, inv_eta);
    const T Fi = fresnel_dielectric(i.z, eta);
    const T ti = (T(1.f) - Fi);
    auto tr = [&](const T& sd) { return exp_nonpositive(-sd / sel(mi > T(0.f), mi, T(1.f))); };
    const mask_t<T> base_on = up && mi > T(0.f);
    f.r = sel(base_on, s.k.r * ti * tr(s.sigma_d.r), T(0.f));
    f.g = sel(base_on, s.k.g * ti * tr(s.sigma_d.g), T(0.f));
    f.b = sel(base_on, s.k.b * ti * tr(s.sigma_d.b), T(0.f));
    const ReflectionTerms<T> t = reflection_terms(distribution(), s.o, i);
    const mask_t<T> coat_on = t.ok && !s.smooth;
    const T fc = sel(coat_on, t.f_over_F * fresnel_dielectric(t.dot_o, eta), T(0.f));
    f.r = f.r + fc;
    f.g = f.g + fc;
    f.b = f.b + fc;
    const T p_diff = sel(up, (T(1.f) - s.p_coat) * (i.z * T(inv_pi_f)), T(0.f));
    pdf = p_diff + sel(coat_on, s.p_coat * t.pdf, T(0.f));
  }

  BsdfEval<T> eval(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    const Setup s = setup(wo);
    BsdfEval<T> e;
    eval_mirrored(s, bsdf_detail::mirror_z(wi, s.sgn), e.f, e.pdf);
    return e;
  }
  T pdf(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept { return eval(wo, wi).pdf; }

  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T& u1, const T& u2) const noexcept {
    using namespace bsdf_detail;
    const Setup s = setup(wo);
    const mask_t<T> coat = uc < s.p_coat;
    const TrowbridgeReitz<T> d = distribution();
    const Vec3<T> wm = d.sample_visible(s.o, u1, u2);
    const Vec3<T> ir = sel(s.smooth, Vec3<T>(-s.o.x, -s.o.y, s.o.z), reflect(s.o, wm));
    const Vec3<T> l = sample_cosine_hemisphere(u1, u2);
    const Vec3<T> i = sel(coat, ir, l);
    Rgb3<T> f;
    T p;
    eval_mirrored(s, i, f, p);
    BsdfSample<T> r;
    r.delta = coat && s.smooth;
    const mask_t<T> delta_ok = s.o.z > T(0.f);
    const mask_t<T> cont_ok = i.z > T(0.f) && p > T(0.f) && s.o.z > T(0.f);
    r.valid = sel_mask(r.delta, delta_ok, cont_ok);
    r.wi = sel(r.valid, mirror_z(i, s.sgn), Vec3<T>(T(0.f), T(0.f), T(1.f)) * s.sgn);
    r.pdf = sel(r.valid, sel(r.delta, s.p_coat, p), T(0.f));
    const T wc = div_or0(r.valid && !r.delta, i.z, p);
    const T wd = div_or0(r.valid && r.delta, s.Fo, s.p_coat);
    r.weight = {sel(r.delta, wd, f.r * wc), sel(r.delta, wd, f.g * wc), sel(r.delta, wd, f.b * wc)};
    return r;
  }
};

}  // namespace tuile
