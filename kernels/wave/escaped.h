// Stage 5b, escaped rays: a ray that meets nothing leaves the scene and sees the lights at
// infinity that have a density over directions (the sky: light kinds of the kind_sky
// group, light/kinds/infinite.h). pbrt-v4's EscapedRayWorkItem and HandleEscapedRays;
// Mitsuba 3's si.emitter(scene) on a miss.
//   - A camera ray that escapes adds the sky's radiance along it to its lane (seen
//     directly: no other technique finds it).
//   - A BSDF sample that escapes (any of a vertex's BSDF samples, the path's continuation
//     among them) adds beta Le w_bsdf / rate_bsdf to its shading point, with w_bsdf the BSDF
//     technique's MIS weight against the light technique's density of the same direction:
//     the pick's probability of that sky (from the point and its geometric normal, as
//     emitter hits give it) times the sky's own density of the direction
//     (pdf_sky_direction), so that a light sample of the sky and an escaped BSDF sample are
//     weighted by the same rule as a light sample of a surface and the BSDF ray that hit it.
//   - Resampled importance sampling: a BSDF candidate that reaches no emitter is a candidate
//     on the sky (ris_sky_lanes), its shadow ray going as far as a ray can.
// Several skies add (each its own entry of the light table, weighted on its own); pipelines
// whose scenes have no sky leave this stage out (Features::kinds without kind_sky), so they
// run exactly as before it existed.
// Reads: the camera or bounce packets (a miss: Embree's invalid geometry id), the shading
// points, the BSDF samples, the light table's sky entries. Writes: the lanes' seen
// emission, the shading points' radiance, the MIS-weight AOV's sums.
#pragma once
#include <bit>

#include "light/bvh.h"
#include "light/sample.h"
#include "wave/optimal_mis.h"
#include "wave/tile.h"

