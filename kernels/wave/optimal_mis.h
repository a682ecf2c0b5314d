// Optimal MIS weights (Kondapaneni, Vévoda, Grittmann, Skřivan, Slusallek, Křivánek 2019,
// "Optimal Multiple Importance Sampling"), for the two techniques of the first vertex
// (--heuristic optimal; later vertices of a path take the power heuristic).
//
// The estimator of one pixel sample, with n_L light and n_B BSDF samples (multi-sample;
// one-sample: n_i = c_i, the choice probabilities, and one sample of the chosen technique):
//   F = alpha_L + alpha_B + sum_s (f(x_s) - alpha_L p_L(x_s) - alpha_B p_B(x_s)) / (n_L p_L(x_s) + n_B p_B(x_s)),
// unbiased for any alpha fixed before the samples are drawn (sum_s p_k / sum n p has
// expectation int p_k = 1: a control variate), equal to the balance heuristic at alpha = 0
// and to it for any alpha where p_L = p_B. The variance is least at A alpha = b with
//   A_ik = int p_i p_k / sum n p,  b_i = int f p_i / sum n p,
// which each sample estimates as r_i r_k and u r_i with r_i = p_i / sum n p, u = f / sum n p
// (u is what the balance heuristic adds). Per pixel and per RGB channel (A is common to the
// channels, b is per channel), tuile sums these moments over the pixel's samples in double
// and solves the 2x2 system before each sample from the samples before it (progressive:
// the alpha a sample uses depends only on earlier samples, so with independent samples the
// estimate stays unbiased; the first optimal_warmup samples of a pixel use alpha = 0, the
// balance heuristic). The moments live in the film (Film::optimal), so passes, progressive
// renders, checkpoints and resumes continue them.
//
// The domain is the points the techniques generate, not directions: a light sample is a
// point on a source (a delta source's sample is a point of its own), a BSDF sample is the
// first thing its ray meets (a surface, an emitter's front, the sky) or a specular
// direction. So a light sample whose shadow ray is blocked, or that failed (the source
// faces away, the direction is under the surface, a zero density), has p_B = 0: its term is
// -alpha_L / n_L with r = (1 / n_L, 0); a BSDF sample that meets no emitter, or a specular
// one, has p_L = 0 likewise. Failures and occluded samples therefore count in A (r_i r_i =
// 1 / n_i^2) and add -alpha_i / n_i, and every sample of technique i also carries its share
// alpha_i / n_i of the constant (multi-sample; one-sample: the chosen sample carries
// alpha_L + alpha_B), so that a failed sample adds exactly 0 under multi-sample MIS.
// With --light-pick all every source is sampled n_L times: the light technique's
// densities add up over the sources and each sample still carries alpha_L / n_L.
// The hooks run once per pass over all shading points, out of line (TUILE_OUT_OF_LINE): one
// copy per translation unit instead of one inlined into each of the tile pipelines.
#pragma once
#include <algorithm>
#include <cmath>

#include "wave/tile.h"

