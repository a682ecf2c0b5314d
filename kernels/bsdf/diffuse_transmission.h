// pbrt-v4's DiffuseTransmissionBxDF, lane-generic: f = R / pi for wi on wo's side of the
// surface, T / pi on the other side. sample() picks reflection with probability
// pr = max(R) / (max(R) + max(T)) (per lane; invalid where both are 0), then a
// cosine-weighted direction on the chosen side: pdf = pr |cos_i| / pi (resp. (1 - pr)),
// weight = R / pr (resp. T / (1 - pr)).
// Reads: per lane r, t per channel; wo, wi local (unit; wo.z == 0 counts as above).
// Writes: BsdfEval/BsdfSample. Source: pbrt-v4 (4th ed. 9.3 exercise / bxdfs.h).
#pragma once
#include "bsdf/bsdf.h"
#include "bsdf/conductor.h"
#include "sample/sampling.h"

namespace tuile {

template <class T> struct DiffuseTransmissionBsdf {
  Rgb3<T> r, t;

  T prob_reflect(mask_t<T>& any_lobe) const noexcept {
    const T mr = bsdf_detail::max3(r), mt = bsdf_detail::max3(t);
    any_lobe = mr + mt > T(0.f);
    return bsdf_detail::div_or0(any_lobe, mr, mr + mt);
  }

  BsdfEval<T> eval(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    using namespace bsdf_detail;
    mask_t<T> on;
    const T pr = prob_reflect(on);
    const T ci = wi.z * sign_of_z(wo);
    const mask_t<T> same = ci > T(0.f), other = ci < T(0.f);
    const T s = T(inv_pi_f);
    BsdfEval<T> e;
    e.f = sel3(same, scale(r, s), sel3(other, scale(t, s), zero3<T>()));
    e.pdf = sel(on, sel(same, pr, sel(other, T(1.f) - pr, T(0.f))) * (abs(ci) * s), T(0.f));
    return e;
  }
  T pdf(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept { return eval(wo, wi).pdf; }

  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T& u1, const T& u2) const noexcept {
    using namespace bsdf_detail;
    mask_t<T> on;
    const T pr = prob_reflect(on);
    const mask_t<T> refl = uc < pr;
    const Vec3<T> l = sample_cosine_hemisphere(u1, u2);
    const T side = sign_of_z(wo) * sel(refl, T(1.f), T(-1.f));
    BsdfSample<T> s;
    s.delta = mask_t<T>(false);
    s.valid = on && l.z > T(0.f);
    s.wi = sel(s.valid, Vec3<T>(l.x, l.y, l.z * side), Vec3<T>(T(0.f), T(0.f), T(1.f)));
    const T p = sel(refl, pr, T(1.f) - pr);
    s.pdf = sel(s.valid, p * (l.z * T(inv_pi_f)), T(0.f));
    const T inv_p = div_or0(s.valid, T(1.f), p);
    s.weight = scale(sel3(refl, r, t), inv_p);
    return s;
  }
};

}  // namespace tuile