namespace tuile {

// The BSDF technique's weight for a sample that found a source (an emitter it hit, or the
// sky it escaped to), pdf_b its density and pdf_l the light technique's for the same
// direction: the heuristic under MIS, 0 where the light technique alone counts (light
// sampling; resampled importance sampling, whose candidates cover those directions), 1
// under BSDF sampling. (A delta lobe's sample counts with weight 1 whatever the strategy:
// the callers override it.)
template <class T>
inline T bsdf_technique_weight(const Estimator& est, float rate_light, float rate_bsdf, const T& pdf_b, const T& pdf_l) {
  if (est.strategy == Strategy::mis) return mis_weight(est.heuristic, T(rate_bsdf) * pdf_b, T(rate_light) * pdf_l, est.mis);
  if (est.strategy == Strategy::light || est.strategy == Strategy::ris) return T(0.f);
  return T(1.f);
}

// The probability that the light technique picks source sky from the point x (geometric
// normal n): the light BVH's pmf where sources are picked with it, the alias table's
// otherwise.
template <class T> inline T sky_pick_pmf(const LightView& L, const Vec3<T>& x, const Vec3<T>& n, int32_t sky) {
  const PickContext<T> ctx{x, n};
  if (L.bvh) return BvhPicker{*L.bvh}.template pmf<tier_gather>(ctx, sky);
  return AliasPicker{L}.template pmf<tier_gather>(ctx, sky);
}

// The radiance of sky entry i along the world direction d: its table radiance, times the
// texel of its environment map along d where it has one (light/kinds/infinite.h). With
// Pdf, returns also the density the sky's light samples give d (light/sample.h's
// pdf_sky_direction: not including the pick), from the same lookup of the texel.
template <class T, bool Pdf> inline T sky_lookup(const LightView& L, int32_t i, const Vec3<T>& d, T& r, T& g, T& b) {
  using Sky = LightKindOps<LightKind::infinite>;
  r = T(L.Lr[i]);
  g = T(L.Lg[i]);
  b = T(L.Lb[i]);
  const LightGeom<T> geo = broadcast_light<T>(L, i);
  if (L.sky_map_count == 0) {
    if constexpr (Pdf) return finite_or_zero(T(Sky::constant_pdf(geo.sky_dist)));
    return T(0.f);
  }
  const i32_t<T> texel = Sky::texel_along(geo, d);
  Sky::apply_texel(geo, texel, r, g, b);
  if constexpr (Pdf) return finite_or_zero(Sky::pdf_of_texel(geo, texel));
  return T(0.f);
}
template <class T> inline void sky_radiance(const LightView& L, int32_t i, const Vec3<T>& d, T& r, T& g, T& b) {
  sky_lookup<T, false>(L, i, d, r, g, b);
}
template <class T> inline T sky_radiance_pdf(const LightView& L, int32_t i, const Vec3<T>& d, T& r, T& g, T& b) {
  return sky_lookup<T, true>(L, i, d, r, g, b);
}

// Lanes [i, i + width) of the camera packets: those among the first `lanes` whose ray was
// traced and escaped add every sky's radiance along it.
template <class T> inline void escaped_camera_lanes(const LightView& L, TileBuffers& tb, int i, int lanes) {
  const RayHit16& p = tb.cam[i / packet_width];
  const int l = i % packet_width;
  const i32_t<T> index = i32_t<T>(i) + lane_iota_i32<T>();
  const i32_t<T> geom = load_i32<T>(reinterpret_cast<const int32_t*>(p.geomID + l));
  const auto miss = f_mask_from_i(geom < i32_t<T>(0) && index < i32_t<T>(lanes) &&
                                  load_i32<T>(tb.lanes.cam_valid + i) != i32_t<T>(0));  // invalid_id reads as -1
  if (!any(miss)) return;
  const Vec3<T> d = load3<T>(p.ray.dir_x + l, p.ray.dir_y + l, p.ray.dir_z + l);
  for (int s = 0; s < L.sky_count; ++s) {
    T r, g, b;
    sky_radiance<T>(L, L.sky_light[s], d, r, g, b);
    store(tb.lanes.Lr + i, load<T>(tb.lanes.Lr + i) + sel(miss, r, T(0.f)));
    store(tb.lanes.Lg + i, load<T>(tb.lanes.Lg + i) + sel(miss, g, T(0.f)));
    store(tb.lanes.Lb + i, load<T>(tb.lanes.Lb + i) + sel(miss, b, T(0.f)));
  }
}

// The camera rays of the tile's first `lanes` lanes that escaped. T = float: the scalar
// reference.
template <class T = vfloat> inline void escaped_camera(const LightView& L, TileBuffers& tb, int lanes) {
  if (L.sky_count == 0) return;
  const int padded = packet_padded(lanes);
  for (int i = 0; i < padded; i += lane_traits<T>::width) escaped_camera_lanes<T>(L, tb, i, lanes);
}

// Lanes [k, k + width) of the bounce packets (one per shading point): the traced rays that
// escaped add each sky's radiance, MIS-weighted, to their point. Delta: the samples may
// come from a specular lobe (weight 1, tb.tech.delta). chosen_only: one-sample MIS on
// paths (sample_bsdf's continuation): only the points that chose the BSDF technique count.
// Returns the lanes that escaped (bits), for the MIS-weight AOV.
template <class T, bool Delta = false>
inline uint32_t escaped_bounce_lanes(const LightView& L, const Estimator& est, float rate_light, float rate_bsdf, TileBuffers& tb,
                                     int k, bool chosen_only) {
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  // (a ray traced against the emitters alone whose occlusion ray to infinity was blocked:
  // tfar -inf, src/render/tile_run.h escape_rays)
  auto escaped = f_mask_from_i(load_i32<T>(tb.tech.valid + k) != i32_t<T>(0) &&
                               load_i32<T>(reinterpret_cast<const int32_t*>(r.geomID + l)) < i32_t<T>(0)) &&
                 load<T>(r.ray.tfar + l) > T(-INFINITY);
  if (chosen_only) escaped = escaped && load<T>(tb.points.choose_light + k) < T(0.5f);
  const uint32_t bits = lane_bits(escaped);
  if (!bits) return 0;
  const Vec3<T> x = load3<T>(tb.points.px + k, tb.points.py + k, tb.points.pz + k);
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  const Vec3<T> d = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
  const T pdf_b = load<T>(tb.tech.pdf + k);
  const T beta_r = load<T>(tb.tech.beta_r + k), beta_g = load<T>(tb.tech.beta_g + k), beta_b = load<T>(tb.tech.beta_b + k);
  T acc_r(0.f), acc_g(0.f), acc_b(0.f), wsum(0.f);
  T pdf_one_sky(0.f);  // the light technique's density of the direction where there is one sky (optimal MIS)
  for (int s = 0; s < L.sky_count; ++s) {
    const int32_t sky = L.sky_light[s];
    T Le_r, Le_g, Le_b;
    const T pdf_dir = sky_radiance_pdf<T>(L, sky, d, Le_r, Le_g, Le_b);
    const T pdf_l = sky_pick_pmf<T>(L, x, n, sky) * pdf_dir;
    if (L.sky_count == 1) pdf_one_sky = pdf_l;
    T w = bsdf_technique_weight<T>(est, rate_light, rate_bsdf, pdf_b, pdf_l);
    if constexpr (Delta) w = sel(f_mask_from_i(load_i32<T>(tb.tech.delta + k) != i32_t<T>(0)), T(1.f), w);
    const T factor = w / T(rate_bsdf);
    acc_r = acc_r + beta_r * Le_r * factor;
    acc_g = acc_g + beta_g * Le_g * factor;
    acc_b = acc_b + beta_b * Le_b * factor;
    wsum = wsum + w;
  }
  // the channels are >= 0 or NaN: their sum is finite iff each one is
  const auto fin = is_finite(acc_r + acc_g + acc_b);
  const auto add = escaped && fin;
  tb.stats.rejected_bsdf += static_cast<uint64_t>(std::popcount(lane_bits(escaped && !fin)));
  store(tb.radiance.r + k, load<T>(tb.radiance.r + k) + sel(add, acc_r, T(0.f)));
  store(tb.radiance.g + k, load<T>(tb.radiance.g + k) + sel(add, acc_g, T(0.f)));
  store(tb.radiance.b + k, load<T>(tb.radiance.b + k) + sel(add, acc_b, T(0.f)));
  if (est.aov_mis_weight) store(tb.tech.wb + k, wsum);
  if (optimal_mis(est)) {  // what the point's BSDF sample met, for optimal_bsdf_pass (one sky)
    // (the lanes whose sample met an emitter keep what weight_queue wrote)
    store_valid(tb.opt.hit + k, add || f_mask_from_i(load_i32<T>(tb.opt.hit + k) != i32_t<T>(0)));
    store(tb.opt.pl + k, sel(add, pdf_one_sky, load<T>(tb.opt.pl + k)));
    store(tb.opt.ur + k, sel(add, acc_r, load<T>(tb.opt.ur + k)));
    store(tb.opt.ug + k, sel(add, acc_g, load<T>(tb.opt.ug + k)));
    store(tb.opt.ub + k, sel(add, acc_b, load<T>(tb.opt.ub + k)));
    store(tb.opt.wb + k, sel(add, wsum, load<T>(tb.opt.wb + k)));
  }
  return lane_bits(add);
}

// The bounce rays of the shading points that escaped (after the trace against the whole
// scene). T = float: the scalar reference.
template <class T = vfloat, bool Delta = false>
inline void escaped_bounce(const LightView& L, const Estimator& est, float rate_light, float rate_bsdf, TileBuffers& tb,
                           bool chosen_only = false) {
  if (L.sky_count == 0) return;
  const int padded = packet_padded(tb.points.count);
  for (int k = 0; k < padded; k += lane_traits<T>::width) {
    const uint32_t added = escaped_bounce_lanes<T, Delta>(L, est, rate_light, rate_bsdf, tb, k, chosen_only);
    if (!est.aov_mis_weight) continue;
    for (uint32_t bits = added; bits; bits &= bits - 1) {  // one weight per sky, as emitter hits give one per hit
      const int j = k + std::countr_zero(bits);
      const int lane = tb.points.lane[j];
      tb.lanes.wsum[lane] += tb.tech.wb[j];
      tb.lanes.wcnt[lane] += static_cast<float>(L.sky_count);
    }
  }
}

}  // namespace tuile
