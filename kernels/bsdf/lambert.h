// Lambert's diffuse BRDF, f = rho / pi, sampled by cosine-weighted directions: pdf =
// cos(theta) / pi, so f cos / pdf = rho exactly (the course's "use f_r as the pdf").
// Directions below the surface get f = 0 and pdf = 0. Source: Shirley & Chiu 1997
// (concentric disk) and Malley's method for the sampling map (sample/sampling.h).
#pragma once
#include "bsdf/bsdf.h"
#include "sample/sampling.h"

namespace tuile {

template <class T> struct Lambert {
  static constexpr bool reads_wo = false;
  Rgb3<T> rho;  // albedo, per channel, in [0, 1]

  T pdf(const SurfacePoint<T>& sp, const Vec3<T>& wi) const noexcept { return pdf_cosine_hemisphere(dot(sp.n, wi)); }

  BsdfEval<T> eval(const SurfacePoint<T>& sp, const Vec3<T>& wi) const noexcept {
    const T cos_theta = dot(sp.n, wi);
    const auto above = cos_theta > T(0.f);
    const T s = sel(above, T(inv_pi_f), T(0.f));
    return {{rho.r * s, rho.g * s, rho.b * s}, pdf_cosine_hemisphere(cos_theta)};
  }

  // A cosine-weighted direction around n (Duff et al.'s basis); invalid where the map
  // lands on the horizon.
  BsdfSample<T> sample(const SurfacePoint<T>& sp, const T& u1, const T& u2) const noexcept {
    const Vec3<T> local = sample_cosine_hemisphere(u1, u2);
    Vec3<T> t, b;
    make_basis(sp.n, t, b);
    BsdfSample<T> s;
    s.wi = normalize(t * local.x + b * local.y + sp.n * local.z);
    s.valid = local.z > T(0.f);
    s.weight = {sel(s.valid, rho.r, T(0.f)), sel(s.valid, rho.g, T(0.f)), sel(s.valid, rho.b, T(0.f))};
    s.pdf = pdf(sp, s.wi);
    s.delta = mask_t<T>(false);
    return s;
  }
};

}  // namespace tuile
