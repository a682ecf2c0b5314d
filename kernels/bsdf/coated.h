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
// R_i by Gauss-Legendre quadrature, once per material (the material table's mp_ri_*,
// coat_internal_reflectance_rgb; it depends on eta, thickness and albedo alone), or at each
// evaluation where the caller gives none: 8 nodes on [0, mu_c] (total internal
// reflection, integrand 2 mu exp(-a / mu)) and 8 nodes on [mu_c, 1] in s with
// mu = mu_c + (1 - mu_c) s^2 (which removes F_int's square-root kink at mu_c).
// Sampling: the coat lobe with probability p_c = F(mu_o) / (F(mu_o) + (1 - F(mu_o)) max(rho))
// (a mirror direction, or a visible normal of the coat's distribution), else a
// cosine-weighted direction; the pdf is the mixture p_c pdf_coat + (1 - p_c) cos / pi (the
// delta part excluded, as everywhere: a mirror sample reports pdf p_c).
// Sources: Weidlich & Wilkie 2007 ("Arbitrarily layered micro-facet surfaces"); Jakob,
// Mitsuba 0.5 plastic/roughplastic; pbrt-v4 LayeredBxDF (4th ed. 14.3); Walter et al. 2007.
//
// pbrt-v4's "coatedconductor" (CoatedConductorBsdf): the same coat over a conductor of
// complex index (conductor_eta + i conductor_k) / eta, relative to the coat medium as
// pbrt-v4's CoatedConductorMaterial divides it, with its own Trowbridge-Reitz alphas.
// Deterministic as well, in the mirrored frame, with o' = (o.x / eta, o.y / eta, mu_o')
// the direction inside the coat whose smooth refraction is o (likewise i'):
//   f = f_coat + f_base,  f_coat as above,
//   f_base = h(o) h(i) f_c(o', i') / eta^2,
//   h(x) = (1 - F(mu_x)) Tr(mu_x') / sqrt(1 - F(mu_x) Fc(mu_x') Tr(mu_x')^2)  per channel,
// f_c the conductor's microfacet BRDF (D G Fc(o'.wm) / (4 mu_o' mu_i'), the half vector of
// o' and i') with the inner alphas alpha'^2 = alpha_base^2 + w alpha_coat^2 per axis,
// w = (eta - 1)^2 / (2 eta^2) (0 under a smooth coat). This is light refracted in
// ((1 - F) and, with the compression of solid angle d omega' = mu_i d omega / (eta^2 mu_i')
// and the eta^2 of radiance entering, 1 / eta^2 in all), reflected once by the conductor,
// refracted out, attenuated by the slab both ways; the factor under the square roots sums
// the series of internal reflections at the coat along the macro directions (coat and
// conductor reflecting with F and Fc), exact for the mirror path: with both layers smooth
// the BSDF is one delta lobe at the mirror direction with weight
//   F(mu_o) + B(o),  B(o) = (1 - F)^2 Fc Tr^2 / (1 - F Fc Tr^2)  (F at mu_o, Fc, Tr at mu_o'),
// the sum of pbrt-v4's walk (without its maxDepth). The square root splits it
// reciprocally between o and i for rough bases. Neglected: light the rough base reflects
// beyond the critical angle (trapped by total internal reflection, it bounces on in the
// walk: the model is up to 0.14 darker in a bright channel at base alpha 0.3); with a
// rough coat, its Fresnel transmittance and microfacet loss are the smooth coat's (as
// above), and its spread of the refracted directions is folded into the inner alphas
// (small-angle: a facet tilt d deviates the exit direction by (eta - 1) d on each crossing,
// a base facet by 2 eta d, so as variances alpha'^2 += 2 ((eta - 1) / (2 eta))^2
// alpha_coat^2). albedo: sigma = 1 - albedo as above (for a conductor the scattered light
// keeps the specular path: energy-conserving, angularly wrong). tests/test_materials.cpp
// measures all of this against pbrt-v4's random walk with a conductor bottom.
// Sampling: the coat with p_c = F(mu_o) / (F(mu_o) + max B(o)), else the base: a visible
// normal of the inner distribution seen from o', i' its mirror, refracted out (invalid
// under total internal reflection); pdf = p_c pdf_coat + (1 - p_c) pdf_vndf(i') mu_i /
// (eta^2 mu_i'). Delta lobes (pdf = the lobe's probability): a smooth coat's mirror
// (weight F / p_c), a smooth inner base's mirror (B / (1 - p_c)), both (one lobe, pdf 1,
// weight F + B).
#pragma once
#include "bsdf/bsdf.h"
#include "bsdf/conductor.h"
#include "bsdf/dielectric.h"
#include "bsdf/fresnel.h"
#include "bsdf/microfacet.h"
#include "sample/sampling.h"

