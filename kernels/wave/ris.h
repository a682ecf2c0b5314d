// Resampled importance sampling of direct light (Talbot et al. 2005; Bitterli et al. 2020,
// sections 3-4), at every vertex of a path: per shading point, M candidates from the light
// technique (the picker, then a point on the source: the light samples' own code,
// sample_lights.h) and K from BSDF sampling (the direction's nearest emitter, found against
// the emitters alone, with no occlusion test), streamed through a one-entry reservoir; the
// kept candidate gets one shadow ray.
//
// Resampling weights: the balance heuristic over the two sources of candidates with the
// target p-hat = luminance of the unshadowed integrand f Le |cos| (solid-angle measure; a
// delta source's is f I cos / d^2 with its pick probability as its density):
//   w_j = m_t(x_j) p-hat(x_j) / p_t(x_j) = p-hat(x_j) / (M p_light(x_j) + K p_bsdf(x_j)),
// and the estimate f(y) V(y) Le / p-hat(y) * sum_j w_j for the kept y (chosen with
// probability w_y / sum w). Its expectation given the candidates is
// sum_j f(x_j) V(x_j) / (M p_light + K p_bsdf), the multi-sample balance-heuristic MIS
// estimate, so it is unbiased wherever f Le V > 0 implies p-hat > 0, which holds since
// luminance has positive weights. M = 1, K = 0 is light sampling itself (w = p-hat / p_light).
// A candidate's p_bsdf is the BSDF's density of its direction; that the BSDF technique
// would reach that point only if it is the nearest emitter along it is fine: where it is
// not, something lies in between and the candidate is occluded (f V = 0).
// Delta lobes are not candidates (f = 0 off the lobe); the path's BSDF sample still finds
// the lights they reflect (emitter_hits.h counts those hits with weight 1, and no others).
#pragma once
#include "wave/accumulate.h"
#include "wave/emitter_hits.h"
#include "wave/escaped.h"
#include "wave/sample_lights.h"

