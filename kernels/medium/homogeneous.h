// The building blocks of volumetric path tracing in a homogeneous medium, lane-generic (T =
// float, the scalar reference, or a SIMD batch; every function from +, -, *, /, sqrt,
// floor and lanes/lane_math.h, so every lane gives the scalar reference's bits):
//   - the Henyey-Greenstein phase function, its sampling and pdf (pbrt-v4's conventions:
//     wo points away from the scattering point, towards where the light goes next, and
//     p(wo, wi) = HG(dot(wo, wi), g) with HG(c, g) = (1 - g^2) / (4 pi (1 + g^2 + 2 g c)^1.5),
//     so g > 0 scatters forward: wi near -wo);
//   - free-flight distances in a medium whose coefficients vary by colour channel, without
//     bias: the distance is drawn from one channel's exponential (the hero channel, chosen
//     per sample), and the sample is weighted by the one-sample MIS (balance heuristic) over
//     the three channels' densities: each channel's estimate is unbiased whatever the
//     others' coefficients (Miller, Georgiev & Jarosz 2019, in the homogeneous case where
//     delta tracking's majorant is the medium itself and null collisions never happen);
//   - transmittance, exp(-sigma_t d) per channel (ratio tracking in a homogeneous medium
//     is exact and deterministic: its majorant is sigma_t).
// Not yet wired into the renderer (issue 30's volumetric integrator will call these);
// tests/test_medium_kernels.cpp checks each against its density and against closed forms.
#pragma once
#include "bsdf/bsdf.h"
#include "lanes/lane_math.h"
#include "lanes/vec.h"

namespace tuile {

// Henyey-Greenstein's density at cos_theta = dot(wo, wi), per steradian.
template <class T> inline T hg_phase(const T& cos_theta, const T& g) noexcept {
  const T d = mul_add(T(2.f) * g, cos_theta, mul_add(g, g, T(1.f)));
  const T dc = max(d, T(1e-30f));
  return (T(1.f) - g * g) * T(inv_four_pi_f) / (dc * sqrt(dc));
}

template <class T> struct PhaseSample {
  Vec3<T> wi;
  T pdf;  // = hg_phase(dot(wo, wi), g); the phase function's weight p / pdf is 1
};

// Samples wi with density hg_phase(dot(wo, wi), g) (pbrt-v4's SampleHenyeyGreenstein: the
// inverted CDF of cos theta, uniform below |g| = 1e-3), wo unit.
template <class T> inline PhaseSample<T> sample_hg(const Vec3<T>& wo, const T& g, const T& u1, const T& u2) noexcept {
  const mask_t<T> iso = abs(g) < T(1e-3f);
  const T gs = sel(iso, T(0.5f), g);  // (any value where iso: its result is not used)
  const T sq = (T(1.f) - gs * gs) / mul_add(T(-2.f) * gs, u1, T(1.f) + gs);
  const T c_hg = (T(-0.5f) / gs) * (mul_add(gs, gs, T(1.f)) - sq * sq);
  const T c = min(max(sel(iso, mul_add(T(-2.f), u1, T(1.f)), c_hg), T(-1.f)), T(1.f));
  const T s = sqrt(max(T(1.f) - c * c, T(0.f)));
  T sp, cp;
  lane_math::sincos_2pi(u2, sp, cp);
  Vec3<T> t, b;
  make_basis(wo, t, b);
  PhaseSample<T> r;
  r.wi = t * (s * cp) + b * (s * sp) + wo * c;
  r.pdf = hg_phase(c, g);
  return r;
}

// A free flight from a point in a medium of extinction sigma_t (per channel, >= 0) towards
// a surface tmax away (tmax may be +inf). u_hero picks the hero channel (uniform over the
// three), u_dist the distance by its exponential. Either the flight stops at t < tmax (a
// real collision, scattered = true) or it passes the whole segment. weight multiplies the
// path's throughput per channel: for a collision sigma_t_c e^(-sigma_t_c t) / pdf(t) (the
// caller multiplies by the albedo sigma_s / sigma_t, or takes the absorbed share), for a
// pass e^(-sigma_t_c tmax) / P(pass), with pdf and P the mixture over the three channels
// (one-sample MIS, balance heuristic), so E[weight * g(event)] is each channel's own
// expectation for any g.
template <class T> struct FreeFlight {
  T t;                 // the collision's distance (tmax where passed)
  mask_t<T> scattered;
  Rgb3<T> weight;
};
template <class T>
inline FreeFlight<T> sample_free_flight(const Rgb3<T>& sigma_t, const T& tmax, const T& u_hero, const T& u_dist) noexcept {
  const T st_h = sel(u_hero < T(1.f / 3.f), sigma_t.r, sel(u_hero < T(2.f / 3.f), sigma_t.g, sigma_t.b));
  // t = -log(1 - u) / sigma_hero (infinite where the hero channel does not extinguish)
  const T one_minus = max(T(1.f) - u_dist, T(1e-30f));
  const mask_t<T> hero_on = st_h > T(0.f);
  const T t = sel(hero_on, T(0.f) - lane_math::log_positive(one_minus) / sel(hero_on, st_h, T(1.f)), T(INFINITY));
  FreeFlight<T> f;
  f.scattered = t < tmax;
  f.t = sel(f.scattered, t, tmax);
  // per channel: transmittance to f.t (0 * inf guarded: a channel of sigma_t 0 transmits 1)
  auto tr = [&](const T& st) { return sel(st > T(0.f), lane_math::exp_nonpositive(T(0.f) - st * f.t), T(1.f)); };
  const T tr_r = tr(sigma_t.r), tr_g = tr(sigma_t.g), tr_b = tr(sigma_t.b);
  // the mixture's density of the collision, or its probability of passing
  const T pdf = sel(f.scattered, (sigma_t.r * tr_r + sigma_t.g * tr_g + sigma_t.b * tr_b) * T(1.f / 3.f),
                    (tr_r + tr_g + tr_b) * T(1.f / 3.f));
  const mask_t<T> ok = pdf > T(0.f);
  const T inv = sel(ok, T(1.f) / sel(ok, pdf, T(1.f)), T(0.f));
  f.weight = {sel(f.scattered, sigma_t.r * tr_r, tr_r) * inv, sel(f.scattered, sigma_t.g * tr_g, tr_g) * inv,
              sel(f.scattered, sigma_t.b * tr_b, tr_b) * inv};
  return f;
}

// Transmittance along d in a homogeneous medium, per channel (d may be +inf: 0, or 1 where
// sigma_t is 0).
template <class T> inline Rgb3<T> transmittance(const Rgb3<T>& sigma_t, const T& d) noexcept {
  auto tr = [&](const T& st) { return sel(st > T(0.f), lane_math::exp_nonpositive(T(0.f) - st * d), T(1.f)); };
  return {tr(sigma_t.r), tr(sigma_t.g), tr(sigma_t.b)};
}

}  // namespace tuile