namespace tuile {

namespace bsdf_detail {

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
    const T att = lane_math::exp_nonpositive(-a / sel(mu > T(0.f), mu, T(1.f)));
    sum = mul_add(c.w[k], sel(mu > T(0.f), att, T(0.f)), sum);
  }
  return sum;
}

// sigma thickness per channel, sigma = 1 - albedo (see the header comment).
template <class T> inline Rgb3<T> slab_depth(const Rgb3<T>& albedo, const T& thickness) noexcept {
  return {(T(1.f) - albedo.r) * thickness, (T(1.f) - albedo.g) * thickness, (T(1.f) - albedo.b) * thickness};
}

// R_i per channel for a coat of index eta over a slab of that thickness and albedo.
template <class T> inline Rgb3<T> coat_internal_reflectance_rgb(const T& eta, const T& thickness, const Rgb3<T>& albedo) noexcept {
  const Rgb3<T> sigma_d = slab_depth(albedo, thickness);
  const CoatNodes<T> nodes = coat_internal_nodes(eta);
  Rgb3<T> Ri;
  Ri.r = coat_internal_reflectance(nodes, T(2.f) * sigma_d.r);
  if (all(albedo.r == T(0.f) && albedo.g == T(0.f) && albedo.b == T(0.f))) {
    Ri.g = Ri.r;
    Ri.b = Ri.r;
  } else {
    Ri.g = coat_internal_reflectance(nodes, T(2.f) * sigma_d.g);
    Ri.b = coat_internal_reflectance(nodes, T(2.f) * sigma_d.b);
  }
  return Ri;
}

// cos of the refracted direction inside the coat for an outside cosine mu >= 0.
template <class T> inline T refracted_cos(const T& mu, const T& inv_eta) noexcept {
  const T sin2_t = ((T(1.f) - mu) * (T(1.f) + mu)) * (inv_eta * inv_eta);
  return sqrt(max(T(1.f) - sin2_t, T(0.f)));
}