namespace tuile {

// Empty reservoirs for the tile's shading points.
inline void ris_clear(TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  RisReservoirs& r = tb.ris;
  std::fill_n(r.wsum, padded, 0.f);
  std::fill_n(r.cr, padded, 0.f);
  std::fill_n(r.cg, padded, 0.f);
  std::fill_n(r.cb, padded, 0.f);
  std::fill_n(r.ox, padded, 0.f);
  std::fill_n(r.oy, padded, 0.f);
  std::fill_n(r.oz, padded, 0.f);
  std::fill_n(r.dx, padded, 0.f);
  std::fill_n(r.dy, padded, 0.f);
  std::fill_n(r.dz, padded, 1.f);
  std::fill_n(r.tfar, padded, 1.f);
}

// Streams one candidate per lane into the reservoirs of points [k, k + width): the sum of
// weights grows by w, and the candidate replaces the kept one with probability w / sum
// (u: a uniform number of its own). c: the candidate's integrand f Le cos, per channel.
template <class T>
inline void ris_offer(TileBuffers& tb, int k, const mask_t<T>& ok, const T& w, const T& u, const T& target, const T& c_r,
                      const T& c_g, const T& c_b, const Vec3<T>& org, const Vec3<T>& dir, const T& tfar) {
  RisReservoirs& r = tb.ris;
  const T wsum = load<T>(r.wsum + k) + sel(ok, w, T(0.f));
  const auto take = ok && u * wsum < w;
  store(r.wsum + k, wsum);
  if (!any(take)) return;
  const T inv = T(1.f) / sel(take, target, T(1.f));
  store(r.cr + k, sel(take, c_r * inv, load<T>(r.cr + k)));
  store(r.cg + k, sel(take, c_g * inv, load<T>(r.cg + k)));
  store(r.cb + k, sel(take, c_b * inv, load<T>(r.cb + k)));
  store(r.ox + k, sel(take, org.x, load<T>(r.ox + k)));
  store(r.oy + k, sel(take, org.y, load<T>(r.oy + k)));
  store(r.oz + k, sel(take, org.z, load<T>(r.oz + k)));
  store(r.dx + k, sel(take, dir.x, load<T>(r.dx + k)));
  store(r.dy + k, sel(take, dir.y, load<T>(r.dy + k)));
  store(r.dz + k, sel(take, dir.z, load<T>(r.dz + k)));
  store(r.tfar + k, sel(take, tfar, load<T>(r.tfar + k)));
}

// A light candidate for points [k, k + width) (u0: pick, u1: resampling, u2 u3: point).
template <class T, unsigned Kinds = kind_all, bool Pick = true, unsigned Bsdfs = bsdf_diffuse>
TUILE_FLATTEN inline void ris_light_lanes(const GeomView& G, const LightView& L, const Estimator& est, const LightPass& pass,
                                          TileBuffers& tb, int k) {
  const auto active = (T(static_cast<float>(k)) + lane_iota<T>()) < T(static_cast<float>(tb.points.count));
  const LightCandidate<T> s = light_candidate_lanes<T, Kinds, Pick, Bsdfs>(G, L, est, pass, tb, k, active);
  const T pdf_l = sel(s.is_delta, s.pick, s.pick * s.pdf_sa);
  const T pdf_b = sel(s.is_delta, T(0.f), s.fe.pdf);
  const T a = s.cos_x * s.scale;
  const T c_r = s.fe.f.r * s.Le_r * a, c_g = s.fe.f.g * s.Le_g * a, c_b = s.fe.f.b * s.Le_b * a;
  const T target = luminance(c_r, c_g, c_b);
  const T denom = T(static_cast<float>(est.ris_light)) * pdf_l + T(static_cast<float>(est.ris_bsdf)) * pdf_b;
  auto ok = s.ok && s.ray_ok && pdf_l > T(0.f) && target > T(0.f) && is_finite(target);
  const T w = target / sel(ok, denom, T(1.f));
  const auto fin = is_finite(w);
  if (any(ok && !fin)) tb.stats.rejected_light += static_cast<uint64_t>(count(ok && !fin));
  ok = ok && fin;
  ris_offer(tb, k, ok, w, load<T>(tb.tech.u1 + k), target, c_r, c_g, c_b, s.org, s.dir, s.tfar);
}

// Offers the BSDF samples of lanes cand, each of which found a source (radiance Le, and
// pdf_l the light technique's density of the direction), to the reservoirs (u3:
// resampling, or u where given); the shadow ray goes from o along d and stops at tfar.
// Returns the weight offered (0 in the lanes that offered nothing).
template <class T>
inline T ris_offer_bsdf_lanes(const Estimator& est, TileBuffers& tb, int k, const mask_t<T>& cand, const T& pdf_l,
                              const T& Le_r, const T& Le_g, const T& Le_b, const Vec3<T>& o, const Vec3<T>& d,
                              const T& tfar, const T* u = nullptr) {
  const T pdf_b = load<T>(tb.tech.pdf + k);
  // f cos = throughput times pdf
  const T c_r = load<T>(tb.tech.beta_r + k) * pdf_b * Le_r;
  const T c_g = load<T>(tb.tech.beta_g + k) * pdf_b * Le_g;
  const T c_b = load<T>(tb.tech.beta_b + k) * pdf_b * Le_b;
  const T target = luminance(c_r, c_g, c_b);
  const T denom = T(static_cast<float>(est.ris_light)) * pdf_l + T(static_cast<float>(est.ris_bsdf)) * pdf_b;
  auto ok = cand && pdf_b > T(0.f) && target > T(0.f) && is_finite(target);
  const T w = target / sel(ok, denom, T(1.f));
  const auto fin = is_finite(w);
  if (any(ok && !fin)) tb.stats.rejected_bsdf += static_cast<uint64_t>(count(ok && !fin));
  ok = ok && fin;
  ris_offer(tb, k, ok, w, u ? *u : load<T>(tb.tech.u3 + k), target, c_r, c_g, c_b, o, d, tfar);
  return sel(ok, w, T(0.f));
}

// A BSDF candidate for points [k, k + width), after its ray was traced against the
// emitters (u3: resampling). T: at most a packet's width (the lanes read one packet's hits).
template <class T, unsigned Kinds = kind_all, unsigned Bsdfs = bsdf_diffuse>
TUILE_FLATTEN inline void ris_bsdf_lanes(const GeomView& G, const LightView& L, const Estimator& est, TileBuffers& tb, int k) {
  auto traced = f_mask_from_i(load_i32<T>(tb.tech.valid + k) != i32_t<T>(0));
  if constexpr ((Bsdfs & bsdf_delta_capable) != 0)  // a delta lobe's direction is not a candidate
    traced = traced && f_mask_from_i(load_i32<T>(tb.tech.delta + k) == i32_t<T>(0));
  const i32_t<T> light = bounce_hit_light<T>(G, tb, k, traced);
  const auto lit = f_mask_from_i(light >= i32_t<T>(0));
  if (!any(lit)) return;
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  const i32_t<T> li = max(light, i32_t<T>(0));
  const Vec3<T> o = load3<T>(r.ray.org_x + l, r.ray.org_y + l, r.ray.org_z + l);
  const Vec3<T> d = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
  const auto front = lit && light_front_lanes<T, (Kinds & kind_rects) == 0>(L, li, o, d);
  if (!any(front)) return;
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const T t = load<T>(r.ray.tfar + l);
  // distance from x itself (the ray started eps off it along n, on the side it leaves by)
  const T dist = t + load<T>(tb.points.eps + k) * abs(dot(n, d));
  T Le_r, Le_g, Le_b;
  const T pdf_l = light_pdf_of_hit<T, Kinds>(L, est, tb, to_i32(T(static_cast<float>(k)) + lane_iota<T>()), li, x, d, dist, Le_r, Le_g, Le_b);
  // the visibility ray: the bounce ray itself, stopping 2^-12 of the distance short of
  // the emitter as shadow rays do
  ris_offer_bsdf_lanes<T>(est, tb, k, front, pdf_l, Le_r, Le_g, Le_b, o, d, t * T(1.f - 1.f / 4096.f));
}

// A BSDF candidate for points [k, k + width) that reached no emitter (traced against the
// emitters alone) is a candidate on each sky, whose shadow ray decides
// whether anything of the scene lies in between. Each sky is a source of its own (a light
// candidate from one sky counts its radiance and its density alone), so the direction is
// offered once per sky; the offers after the first reuse the resampling number, rescaled
// to the part of [0, 1) the previous offer's choice left (uniform again given that choice).
template <class T, unsigned Bsdfs = bsdf_diffuse> inline void ris_sky_lanes(const LightView& L, const Estimator& est, TileBuffers& tb, int k) {
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  auto missed = f_mask_from_i(load_i32<T>(tb.tech.valid + k) != i32_t<T>(0) &&
                              load_i32<T>(reinterpret_cast<const int32_t*>(r.geomID + l)) < i32_t<T>(0));
  if constexpr ((Bsdfs & bsdf_delta_capable) != 0)  // a delta lobe's direction is not a candidate
    missed = missed && f_mask_from_i(load_i32<T>(tb.tech.delta + k) == i32_t<T>(0));
  if (!any(missed)) return;
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const Vec3<T> o = load3<T>(r.ray.org_x + l, r.ray.org_y + l, r.ray.org_z + l);
  const Vec3<T> d = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
  T u = load<T>(tb.tech.u3 + k);
  for (int s = 0; s < L.sky_count; ++s) {
    const int32_t sky = L.sky_light[s];
    const T pdf_l = sky_pick_pmf<T>(L, x, n, sky) * pdf_sky_direction<kind_sky>(broadcast_light<T>(L, sky), d);
    T Le_r, Le_g, Le_b;
    sky_radiance<T>(L, sky, d, Le_r, Le_g, Le_b);
    const T w = ris_offer_bsdf_lanes<T>(est, tb, k, missed, pdf_l, Le_r, Le_g, Le_b, o, d,
                                        T(LightKindOps<LightKind::distant>::infinite_distance), &u);
    if (s + 1 == L.sky_count) break;
    // the offer was taken where u < p = w / wsum: u / p or (u - p) / (1 - p) is uniform again
    const T wsum = load<T>(tb.ris.wsum + k);
    const T p = sel(wsum > T(0.f), w / sel(wsum > T(0.f), wsum, T(1.f)), T(0.f));
    const auto took = u < p;
    u = sel(took, u / sel(took, p, T(1.f)), (u - p) / sel(p < T(1.f), T(1.f) - p, T(1.f)));
    u = min(max(u, T(0.f)), T(0x1.fffffep-1f));
  }
}

// The kept candidates' shadow rays and contributions (f Le cos / p-hat times the sum of
// weights), for the shadow query and accumulate_shadow.
template <class T> inline void ris_finish_lanes(TileBuffers& tb, int k) {
  const RisReservoirs& r = tb.ris;
  const auto active = (T(static_cast<float>(k)) + lane_iota<T>()) < T(static_cast<float>(tb.points.count));
  const T wsum = load<T>(r.wsum + k);
  const T c_r = load<T>(r.cr + k) * wsum, c_g = load<T>(r.cg + k) * wsum, c_b = load<T>(r.cb + k) * wsum;
  const T c_sum = c_r + c_g + c_b;
  const auto fin = is_finite(c_sum);
  const auto kept = active && wsum > T(0.f) && c_sum > T(0.f);
  if (any(kept && !fin)) tb.stats.rejected_light += static_cast<uint64_t>(count(kept && !fin));
  const auto live = kept && fin;
  store(tb.tech.cr + k, sel(live, c_r, T(0.f)));
  store(tb.tech.cg + k, sel(live, c_g, T(0.f)));
  store(tb.tech.cb + k, sel(live, c_b, T(0.f)));
  store_rays(tb.shadow, k, load3<T>(r.ox + k, r.oy + k, r.oz + k), load3<T>(r.dx + k, r.dy + k, r.dz + k), load<T>(r.tfar + k));
  store_valid(tb.tech.valid + k, live);
}

// Light candidate j: its random numbers (SampleLayout's light_pick pair: the pick and the
// resampling number; light_point: the point) and its lanes.
template <unsigned Kinds = kind_all, bool Pick = true, unsigned Bsdfs = bsdf_diffuse>
inline void ris_light_candidates(const GeomView& G, const LightView& L, const Estimator& est, const LightPass& pass,
                                 uint32_t sample, uint32_t pick_pair, uint32_t point_pair, TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  point_pairs(est, tb, sample, pick_pair, padded, tb.tech.u0, tb.tech.u1);
  point_pairs(est, tb, sample, point_pair, padded, tb.tech.u2, tb.tech.u3);
  for_lane_batches<vfloat4>(0, padded, [&](auto lane, int k) {
    ris_light_lanes<typename decltype(lane)::type, Kinds, Pick, Bsdfs>(G, L, est, pass, tb, k);
  });
}

// BSDF candidate m, after sample_bsdf and the trace against the emitters: the resampling
// numbers (second dimension of SampleLayout's bsdf_lobe pair) and its lanes.
template <unsigned Kinds = kind_all, unsigned Bsdfs = bsdf_diffuse>
inline void ris_bsdf_candidates(const GeomView& G, const LightView& L, const Estimator& est, uint32_t sample,
                                uint32_t lobe_pair, TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  point_pairs(est, tb, sample, lobe_pair, padded, tb.tech.u2, tb.tech.u3);
  // one batch at a time: a batch reads the hits of one packet (as queue_emitter_lanes)
  for (int k = 0; k < padded; k += simd_width) ris_bsdf_lanes<vfloat, Kinds, Bsdfs>(G, L, est, tb, k);
  if constexpr ((Kinds & kind_sky) != 0)
    if (L.sky_count > 0)
      for (int k = 0; k < padded; k += simd_width) ris_sky_lanes<vfloat, Bsdfs>(L, est, tb, k);
}

template <class T = vfloat> inline void ris_finish(TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  for (int k = 0; k < padded; k += lane_traits<T>::width) ris_finish_lanes<T>(tb, k);
}

}  // namespace tuile
