// The Trowbridge-Reitz (GGX) microfacet distribution, lane-generic: the normal density
// D(wm), Smith's masking (Lambda, G1, the height-correlated G), the density of visible
// normals D_w(wm) and its sampling.
// Reads: alpha_x, alpha_y per lane (each lane its own material); directions in the local
// shading frame (z the shading normal), unit. Writes: densities, masking values, sampled
// microfacet normals (unit, z >= 0). Assumes finite input; alphas are clamped below at
// min_alpha (only lanes that are effectively smooth have smaller ones, and they never use
// the distribution: the clamp keeps their lanes finite).
// Only +, -, *, /, sqrt and the lane sincos (lanes/lane_math.h): every lane gives the
// scalar reference's bits.
// Sources: Trowbridge & Reitz 1975; Walter et al. 2007 (GGX); Heitz 2014 ("Understanding
// the masking-shadowing function", Lambda and the height-correlated G); Heitz 2018 (visible
// normals); Dupuy & Benyoub 2023 ("Sampling visible GGX normals with spherical caps": the
// sampling map used here, equivalent in distribution to Heitz 2018 and without its basis);
// pbrt-v4 (roughness_to_alpha, EffectivelySmooth).
#pragma once
#include <algorithm>
#include "bsdf/bsdf.h"
#include "lanes/lane_math.h"

namespace tuile {

inline constexpr float smooth_alpha = 1e-3f;  // max(alpha_x, alpha_y) below: a delta lobe (pbrt-v4)
inline constexpr float min_alpha = 1e-5f;     // the distribution clamps its alphas here

// pbrt-v4's TrowbridgeReitzDistribution::RoughnessToAlpha.
template <class T> inline T roughness_to_alpha(const T& roughness) noexcept { return sqrt(max(roughness, T(0.f))); }

// pbrt-v4's regularization of one alpha (TrowbridgeReitzDistribution::Regularize;
// Estimator::regularize): below 0.3, twice it within [0.1, 0.3] (0 becomes 0.1).
inline float regularized_alpha(float a) noexcept { return a < 0.3f ? std::clamp(2.f * a, 0.1f, 0.3f) : a; }

// Lanes whose lobe is a delta (pbrt-v4 EffectivelySmooth, the later form with max).
template <class T> inline mask_t<T> effectively_smooth(const T& alpha_x, const T& alpha_y) noexcept {
  return max(alpha_x, alpha_y) < T(smooth_alpha);
}

template <class T> struct TrowbridgeReitz {
  T alpha_x, alpha_y;

  mask_t<T> effectively_smooth() const noexcept { return tuile::effectively_smooth(alpha_x, alpha_y); }

  // The same distribution with the alphas clamped to min_alpha: what the BSDFs evaluate.
  TrowbridgeReitz clamped() const noexcept { return {max(alpha_x, T(min_alpha)), max(alpha_y, T(min_alpha))}; }

  // D(wm) = 1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2) for unit wm: the same value as
  // pbrt's tan^2 form, without its cos^4 underflow and its 1e-16 cutoff.
  T D(const Vec3<T>& wm) const noexcept {
    const T sx = wm.x / alpha_x, sy = wm.y / alpha_y;
    const T d = mul_add(sx, sx, mul_add(sy, sy, wm.z * wm.z));
    return T(inv_pi_f) / ((alpha_x * alpha_y) * (d * d));
  }

  // a = alpha(phi)^2 tan^2(theta) = (ax^2 x^2 + ay^2 y^2) / z^2; infinite at the horizon.
  T lambda_arg(const Vec3<T>& w) const noexcept {
    const T ax = alpha_x * w.x, ay = alpha_y * w.y;
    const T num = mul_add(ax, ax, ay * ay);
    const T z2 = w.z * w.z;
    return sel(z2 > T(0.f), num / sel(z2 > T(0.f), z2, T(1.f)), T(INFINITY));
  }
  // Lambda(w) = (sqrt(1 + a) - 1) / 2, as a / (2 (sqrt(1 + a) + 1)) (no cancellation).
  T Lambda(const Vec3<T>& w) const noexcept {
    const T a = lambda_arg(w);
    return sel(a < T(INFINITY), a / (T(2.f) * (sqrt(T(1.f) + a) + T(1.f))), T(INFINITY));
  }
  // G1 = 1 / (1 + Lambda) = 2 / (1 + sqrt(1 + a)): 0 at the horizon.
  T G1(const Vec3<T>& w) const noexcept { return T(2.f) / (T(1.f) + sqrt(T(1.f) + lambda_arg(w))); }
  // Height-correlated G = 1 / (1 + Lambda(wo) + Lambda(wi)) = 2 / (sqrt(1 + ao) + sqrt(1 + ai)).
  T G(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    return T(2.f) / (sqrt(T(1.f) + lambda_arg(wo)) + sqrt(T(1.f) + lambda_arg(wi)));
  }
  // G / G1(wo), the weight of a visible-normal sample (finite where G1(wo) > 0).
  T G_over_G1(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    const T so = sqrt(T(1.f) + lambda_arg(wo));
    return (T(1.f) + so) / (so + sqrt(T(1.f) + lambda_arg(wi)));
  }

  // Density of the normals visible from w, D_w(wm) = G1(w) |w.wm| D(wm) / |cos theta_w|
  // (pbrt-v4 D(w, wm), with AbsDot): it integrates to 1 over the wm with w.wm > 0.
  T D(const Vec3<T>& w, const Vec3<T>& wm) const noexcept {
    const T c = abs(w.z);
    return sel(c > T(0.f), G1(w) * abs(dot(w, wm)) * D(wm) / sel(c > T(0.f), c, T(1.f)), T(0.f));
  }
  T pdf(const Vec3<T>& w, const Vec3<T>& wm) const noexcept { return D(w, wm); }

  // A normal visible from w, with density D_w (Dupuy & Benyoub 2023): stretch w to the
  // hemisphere configuration, sample the spherical cap of directions c with c.z >= -w'.z
  // uniformly, h = c + w', unstretch. Returns wm with wm.z >= 0; w below the surface is
  // treated as its mirror -w (pbrt-v4's Sample_wm). (u1, u2) in [0, 1).
  Vec3<T> sample_visible(const Vec3<T>& w, const T& u1, const T& u2) const noexcept {
    const T sgn = sel(w.z < T(0.f), T(-1.f), T(1.f));
    Vec3<T> ws{alpha_x * w.x * sgn, alpha_y * w.y * sgn, w.z * sgn};
    ws = ws * (T(1.f) / sqrt(dot(ws, ws)));
    T sp, cp;
    lane_math::sincos_2pi(u1, sp, cp);
    const T z = mul_add(T(1.f) - u2, T(1.f) + ws.z, -ws.z);
    const T sin_t = sqrt(min(max((T(1.f) - z) * (T(1.f) + z), T(0.f)), T(1.f)));
    const Vec3<T> h{mul_add(sin_t, cp, ws.x), mul_add(sin_t, sp, ws.y), z + ws.z};
    Vec3<T> m{alpha_x * h.x, alpha_y * h.y, max(h.z, T(0.f))};
    const T l2 = dot(m, m);
    m = sel(l2 > T(0.f), m * (T(1.f) / sqrt(sel(l2 > T(0.f), l2, T(1.f)))), Vec3<T>(T(0.f), T(0.f), T(1.f)));
    return m;
  }
};

}  // namespace tuile