// The slab's transmittance along a direction of cosine mu' inside it, for a per-channel
// optical depth sd = sigma thickness: exp(-sd / mu') (0 where mu' <= 0 is never read: the
// callers mask those lanes).
template <class T> inline T layer_tr(const T& sd, const T& mu) noexcept {
  return lane_math::exp_nonpositive(-sd / sel(mu > T(0.f), mu, T(1.f)));
}
template <class T> inline Rgb3<T> layer_tr(const Rgb3<T>& sd, const T& mu) noexcept {
  return {layer_tr(sd.r, mu), layer_tr(sd.g, mu), layer_tr(sd.b, mu)};
}
// The same, one exponential where every lane's three depths are equal (albedo 0, a grey
// albedo, or no slab: the usual case): the same bits.
template <class T> inline Rgb3<T> layer_tr_rgb(const Rgb3<T>& sd, const T& mu) noexcept {
  if (all(sd.r == sd.g && sd.g == sd.b)) {
    const T t = layer_tr(sd.r, mu);
    return {t, t, t};
  }
  return layer_tr(sd, mu);
}
// What the coated BSDFs share about their top interface, per lane, in the frame mirrored
// so that wo.z >= 0.
template <class T> struct CoatTop {
  T sgn;             // the mirroring, +1 or -1
  Vec3<T> o;         // wo mirrored
  mask_t<T> smooth;  // the coat's reflection is a delta lobe
  T Fo;              // F(mu_o)
};
template <class T> inline CoatTop<T> coat_top(const Vec3<T>& wo, const T& eta, const T& ax, const T& ay) noexcept {
  CoatTop<T> c;
  c.sgn = sign_of_z(wo);
  c.o = mirror_z(wo, c.sgn);
  c.smooth = effectively_smooth(ax, ay);
  c.Fo = fresnel_dielectric(c.o.z, eta);
  return c;
}
// The probability of sampling the coat's lobe: F(mu_o) against the base's weight.
template <class T> inline T coat_probability(const T& Fo, const T& base_w) noexcept {
  const T den = Fo + base_w;
  return sel(den > T(0.f), Fo / sel(den > T(0.f), den, T(1.f)), T(1.f));
}
// The rough coat's reflection lobe at i (mirrored frame): f = D G F(wo.wm) / (4 mu_o mu_i)
// and its visible-normal pdf, both 0 on smooth lanes and where the lobe is off.
template <class T>
inline void coat_lobe(const TrowbridgeReitz<T>& d, const CoatTop<T>& c, const T& eta, const Vec3<T>& i, T& fc,
                      T& pdf) noexcept {
  const ReflectionTerms<T> t = reflection_terms(d, c.o, i);
  const mask_t<T> coat_on = t.ok && !c.smooth;
  fc = sel(coat_on, t.f_over_F * fresnel_dielectric(t.dot_o, eta), T(0.f));
  pdf = sel(coat_on, t.pdf, T(0.f));
}
// A direction of the coat's lobe: the mirror direction (smooth), else the reflection about
// a visible normal.
template <class T>
inline Vec3<T> coat_sample_dir(const TrowbridgeReitz<T>& d, const CoatTop<T>& c, const T& u1, const T& u2) noexcept {
  const Vec3<T> wm = d.sample_visible(c.o, u1, u2);
  return sel(c.smooth, Vec3<T>(-c.o.x, -c.o.y, c.o.z), reflect(c.o, wm));
}

}  // namespace bsdf_detail

// (the material table computes R_i once per material: mp_ri_*)
using bsdf_detail::coat_internal_reflectance_rgb;