namespace tuile {

inline bool optimal_mis(const Estimator& e) noexcept {
  return e.strategy == Strategy::mis && e.heuristic == Heuristic::optimal;
}

// The samples of a pixel that use alpha = 0 (the balance heuristic) before its moments
// are used: with fewer, the 2x2 system is fit to one or two points and alpha is noise.
inline constexpr uint32_t optimal_warmup = 4;

// Solves A alpha = b for the three channels from a pixel's moments m (OptimalMoment order).
// A is symmetric and positive semi-definite: by Cramer's rule, or by the pseudo-inverse where the smaller eigenvalue is below 1e-9 of the larger (the techniques'
// densities proportional over the samples: the system is singular, and every solution
// gives the same estimate to rounding; the pseudo-inverse takes the smallest alpha), and
// alpha = 0 (the balance heuristic) where A is zero or not finite or a result is not finite.
// In double; the alphas are rounded to float once.
inline void solve_optimal_alpha(const double* m, float* alpha_l, float* alpha_b) noexcept {
  const double a = m[opt_a_ll], h = m[opt_a_lb], c = m[opt_a_bb];
  for (int ch = 0; ch < 3; ++ch) alpha_l[ch] = alpha_b[ch] = 0.f;
  if (!(std::isfinite(a) && std::isfinite(h) && std::isfinite(c)) || !(a + c > 0.0)) return;
  // eigenvalues of [[a, h], [h, c]]: mean +- radius; the smaller one as det / l1 (no
  // cancellation); the eigenvector of l1 is (h, l1 - a), or an axis where h = 0
  const double mean = 0.5 * (a + c), half = 0.5 * (a - c);
  const double radius = std::sqrt(half * half + h * h);
  const double l1 = mean + radius;
  const double l2 = std::max(0.0, (a * c - h * h) / l1);
  const bool full_rank = l2 > 1e-9 * l1;
  double v1x = a >= c ? 1.0 : 0.0, v1y = a >= c ? 0.0 : 1.0;
  if (!full_rank && h != 0.0) {
    const double d = half >= 0.0 ? h * h / (radius + half) : radius - half;  // l1 - a, without cancellation
    const double len = std::sqrt(h * h + d * d);
    v1x = h / len;
    v1y = d / len;
  }
  const double inv_det = 1.0 / (a * c - h * h);
  for (int ch = 0; ch < 3; ++ch) {
    const double bl = m[opt_b_l + ch], bb = m[opt_b_b + ch];
    double xl, xb;
    if (full_rank) {  // Cramer's rule: an error of about cond(A) 2^-53
      xl = (c * bl - h * bb) * inv_det;
      xb = (a * bb - h * bl) * inv_det;
    } else {  // the pseudo-inverse: along the larger eigenvector only
      const double p1 = (v1x * bl + v1y * bb) / l1;
      xl = p1 * v1x;
      xb = p1 * v1y;
    }
    if (std::isfinite(xl) && std::isfinite(xb)) {
      alpha_l[ch] = static_cast<float>(xl);
      alpha_b[ch] = static_cast<float>(xb);
    }
  }
}

// Before a sample: each tile lane's alphas from its pixel's moments so far (the film's,
// loaded at tile start, plus this render's), or zero during the warm-up. `samples_before`:
// the pixel's samples before this one. The alphas are solved again at the render's first
// sample of the tile (`first`) and whenever a pixel's sample count reaches a power of two,
// and kept between: each solve still uses earlier samples only, and solving at every sample
// cost about a third of the estimator's overhead without a measurable gain.
TUILE_OUT_OF_LINE inline void optimal_alphas(TileBuffers& tb, int lanes, uint64_t samples_before, bool first) noexcept {
  OptimalState& o = tb.opt;
  const bool solve = first || (samples_before & (samples_before - 1)) == 0;
  if (!solve && samples_before > optimal_warmup) return;
  for (int i = 0; i < lanes; ++i) {
    float al[3], ab[3];
    if (samples_before < optimal_warmup) {
      al[0] = al[1] = al[2] = ab[0] = ab[1] = ab[2] = 0.f;
    } else {
      double m[opt_moments];
      for (int j = 0; j < opt_moments; ++j) m[j] = o.prior[j][i] + o.sum[j][i];
      solve_optimal_alpha(m, al, ab);
    }
    for (int ch = 0; ch < 3; ++ch) {
      o.alpha_l[ch][i] = al[ch];
      o.alpha_b[ch][i] = ab[ch];
    }
  }
}

// One technique sample of shading point k, whose lane is i: its u (what the balance
// heuristic added to the point's radiance, per channel) and r = (r_L, r_B). Adds the
// control variate and the constant share to the point's radiance, the moments to the
// lane's sums, and returns the sample's effective MIS weight relative to its balance one
// (for the mis_weight AOV: luminance of (u - alpha.r + share) over luminance of u; 1 where
// u is 0).
inline float optimal_add(TileBuffers& tb, int k, const float* u, float rl, float rb, float share_l, float share_b) noexcept {
  OptimalState& o = tb.opt;
  const int i = tb.points.lane[k];
  float* rad[3] = {tb.radiance.r, tb.radiance.g, tb.radiance.b};
  float out[3];
  for (int ch = 0; ch < 3; ++ch) {
    const float al = o.alpha_l[ch][i], ab = o.alpha_b[ch][i];
    out[ch] = u[ch] - (al * rl + ab * rb) + (al * share_l + ab * share_b);
    rad[ch][k] += out[ch] - u[ch];
  }
  const double dl = rl, db = rb;
  o.sum[opt_a_ll][i] += dl * dl;
  o.sum[opt_a_lb][i] += dl * db;
  o.sum[opt_a_bb][i] += db * db;
  for (int ch = 0; ch < 3; ++ch) {
    o.sum[opt_b_l + ch][i] += static_cast<double>(u[ch]) * dl;
    o.sum[opt_b_b + ch][i] += static_cast<double>(u[ch]) * db;
  }
  const float yu = 0.2126f * u[0] + 0.7152f * u[1] + 0.0722f * u[2];
  const float yo = 0.2126f * out[0] + 0.7152f * out[1] + 0.0722f * out[2];
  return yu != 0.f ? yo / yu : 1.f;
}

// The constant's share each technique's sample carries: alpha_i / n_i (multi-sample), or,
// under one-sample MIS, alpha_L + alpha_B on the one sample (share_l = share_b = 1).
struct OptimalShares {
  float l, b;  // the factors of alpha_L and alpha_B
};
inline OptimalShares optimal_shares(const Estimator& e, float rate_light, float rate_bsdf, bool light_sample) noexcept {
  if (e.one_sample()) return {1.f, 1.f};
  return light_sample ? OptimalShares{1.f / rate_light, 0.f} : OptimalShares{0.f, 1.f / rate_bsdf};
}

// After a light pass's shadow rays (accumulate_shadow): every shading point that took a
// light sample. Lit samples (traced and unoccluded) read their densities from the light
// stage (tech.pl, tech.pb; a delta source's pb is 0); the rest are points of the light
// technique alone (u = 0, r = (1 / n_L, 0)).
TUILE_OUT_OF_LINE inline void optimal_light_pass(TileBuffers& tb, const Estimator& e, float rate_light, float rate_bsdf) noexcept {
  const OptimalShares sh = optimal_shares(e, rate_light, rate_bsdf, true);
  for (int k = 0; k < tb.points.count; ++k) {
    if (e.one_sample() && !(tb.points.choose_light[k] > 0.5f)) continue;
    const bool lit = tb.tech.valid[k] != 0 && tb.shadow[k / packet_width].tfar[k % packet_width] != -INFINITY;
    float u[3] = {0.f, 0.f, 0.f};
    float rl = 1.f / rate_light, rb = 0.f;
    if (lit) {
      u[0] = tb.tech.cr[k];
      u[1] = tb.tech.cg[k];
      u[2] = tb.tech.cb[k];
      const float pl = tb.tech.pl[k], pb = tb.tech.pb[k];
      const float q = rate_light * pl + rate_bsdf * pb;
      if (q > 0.f && std::isfinite(q)) {
        rl = pl / q;
        rb = pb / q;
      }
    }
    optimal_add(tb, k, u, rl, rb, sh.l, sh.b);
  }
}

// Before a BSDF pass's emitter hits are weighted: no point has met an emitter yet.
TUILE_OUT_OF_LINE inline void optimal_bsdf_clear(TileBuffers& tb) noexcept { std::fill_n(tb.opt.hit, packet_padded(tb.points.count), 0); }

// After a BSDF pass's emitter hits and escaped rays (weight_queue, escaped_bounce, which
// set opt.hit, opt.pl and opt.u of the points whose sample met an emitter or the sky):
// every shading point that took a BSDF sample. A specular sample (tech.delta) or one that
// met nothing that emits is a point of the BSDF technique alone.
TUILE_OUT_OF_LINE inline void optimal_bsdf_pass(TileBuffers& tb, const Estimator& e, float rate_light, float rate_bsdf, bool delta_capable,
                              bool aov) noexcept {
  const OptimalShares sh = optimal_shares(e, rate_light, rate_bsdf, false);
  for (int k = 0; k < tb.points.count; ++k) {
    if (e.one_sample() && tb.points.choose_light[k] > 0.5f) continue;
    float u[3] = {0.f, 0.f, 0.f};
    float rl = 0.f, rb = 1.f / rate_bsdf;
    const bool hit = tb.opt.hit[k] != 0;
    if (hit) {
      u[0] = tb.opt.ur[k];
      u[1] = tb.opt.ug[k];
      u[2] = tb.opt.ub[k];
      const bool delta = delta_capable && tb.tech.delta[k] != 0;
      const float pl = tb.opt.pl[k], pb = tb.tech.pdf[k];
      const float q = rate_light * pl + rate_bsdf * pb;
      if (!delta && q > 0.f && std::isfinite(q)) {
        rl = pl / q;
        rb = pb / q;
      }
    }
    const float w = optimal_add(tb, k, u, rl, rb, sh.l, sh.b);
    // the mis_weight AOV: the hit's balance weight (added by the stage) times the
    // control variate's change of it
    if (aov && hit) tb.lanes.wsum[tb.points.lane[k]] += tb.opt.wb[k] * (w - 1.f);
  }
}

// At tile start: the moments of the tile's pixels before this render (`prior`: the film the
// earlier samples are in, 9 per pixel; null: none) and this render's sums at zero.
TUILE_OUT_OF_LINE inline void optimal_tile_start(TileBuffers& tb, int lanes, const double* prior) noexcept {
  OptimalState& o = tb.opt;
  const int padded = packet_padded(lanes);
  for (int j = 0; j < opt_moments; ++j) {
    std::fill_n(o.sum[j], padded, 0.0);
    for (int i = 0; i < lanes; ++i) o.prior[j][i] = prior ? prior[static_cast<size_t>(opt_moments) * tb.lanes.pixel[i] + j] : 0.0;
  }
}

// At tile end: this render's moments into the film (9 per pixel).
TUILE_OUT_OF_LINE inline void optimal_tile_end(const TileBuffers& tb, int lanes, double* film) noexcept {
  for (int i = 0; i < lanes; ++i)
    for (int j = 0; j < opt_moments; ++j) film[static_cast<size_t>(opt_moments) * tb.lanes.pixel[i] + j] += tb.opt.sum[j][i];
}

}  // namespace tuile
