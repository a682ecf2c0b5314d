// pbrt-v4's HairBxDF (Chiang, Bitterli, Tappan & Burley 2016, "A Practical and Controllable
// Hair and Fur Model for Production Path Tracing"), lane-generic: a dielectric cylinder
// with an absorbing interior, whose scattering is the sum of the lobes R (p = 0), TT
// (p = 1), TRT (p = 2) and the rest (p = 3, uniform in azimuth); each lobe is
// Mp (longitudinal, d'Eon et al. 2011, tilted by the cuticle's scale angle alpha)
// x Ap (attenuation: Fresnel and the interior's transmittance) x Np (azimuthal: a trimmed
// logistic around the lobe's exit angle Phi(p, gamma_o, gamma_t)).
//
// Frame: x along the fiber (the curve's tangent), z the shading normal, y = z cross x;
// h in [-1, 1] is where the ray met the fiber across its width (sin gamma_o). f includes
// pbrt-v4's division by |cos theta| with the normal (|wi.z|), so f |wi.z| is the lobes' sum.
// sample() picks a lobe with probability proportional to its mean attenuation A_p, then
// theta by Mp and the azimuth by Np (pbrt-v4's HairBxDF::Sample_f); its pdf and f are those
// of eval() at the sampled direction (the same code), so sample().pdf == eval(wi).pdf.
// With sigma_a = 0 and alpha = 0, sample()'s weight is 1 up to Mp's and Np's truncations.
//
// Differences from pbrt-v4, each more exact: Mp's normalisation in one formula for every
// v (log I0(a) - b - 1/v - log v - log(1 - e^{-2/v}), where pbrt switches at v = 0.1 and
// drops the last term), I0's series to 20 terms (pbrt: 10, 2% short at a = 12) and
// log I0's asymptotic expansion to 1/a^3 above a = 12 (pbrt: 1/(16a), 0.5% off there).
// Every function is from +, -, *, /, sqrt, floor and bit operations (lanes/lane_math.h), so
// every lane gives the scalar reference's bits.
//
// Not reciprocal per offset h (neither is the model: A_p and gamma_t depend on theta_o);
// averaged over h with alpha = 0 and |sin theta_i| = |sin theta_o| it is
// (tests/test_hair.cpp).
#pragma once
#include <algorithm>
#include <cmath>

#include "bsdf/bsdf.h"
#include "bsdf/conductor.h"
#include "bsdf/fresnel.h"
#include "lanes/lane_math.h"