// A dielectric coat (index eta, Trowbridge-Reitz alpha_x, alpha_y) over a base layer,
// separated by a slab of thickness `thickness` and single-scattering albedo `albedo`: the
// shape of pbrt-v4's LayeredBxDF<DielectricBxDF, Bottom>, evaluated by the deterministic
// models of the header comment instead of its random walk. The template owns the coat: its
// reflection lobe, the choice between coat and base when sampling, the mirrored frame
// (two-sided), the delta lobes' weights and the sample's bookkeeping. Base, the layer seen
// through the coat, provides (all in the mirrored frame, wo.z >= 0):
//   struct Setup: its per-lane quantities of wo (setup(coat, top, sigma_d));
//   weight(Setup, top): its albedo seen from wo, against which F(mu_o) sets the probability
//     of sampling the coat;
//   eval(coat, Setup, sigma_d, i, up, f, pdf): its f and its lobe's density at i;
//   mixture_pdf(p_coat, up, i, pdf_base, pdf_coat): the two lobes' mixture density;
//   sample(coat, Setup, u1, u2): a direction of its lobe, whether it exists, whether it is a
//     delta lobe (smooth), and that lobe's weight per channel (delta_weight, 0 where it has
//     no delta lobe).
template <class T, class Base> struct CoatedBsdf {
  T eta, alpha_x, alpha_y;
  Base base;
  T thickness;
  Rgb3<T> albedo;

  TrowbridgeReitz<T> distribution() const noexcept { return TrowbridgeReitz<T>{alpha_x, alpha_y}.clamped(); }

  // The per-lane quantities that do not depend on wi.
  struct Setup {
    bsdf_detail::CoatTop<T> top;
    Rgb3<T> sigma_d;  // sigma thickness per channel
    typename Base::Setup b;
    T p_coat;
  };
  Setup setup(const Vec3<T>& wo) const noexcept {
    using namespace bsdf_detail;
    Setup s;
    s.top = coat_top(wo, eta, alpha_x, alpha_y);
    s.sigma_d = slab_depth(albedo, thickness);
    s.b = base.setup(*this, s.top, s.sigma_d);
    s.p_coat = coat_probability(s.top.Fo, base.weight(s.b, s.top));
    return s;
  }

  // f and the mixture pdf (continuous lobes) for a direction i in the mirrored frame.
  void eval_mirrored(const Setup& s, const Vec3<T>& i, Rgb3<T>& f, T& pdf) const noexcept {
    using namespace bsdf_detail;
    const mask_t<T> up = i.z > T(0.f) && s.top.o.z > T(0.f);
    T pb;
    base.eval(*this, s.b, s.sigma_d, i, up, f, pb);
    T fc, pc;
    coat_lobe(distribution(), s.top, eta, i, fc, pc);
    f.r = f.r + fc;
    f.g = f.g + fc;
    f.b = f.b + fc;
    pdf = Base::mixture_pdf(s.p_coat, up, i, pb, pc);
  }

  BsdfEval<T> eval(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    const Setup s = setup(wo);
    BsdfEval<T> e;
    eval_mirrored(s, bsdf_detail::mirror_z(wi, s.top.sgn), e.f, e.pdf);
    return e;
  }
  T pdf(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept { return eval(wo, wi).pdf; }

  // The coat's lobe with probability p_coat, else the base's. Delta lobes (pdf = the
  // lobe's probability): a smooth coat's mirror (weight F / p_coat), a smooth base's delta
  // (its delta_weight / (1 - p_coat)), and, where both are smooth, their one lobe at the
  // mirror direction (pdf 1, weight F + the base's).
  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T& u1, const T& u2) const noexcept {
    using namespace bsdf_detail;
    const Setup s = setup(wo);
    const Vec3<T>& o = s.top.o;
    const mask_t<T> coat = uc < s.p_coat;
    const Vec3<T> ic = coat_sample_dir(distribution(), s.top, u1, u2);
    const typename Base::Sample bs = base.sample(*this, s.b, u1, u2);
    const Vec3<T> i = sel(coat, ic, bs.wi);
    Rgb3<T> f;
    T p;
    eval_mirrored(s, i, f, p);
    BsdfSample<T> r;
    const mask_t<T> both = s.top.smooth && bs.smooth;
    r.delta = both || sel_mask(coat, s.top.smooth, bs.smooth);
    const mask_t<T> delta_ok = o.z > T(0.f);
    const mask_t<T> cont_ok = i.z > T(0.f) && p > T(0.f) && o.z > T(0.f) && (coat || bs.ok);
    r.valid = sel_mask(r.delta, delta_ok, cont_ok);
    r.wi = sel(r.valid, mirror_z(i, s.top.sgn), Vec3<T>(T(0.f), T(0.f), T(1.f)) * s.top.sgn);
    const T p_lobe = sel(both, T(1.f), sel(coat, s.p_coat, T(1.f) - s.p_coat));
    r.pdf = sel(r.valid, sel(r.delta, p_lobe, p), T(0.f));
    const T wc = div_or0(r.valid && !r.delta, i.z, p);
    const mask_t<T> dv = r.valid && r.delta;
    const T wcoat = sel(both || coat, s.top.Fo, T(0.f));
    const mask_t<T> with_base = both || !coat;
    auto chan = [&](const T& fch, const T& Bo) {
      return sel(r.delta, div_or0(dv, wcoat + sel(with_base, Bo, T(0.f)), p_lobe), fch * wc);
    };
    r.weight = {chan(f.r, bs.delta_weight.r), chan(f.g, bs.delta_weight.g), chan(f.b, bs.delta_weight.b)};
    return r;
  }
};

