// pbrt-v4's ThinDielectricBxDF, lane-generic: a thin slab of dielectric (index eta over the
// surrounding medium) seen as one surface. Light inside the slab bounces between its two
// parallel faces; summing the geometric series of the internal reflections gives
// R' = R + T^2 R / (1 - R^2) and T' = 1 - R' (R, T the single-interface Fresnel terms at
// |cos_o|). Both lobes are deltas: mirror reflection with probability R' / (R' + T'), and
// straight-through transmission wi = -wo (the two refractions cancel) with T' / (R' + T').
// eval and pdf are 0 (delta lobes only). Radiance is not scaled: light leaves into the
// medium it came from.
// Reads: per lane eta; wo local (unit). Writes: BsdfEval/BsdfSample.
// Source: pbrt-v4 (4th ed. 9.5.2, ThinDielectricBxDF).
#pragma once
#include "bsdf/bsdf.h"
#include "bsdf/fresnel.h"

namespace tuile {

template <class T> struct ThinDielectricBsdf {
  T eta;

  BsdfEval<T> eval(const Vec3<T>&, const Vec3<T>&) const noexcept {
    return {{T(0.f), T(0.f), T(0.f)}, T(0.f)};
  }
  T pdf(const Vec3<T>&, const Vec3<T>&) const noexcept { return T(0.f); }

  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T&, const T&) const noexcept {
    T R = fresnel_dielectric(abs(wo.z), eta);
    T Tr = T(1.f) - R;
    const mask_t<T> partial = R < T(1.f);
    const T one_m_r2 = (T(1.f) - R) * (T(1.f) + R);
    R = sel(partial, R + Tr * Tr * R / sel(partial, one_m_r2, T(1.f)), R);
    Tr = T(1.f) - R;
    const T sum = R + Tr;
    const T p_r = R / sum;
    const mask_t<T> refl = uc < p_r;
    BsdfSample<T> s;
    s.delta = mask_t<T>(true);
    s.valid = wo.z != T(0.f);
    s.wi = sel(refl, Vec3<T>(-wo.x, -wo.y, wo.z), -wo);
    s.wi = sel(s.valid, s.wi, Vec3<T>(T(0.f), T(0.f), T(1.f)));
    s.pdf = sel(s.valid, sel(refl, p_r, Tr / sum), T(0.f));
    const T w = sel(s.valid, sum, T(0.f));  // R' / p_r = T' / p_t = R' + T'
    s.weight = {w, w, w};
    return s;
  }
};

}  // namespace tuile