namespace tuile {

// The per-material constants of the hair BSDF, derived once from beta_m, beta_n and alpha
// (degrees) in double precision: what the kernel gathers (MatParam's mp_hair_*).
struct HairConstants {
  float inv_v[3];     // 1 / v_p, p = 0, 1, 2 (v_1 = v_0 / 4, v_2 = 4 v_0; p = 3 uses v_2)
  float v[3];
  float log_norm[3];  // -1/v - log v - log(1 - e^{-2/v}): log of Mp's normalisation
  float exp_m2v[3];   // e^{-2/v} (Mp's sampling)
  float s;            // the logistic's scale
  float e_pi_s;       // e^{-pi/s}
  float sin2k[3], cos2k[3];  // sin and cos of 2^k alpha, k = 0, 1, 2
};
inline HairConstants hair_constants(float beta_m, float beta_n, float alpha_degrees) {
  HairConstants c{};
  // below 0.01 a lobe is narrower than float can normalise (1/v ~ 2e4 at 0.01; the
  // exponent of Mp cancels terms of that size): 0.01 stands for 0
  const double bm = std::max(static_cast<double>(beta_m), 0.01), bn = std::max(static_cast<double>(beta_n), 0.01);
  const double v0 = std::pow(0.726 * bm + 0.812 * bm * bm + 3.7 * std::pow(bm, 20), 2);
  const double vs[3] = {v0, 0.25 * v0, 4 * v0};
  for (int p = 0; p < 3; ++p) {
    const double v = vs[p];
    c.v[p] = static_cast<float>(v);
    c.inv_v[p] = static_cast<float>(1 / v);
    c.log_norm[p] = static_cast<float>(-1 / v - std::log(v) - std::log(-std::expm1(-2 / v)));
    c.exp_m2v[p] = static_cast<float>(std::exp(-2 / v));
  }
  const double s = 0.626657068657750125603 * (0.265 * bn + 1.194 * bn * bn + 5.372 * std::pow(bn, 22));
  c.s = static_cast<float>(s);
  c.e_pi_s = static_cast<float>(std::exp(-3.14159265358979323846 / s));
  double a = alpha_degrees * 3.14159265358979323846 / 180;
  for (int k = 0; k < 3; ++k, a *= 2) {
    c.sin2k[k] = static_cast<float>(std::sin(a));
    c.cos2k[k] = static_cast<float>(std::cos(a));
  }
  return c;
}

// sigma_a of pbrt-v4's "reflectance" (Chiang et al.'s fit: the colour after many
// scatterings), per channel, c in (0, 1].
inline float hair_sigma_a_from_reflectance(float c, float beta_n) {
  const double b = beta_n;
  const double d = 5.969 - 0.215 * b + 2.532 * b * b - 10.73 * b * b * b + 5.574 * b * b * b * b + 0.245 * std::pow(b, 5);
  const double l = std::log(std::max(static_cast<double>(c), 1e-6)) / d;
  return static_cast<float>(l * l);
}

// Where a ray towards the viewer wo met a fiber of axis t (unit) and radius r, centre c at
// the hit's curve parameter: h = the offset of the hit x from the axis along
// cross(wo, t) / |cross(wo, t)|, over r, clamped to [-1, 1] (0 where wo runs along the
// fiber). With z any normal of the fiber and the azimuth measured in hair_frame's y-z plane,
// this is sin(phi_o - phi_N) for a round fiber's normal N: the R lobe's centre
// phi_o - 2 asin(h) is then the mirror reflection of wo about N (tests/test_materials.cpp),
// and a flat or ribbon curve's hit is that of the round fiber it stands for.
inline float hair_offset(const vec3f& x, const vec3f& c, const vec3f& t, const vec3f& wo, float r) {
  const vec3f y = cross(wo, t);
  const float l = length(y);
  if (!(l > 1e-7f) || !(r > 0.f)) return 0.f;
  const float h = dot(x - c, y) / (l * r);
  return std::isfinite(h) ? std::clamp(h, -1.f, 1.f) : 0.f;
}

namespace hair_detail {

template <class T> inline T safe_sqrt(const T& x) noexcept { return sqrt(max(x, T(0.f))); }

// log I0(x), x >= 0: the series sum (x^2/4)^i / (i!)^2 to i = 20 up to x = 12, above it
// x - log(2 pi x) / 2 + log(1 + 1/(8x) + 9/(128x^2) + 225/(3072x^3)).
template <class T> inline T log_i0(const T& x) noexcept {
  const T xs = min(x, T(12.f));
  const T q = xs * xs * T(0.25f);
  T term(1.f), sum(1.f);
  for (int i = 1; i <= 20; ++i) {
    term = term * q * T(1.f / static_cast<float>(i * i));
    sum = sum + term;
  }
  const T xl = max(x, T(12.f));
  const T r = T(1.f) / xl;
  const T corr = mul_add(mul_add(mul_add(r, T(225.f / 3072.f), T(9.f / 128.f)), r, T(0.125f)), r, T(1.f));
  const T big = xl - T(0.5f) * lane_math::log_positive(T(6.28318530717958647692f) * xl) + lane_math::log_positive(corr);
  return sel(x > T(12.f), big, lane_math::log_positive(sum));
}

// Mp with the material's constants for v (inv_v, log_norm)
template <class T>
inline T mp(const T& cos_i, const T& cos_o, const T& sin_i, const T& sin_o, const T& inv_v, const T& log_norm) noexcept {
  const T a = cos_i * cos_o * inv_v;
  const T b = sin_i * sin_o * inv_v;
  return lane_math::exp_clamped(log_i0(a) - b + log_norm);
}

// x - 2 pi k in [-pi, pi)
template <class T> inline T wrap_pi(const T& x) noexcept {
  const T k = floor((x + T(pi_f)) * T(1.f / two_pi_f));
  return x - k * T(two_pi_f);
}

// The logistic of scale s trimmed to [-pi, pi] (e_pi_s = e^{-pi/s}).
template <class T> inline T trimmed_logistic(const T& x, const T& s, const T& e_pi_s) noexcept {
  const T e = lane_math::exp_nonpositive(T(0.f) - abs(x) / s);
  const T one_e = T(1.f) + e;
  const T norm = (T(1.f) - e_pi_s) / (T(1.f) + e_pi_s);  // CDF(pi) - CDF(-pi)
  return e / (s * one_e * one_e * norm);
}

// The inverse of trimmed_logistic's CDF at u in [0, 1).
template <class T> inline T sample_trimmed_logistic(const T& u, const T& s, const T& e_pi_s) noexcept {
  const T cdf_a = e_pi_s / (T(1.f) + e_pi_s);
  const T k = (T(1.f) - e_pi_s) / (T(1.f) + e_pi_s);
  const T c = max(mul_add(u, k, cdf_a), T(1e-30f));
  const T x = T(0.f) - s * lane_math::log_positive(T(1.f) / c - T(1.f));
  return min(max(x, T(-pi_f)), T(pi_f));
}

}  // namespace hair_detail

template <class T> struct HairBsdf {
  T h;                // [-1, 1]
  T eta;              // the fiber's index of refraction
  Rgb3<T> sigma_a;    // absorption, per unit of the fiber's radius
  T inv_v[3], log_norm[3], exp_m2v[3], v[3];  // HairConstants
  T s, e_pi_s;
  T sin2k[3], cos2k[3];

  // What eval and sample share for a given wo: the lobes' attenuations and their sampling
  // probabilities, the tilted theta_o per lobe, gamma_o, gamma_t and phi_o.
  struct OutTerms {
    T sin_o, cos_o, phi_o, gamma_o, gamma_t;
    Rgb3<T> ap[4];
    T ap_pdf[4];
    T sin_po[3], cos_po[3];
  };

  OutTerms out_terms(const Vec3<T>& wo) const noexcept {
    using namespace hair_detail;
    OutTerms o;
    o.sin_o = min(max(wo.x, T(-1.f)), T(1.f));
    o.cos_o = safe_sqrt(T(1.f) - o.sin_o * o.sin_o);
    o.phi_o = lane_math::atan2(wo.z, wo.y);
    const T hc = min(max(h, T(-1.f)), T(1.f));
    o.gamma_o = lane_math::asin(hc);
    // the refracted ray: theta_t, and gamma_t through the modified index eta'
    const T sin_t = o.sin_o / eta;
    const T cos_t = safe_sqrt(T(1.f) - sin_t * sin_t);
    const T etap = safe_sqrt(eta * eta - o.sin_o * o.sin_o) / max(o.cos_o, T(1e-8f));
    const T sin_gt = hc / etap;
    const T cos_gt = safe_sqrt(T(1.f) - sin_gt * sin_gt);
    o.gamma_t = lane_math::asin(sin_gt);
    // one passage through the interior: exp(-sigma_a 2 cos gamma_t / cos theta_t)
    const T len = T(2.f) * cos_gt / max(cos_t, T(1e-8f));
    const Rgb3<T> tr{lane_math::exp_nonpositive(T(0.f) - sigma_a.r * len), lane_math::exp_nonpositive(T(0.f) - sigma_a.g * len),
                     lane_math::exp_nonpositive(T(0.f) - sigma_a.b * len)};
    // A_p: Fresnel at the cuticle for the incidence cos theta_o cos gamma_o
    const T f = fresnel_dielectric(o.cos_o * safe_sqrt(T(1.f) - hc * hc), eta);
    const T t1 = (T(1.f) - f) * (T(1.f) - f);
    o.ap[0] = {f, f, f};
    o.ap[1] = {t1 * tr.r, t1 * tr.g, t1 * tr.b};
    o.ap[2] = {o.ap[1].r * tr.r * f, o.ap[1].g * tr.g * f, o.ap[1].b * tr.b * f};
    auto rest = [&](const T& a2, const T& t) {
      const T d = T(1.f) - t * f;
      return bsdf_detail::div_or0(d > T(0.f), a2 * f * t, d);
    };
    o.ap[3] = {rest(o.ap[2].r, tr.r), rest(o.ap[2].g, tr.g), rest(o.ap[2].b, tr.b)};
    T avg[4], sum(0.f);
    for (int p = 0; p < 4; ++p) {
      avg[p] = (o.ap[p].r + o.ap[p].g + o.ap[p].b) * T(1.f / 3.f);
      sum = sum + avg[p];
    }
    for (int p = 0; p < 4; ++p) o.ap_pdf[p] = bsdf_detail::div_or0(sum > T(0.f), avg[p], sum);
    // theta_o tilted by the scales: -2 alpha for R, +alpha for TT, +4 alpha for TRT
    o.sin_po[0] = o.sin_o * cos2k[1] - o.cos_o * sin2k[1];
    o.cos_po[0] = o.cos_o * cos2k[1] + o.sin_o * sin2k[1];
    o.sin_po[1] = o.sin_o * cos2k[0] + o.cos_o * sin2k[0];
    o.cos_po[1] = o.cos_o * cos2k[0] - o.sin_o * sin2k[0];
    o.sin_po[2] = o.sin_o * cos2k[2] + o.cos_o * sin2k[2];
    o.cos_po[2] = o.cos_o * cos2k[2] - o.sin_o * sin2k[2];
    for (int p = 0; p < 3; ++p) o.cos_po[p] = abs(o.cos_po[p]);
    return o;
  }

  // Where lobe p (0, 1, 2) leaves a smooth fiber, relative to phi_o: Phi(p) = 2 p gamma_t -
  // 2 gamma_o + p pi (p - 1 internal reflections, p + 1 refractions or reflections at the
  // cuticle; tests/test_materials.cpp traces them through a dielectric cylinder).
  static T exit_azimuth(const T& p, const OutTerms& o) noexcept {
    return T(2.f) * p * o.gamma_t - T(2.f) * o.gamma_o + p * T(pi_f);
  }

  // The lobes' sum f |wi.z| (per channel) and the sampling pdf at wi.
  void lobes(const OutTerms& o, const Vec3<T>& wi, Rgb3<T>& fsum, T& pdf) const noexcept {
    using namespace hair_detail;
    const T sin_i = min(max(wi.x, T(-1.f)), T(1.f));
    const T cos_i = safe_sqrt(T(1.f) - sin_i * sin_i);
    const T phi = lane_math::atan2(wi.z, wi.y) - o.phi_o;
    fsum = bsdf_detail::zero3<T>();
    pdf = T(0.f);
    for (int p = 0; p < 3; ++p) {
      const T m = mp(cos_i, o.cos_po[p], sin_i, o.sin_po[p], inv_v[p], log_norm[p]);
      const T mn = m * trimmed_logistic(wrap_pi(phi - exit_azimuth(T(static_cast<float>(p)), o)), s, e_pi_s);
      fsum = {mul_add(mn, o.ap[p].r, fsum.r), mul_add(mn, o.ap[p].g, fsum.g), mul_add(mn, o.ap[p].b, fsum.b)};
      pdf = mul_add(mn, o.ap_pdf[p], pdf);
    }
    const T m3 = mp(cos_i, o.cos_o, sin_i, o.sin_o, inv_v[2], log_norm[2]) * T(1.f / two_pi_f);
    fsum = {mul_add(m3, o.ap[3].r, fsum.r), mul_add(m3, o.ap[3].g, fsum.g), mul_add(m3, o.ap[3].b, fsum.b)};
    pdf = mul_add(m3, o.ap_pdf[3], pdf);
  }

  BsdfEval<T> eval(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept {
    const OutTerms o = out_terms(wo);
    Rgb3<T> fsum;
    T pdf;
    lobes(o, wi, fsum, pdf);
    const T c = abs(wi.z);
    const T inv_c = bsdf_detail::div_or0(c > T(0.f), T(1.f), c);
    const T k = sel(c > T(0.f), inv_c, T(1.f));
    return {bsdf_detail::scale(fsum, k), pdf};
  }
  T pdf(const Vec3<T>& wo, const Vec3<T>& wi) const noexcept { return eval(wo, wi).pdf; }

  BsdfSample<T> sample(const Vec3<T>& wo, const T& uc, const T& u1, const T& u2) const noexcept {
    using namespace hair_detail;
    const OutTerms o = out_terms(wo);
    // the lobe p by uc over the A_p probabilities, uc rescaled to [0, 1) within it
    T lo(0.f), width = o.ap_pdf[0];
    i32_t<T> p(0);
    T c1 = o.ap_pdf[0];
    for (int q = 1; q < 4; ++q) {
      const mask_t<T> beyond = uc >= c1 && o.ap_pdf[q] > T(0.f);
      p = sel(i_mask_from_f(beyond), i32_t<T>(q), p);
      lo = sel(beyond, c1, lo);
      width = sel(beyond, o.ap_pdf[q], width);
      c1 = c1 + o.ap_pdf[q];
    }
    const T ur = min(bsdf_detail::div_or0(width > T(0.f), uc - lo, width), T(0.99999994f));
    const auto is = [&](int q) { return f_mask_from_i(p == i32_t<T>(q)); };
    // the lobe's tilted theta_o and v (p = 3: untilted, v_2)
    T sin_po = o.sin_o, cos_po = o.cos_o, v_p = v[2], e2 = exp_m2v[2];
    for (int q = 0; q < 3; ++q) {
      sin_po = sel(is(q), o.sin_po[q], sin_po);
      cos_po = sel(is(q), o.cos_po[q], cos_po);
      v_p = sel(is(q), v[q], v_p);
      e2 = sel(is(q), exp_m2v[q], e2);
    }
    // theta_i by Mp (d'Eon's sampling), the cone's azimuth by u2
    const T cos_th = mul_add(v_p, lane_math::log_positive(mul_add(T(1.f) - u1, e2, max(u1, T(1e-5f)))), T(1.f));
    const T sin_th = safe_sqrt(T(1.f) - cos_th * cos_th);
    T sphi, cphi;
    lane_math::sincos_2pi(u2, sphi, cphi);
    const T sin_i = min(max(mul_add(sin_th * cphi, cos_po, T(0.f) - cos_th * sin_po), T(-1.f)), T(1.f));
    const T cos_i = safe_sqrt(T(1.f) - sin_i * sin_i);
    // the azimuth by Np around the lobe's exit angle (p = 3: uniform)
    const T pf = to_f32(p);
    const T dphi = sel(is(3), ur * T(two_pi_f), exit_azimuth(pf, o) + sample_trimmed_logistic(ur, s, e_pi_s));
    T sp, cp;
    lane_math::sincos(wrap_pi(o.phi_o + dphi), sp, cp);
    const Vec3<T> wi{sin_i, cos_i * cp, cos_i * sp};
    Rgb3<T> fsum;
    T pdf;
    lobes(o, wi, fsum, pdf);
    BsdfSample<T> r;
    r.delta = mask_t<T>(false);
    r.valid = pdf > T(0.f) && pdf < T(INFINITY);
    r.pdf = sel(r.valid, pdf, T(0.f));
    const T inv_pdf = bsdf_detail::div_or0(r.valid, T(1.f), pdf);
    r.weight = bsdf_detail::scale(fsum, inv_pdf);
    r.wi = sel(r.valid, wi, Vec3<T>(T(0.f), T(0.f), T(1.f)));
    return r;
  }
};

}  // namespace tuile