// The base of pbrt-v4's "coateddiffuse": a Lambertian layer of albedo rho (the first part
// of the header comment).
template <class T> struct DiffuseBase {
  Rgb3<T> rho;
  // R_i when the caller has it (the material table's, coat_internal_reflectance_rgb of the
  // same parameters: the same bits), else computed at each setup
  bool ri_given = false;
  Rgb3<T> ri{T(0.f), T(0.f), T(0.f)};

  struct Setup {
    Rgb3<T> k;  // (1 - F(mu_o)) Tr(mu_o') rho / (pi eta^2 (1 - rho R_i)) per channel
  };
  template <class Coat>
  Setup setup(const Coat& coat, const bsdf_detail::CoatTop<T>& top, const Rgb3<T>& sigma_d) const noexcept {
    using namespace bsdf_detail;
    Setup s;
    const Rgb3<T> Ri = ri_given ? ri : coat_internal_reflectance_rgb(coat.eta, coat.thickness, coat.albedo);
    const T inv_eta = T(1.f) / coat.eta;
    const T mo = refracted_cos(top.o.z, inv_eta);
    const T c = (T(1.f) - top.Fo) * (T(inv_pi_f) * inv_eta * inv_eta);
    const Rgb3<T> tr = layer_tr_rgb(sigma_d, mo);
    auto chan = [&](const T& rh, const T& t, const T& ri) {
      return sel(mo > T(0.f), c * rh * t / max(T(1.f) - rh * ri, T(1e-6f)), T(0.f));
    };
    s.k = {chan(rho.r, tr.r, Ri.r), chan(rho.g, tr.g, Ri.g), chan(rho.b, tr.b, Ri.b)};
    return s;
  }
  T weight(const Setup&, const bsdf_detail::CoatTop<T>& top) const noexcept {
    return (T(1.f) - top.Fo) * bsdf_detail::max3(rho);
  }
  template <class Coat>
  void eval(const Coat& coat, const Setup& s, const Rgb3<T>& sigma_d, const Vec3<T>& i, const mask_t<T>& up, Rgb3<T>& f,
            T& pdf) const noexcept {
    using namespace bsdf_detail;
    const T inv_eta = T(1.f) / coat.eta;
    const T mi = refracted_cos(i.z, inv_eta);
    const T Fi = fresnel_dielectric(i.z, coat.eta);
    const T ti = (T(1.f) - Fi);
    const mask_t<T> base_on = up && mi > T(0.f);
    const Rgb3<T> tr = layer_tr_rgb(sigma_d, mi);
    f.r = sel(base_on, s.k.r * ti * tr.r, T(0.f));
    f.g = sel(base_on, s.k.g * ti * tr.g, T(0.f));
    f.b = sel(base_on, s.k.b * ti * tr.b, T(0.f));
    pdf = i.z * T(inv_pi_f);  // cosine-weighted (read where up)
  }
  static T mixture_pdf(const T& p_coat, const mask_t<T>& up, const Vec3<T>&, const T& pb, const T& pc) noexcept {
    return sel(up, (T(1.f) - p_coat) * pb, T(0.f)) + p_coat * pc;
  }
  struct Sample {
    Vec3<T> wi;
    mask_t<T> ok, smooth;
    Rgb3<T> delta_weight;
  };
  template <class Coat> Sample sample(const Coat&, const Setup&, const T& u1, const T& u2) const noexcept {
    Sample b;
    b.wi = sample_cosine_hemisphere(u1, u2);
    b.ok = mask_t<T>(true);
    b.smooth = mask_t<T>(false);
    b.delta_weight = {T(0.f), T(0.f), T(0.f)};
    return b;
  }
};

// The base of pbrt-v4's "coatedconductor": a conductor of complex index conductor_eta +
// i conductor_k relative to the outside, Trowbridge-Reitz base_alpha_x, base_alpha_y (the
// second part of the header comment).
template <class T> struct ConductorBase {
  Rgb3<T> conductor_eta, conductor_k;
  T base_alpha_x, base_alpha_y;

  // The base's distribution as seen inside the coat: its alphas widened by the rough
  // coat's spread of the refracted directions, alpha'^2 = alpha_base^2 + w alpha_coat^2
  // with w = (eta - 1)^2 / (2 eta^2) (0 under a smooth coat), not yet clamped.
  template <class Coat> TrowbridgeReitz<T> distribution(const Coat& coat, const mask_t<T>& coat_smooth) const noexcept {
    const T e1 = coat.eta - T(1.f);
    const T w = sel(coat_smooth, T(0.f), (e1 * e1) / (T(2.f) * coat.eta * coat.eta));
    return {sqrt(mul_add(w * coat.alpha_x, coat.alpha_x, base_alpha_x * base_alpha_x)),
            sqrt(mul_add(w * coat.alpha_y, coat.alpha_y, base_alpha_y * base_alpha_y))};
  }

  struct Setup {
    TrowbridgeReitz<T> base;  // clamped
    mask_t<T> base_smooth;
    T inv_eta;
    Vec3<T> o;              // wo mirrored
    Vec3<T> op;             // o refracted into the coat, pointing up (the base's wo)
    Rgb3<T> ceta, ck;       // the conductor's index relative to the coat
    Rgb3<T> ko;             // h(o) / eta^2, h(x) = (1 - F) Tr / sqrt(1 - F Fc Tr^2) at x
    Rgb3<T> Bo;             // the smooth base's weight (1 - F)^2 Fc Tr^2 / (1 - F Fc Tr^2) at o
  };
  // h and the smooth base's weight for an outside cosine mu (refracted: mu_p), per channel.
  static void base_factors(const T& F, const T& Fc, const T& tr, T& h, T& B) noexcept {
    const T t = T(1.f) - F;
    const T tr2 = tr * tr;
    const T den = max(T(1.f) - F * Fc * tr2, T(1e-12f));
    h = t * tr / sqrt(den);
    B = t * t * Fc * tr2 / den;
  }
  template <class Coat>
  Setup setup(const Coat& coat, const bsdf_detail::CoatTop<T>& top, const Rgb3<T>& sigma_d) const noexcept {
    using namespace bsdf_detail;
    Setup s;
    const TrowbridgeReitz<T> b = distribution(coat, top.smooth);
    s.base_smooth = b.effectively_smooth();
    s.base = b.clamped();
    s.inv_eta = T(1.f) / coat.eta;
    s.o = top.o;
    const T mo = refracted_cos(top.o.z, s.inv_eta);
    s.op = {top.o.x * s.inv_eta, top.o.y * s.inv_eta, mo};
    s.ceta = scale(conductor_eta, s.inv_eta);
    s.ck = scale(conductor_k, s.inv_eta);
    const Rgb3<T> Fc = fresnel_complex(mo, s.ceta, s.ck);
    const Rgb3<T> tr = layer_tr_rgb(sigma_d, mo);
    const T c = s.inv_eta * s.inv_eta;
    const mask_t<T> in = mo > T(0.f);
    T h, B;
    base_factors(top.Fo, Fc.r, tr.r, h, B);
    s.ko.r = sel(in, h * c, T(0.f)), s.Bo.r = sel(in, B, T(0.f));
    base_factors(top.Fo, Fc.g, tr.g, h, B);
    s.ko.g = sel(in, h * c, T(0.f)), s.Bo.g = sel(in, B, T(0.f));
    base_factors(top.Fo, Fc.b, tr.b, h, B);
    s.ko.b = sel(in, h * c, T(0.f)), s.Bo.b = sel(in, B, T(0.f));
    return s;
  }
  T weight(const Setup& s, const bsdf_detail::CoatTop<T>&) const noexcept { return bsdf_detail::max3(s.Bo); }
  template <class Coat>
  void eval(const Coat& coat, const Setup& s, const Rgb3<T>& sigma_d, const Vec3<T>& i, const mask_t<T>& up, Rgb3<T>& f,
            T& pdf) const noexcept {
    using namespace bsdf_detail;
    // between the refracted directions o' and i'
    const T mi = refracted_cos(i.z, s.inv_eta);
    const Vec3<T> ip{i.x * s.inv_eta, i.y * s.inv_eta, mi};
    const T Fi = fresnel_dielectric(i.z, coat.eta);
    const Rgb3<T> Fci = fresnel_complex(mi, s.ceta, s.ck);
    const Rgb3<T> tri = layer_tr_rgb(sigma_d, mi);
    const ReflectionTerms<T> t = reflection_terms(s.base, s.op, ip);
    const mask_t<T> base_on = up && mi > T(0.f) && s.op.z > T(0.f) && t.ok && !s.base_smooth;
    const Rgb3<T> Fm = fresnel_complex(t.dot_o, s.ceta, s.ck);
    const T fb = sel(base_on, t.f_over_F, T(0.f));
    auto chan = [&](const T& ko, const T& Fc, const T& tr, const T& F) {
      T h, B;
      base_factors(Fi, Fc, tr, h, B);
      return sel(base_on, ko * h * F * fb, T(0.f));
    };
    f = {chan(s.ko.r, Fci.r, tri.r, Fm.r), chan(s.ko.g, Fci.g, tri.g, Fm.g), chan(s.ko.b, Fci.b, tri.b, Fm.b)};
    // the density of i = the density of i' times d omega' / d omega = mu_i / (eta^2 mu_i')
    const T jac = div_or0(base_on, i.z * (s.inv_eta * s.inv_eta), mi);
    pdf = sel(base_on, t.pdf * jac, T(0.f));
  }
  static T mixture_pdf(const T& p_coat, const mask_t<T>&, const Vec3<T>&, const T& pb, const T& pc) noexcept {
    return mul_add(T(1.f) - p_coat, pb, p_coat * pc);
  }
  struct Sample {
    Vec3<T> wi;
    mask_t<T> ok, smooth;
    Rgb3<T> delta_weight;
  };
  // a visible normal of the inner distribution seen from o', the reflection about it,
  // refracted out (invalid where it is totally internally reflected); a smooth base: the
  // mirror direction
  template <class Coat> Sample sample(const Coat& coat, const Setup& s, const T& u1, const T& u2) const noexcept {
    Sample b;
    const Vec3<T> wm = s.base.sample_visible(s.op, u1, u2);
    const Vec3<T> ipb = reflect(s.op, wm);
    const T e2 = coat.eta * coat.eta;
    const T st2 = e2 * mul_add(ipb.x, ipb.x, ipb.y * ipb.y);
    b.ok = ipb.z > T(0.f) && st2 < T(1.f);
    const Vec3<T> mirror{-s.o.x, -s.o.y, s.o.z};
    b.wi = sel(s.base_smooth, mirror, Vec3<T>(ipb.x * coat.eta, ipb.y * coat.eta, sqrt(max(T(1.f) - st2, T(0.f)))));
    b.smooth = s.base_smooth;
    b.delta_weight = s.Bo;
    return b;
  }
};

// pbrt-v4's "coateddiffuse" and "coatedconductor", with their parameters in pbrt's order.
template <class T> struct CoatedDiffuseBsdf : CoatedBsdf<T, DiffuseBase<T>> {
  CoatedDiffuseBsdf(T eta, T alpha_x, T alpha_y, Rgb3<T> rho, T thickness, Rgb3<T> albedo) noexcept
      : CoatedBsdf<T, DiffuseBase<T>>{eta, alpha_x, alpha_y, DiffuseBase<T>{rho}, thickness, albedo} {}
  // ... with the coat's internal reflectance given (coat_internal_reflectance_rgb(eta,
  // thickness, albedo), e.g. the material table's mp_ri_*)
  CoatedDiffuseBsdf(T eta, T alpha_x, T alpha_y, Rgb3<T> rho, T thickness, Rgb3<T> albedo, Rgb3<T> ri) noexcept
      : CoatedBsdf<T, DiffuseBase<T>>{eta, alpha_x, alpha_y, DiffuseBase<T>{rho, true, ri}, thickness, albedo} {}
};
template <class T> struct CoatedConductorBsdf : CoatedBsdf<T, ConductorBase<T>> {
  CoatedConductorBsdf(T eta, T alpha_x, T alpha_y, Rgb3<T> conductor_eta, Rgb3<T> conductor_k, T base_alpha_x,
                      T base_alpha_y, T thickness, Rgb3<T> albedo) noexcept
      : CoatedBsdf<T, ConductorBase<T>>{eta, alpha_x, alpha_y,
                                         ConductorBase<T>{conductor_eta, conductor_k, base_alpha_x, base_alpha_y},
                                         thickness, albedo} {}
};

}  // namespace tuile
