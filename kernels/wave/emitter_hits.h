// Stage 5, emitter hits: the BSDF-sampled rays that reached the front of an emitter join
// a queue (with the sample's throughput beta = f cos / p and pdf p); each entry gets the
// BSDF technique's MIS weight and adds beta L_e w_bsdf / rate_bsdf to its shading point.
// The light technique's density for the same direction (pick probability times the point
// density in solid angle, under the same fallback rule as sampling) enters q_light. Also
// records w_bsdf for the mis_weight AOV. When bounce rays were traced against the emitters
// alone, the queue's visibility rays decide which entries count.
// Reads the bounce packets, the shading points, the BSDF samples, the light table; writes
// the shading points' radiance.
#pragma once
#include "light/bvh.h"
#include "wave/escaped.h"
#include "wave/optimal_mis.h"
#include "wave/surface_hits.h"

namespace tuile {

// The light technique's density for the direction wi from the shading point `point` (at x)
// reaching source idx at distance dist: the pick's probability (from the point's position
// and geometric normal where the picker reads them) times the point's density in solid
// angle, under the same fallback rule as sampling; and the source's radiance.
template <class T, unsigned Kinds = kind_all>
TUILE_FLATTEN inline T light_pdf_of_hit(const LightView& L, const Estimator& est, const TileBuffers& tb, const i32_t<T>& point,
                                        const i32_t<T>& idx, const Vec3<T>& x, const Vec3<T>& wi, const T& dist, T& Le_r,
                                        T& Le_g, T& Le_b) {
  // gathers, or permutes of small and medium tables (the same values)
  T pdf_point, pick;
  with_table_tier(L, [&](auto tier) {
    constexpr int S = decltype(tier)::value;
    if constexpr ((Kinds & kind_rects) != 0)
      pdf_point = pdf_light_point_sa<Kinds>(est.point, gather_rect_light<S>(L, idx), x, wi, dist);
    else pdf_point = pdf_light_point_sa<Kinds>(est.point, gather_light<S>(L, idx), x, wi, dist);
    if (L.bvh) {  // the pick's context: the shading point's position and geometric normal
      const Vec3<T> n{gather(tb.points.nx, point), gather(tb.points.ny, point), gather(tb.points.nz, point)};
      pick = BvhPicker{*L.bvh}.template pmf<S>(PickContext<T>{x, n}, idx);
    } else {
      pick = AliasPicker{L}.template pmf<S>(PickContext<T>{x, Vec3<T>(T(0.f), T(0.f), T(0.f))}, idx);
    }
    lookup_radiance<S>(L, idx, Le_r, Le_g, Le_b);
  });
  return pick * pdf_point;
}

// The source a traced bounce ray (lanes [k, k + width) of the bounce packets) reached:
// its light index, or -1 (no hit, not traced, or not an emitter).
template <class T>
inline i32_t<T> bounce_hit_light(const GeomView& G, const TileBuffers& tb, int k, const mask_t<T>& traced_in) {
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  const i32_t<T> geom = load_i32<T>(reinterpret_cast<const int32_t*>(r.geomID + l));
  const auto traced = i_mask_from_f(traced_in) && geom >= i32_t<T>(0);  // invalid_id reads as -1
  if (!any(f_mask_from_i(traced))) return i32_t<T>(-1);
  const i32_t<T> gi = max(geom, i32_t<T>(0));
  // the geometry table: a mesh's light per triangle, other kinds' per geometry
  const i32_t<T> kind = gather(G.geom_kind, gi);
  const auto mesh = traced && kind == i32_t<T>(static_cast<int32_t>(GeomKind::triangles));
  const auto other = traced && kind != i32_t<T>(static_cast<int32_t>(GeomKind::triangles));
  const i32_t<T> prim = load_i32<T>(reinterpret_cast<const int32_t*>(r.primID + l));
  i32_t<T> light = sel(mesh, gather(G.tri_light, sel(mesh, gather(G.geom_first, gi) + prim, i32_t<T>(0))), i32_t<T>(-1));
  if (any(f_mask_from_i(other))) light = sel(other, gather(G.geom_light, gi), light);
  return light;
}

// Lanes [j, j + width) of the hit queue.
// Kinds with kind_rects: every source is a rectangle (the same values without dispatch).
// Delta: entries may come from a specular lobe, which no light sample can produce: their
// weight is 1 whatever the strategy.
template <class T, unsigned Kinds = kind_all, bool Delta = false>
TUILE_FLATTEN inline void weight_lanes(const LightView& L, const Estimator& est, float rate_light, float rate_bsdf, TileBuffers& tb,
                         int j) {
  const auto live =
      (T(static_cast<float>(j)) + lane_iota<T>()) < T(static_cast<float>(tb.queue.count)) && load<T>(tb.queue.vis + j) > T(0.f);
  const i32_t<T> idx = load_i32<T>(tb.queue.light + j);
  const Vec3<T> x = load3<T>(tb.queue.x + j, tb.queue.y + j, tb.queue.z + j);
  const Vec3<T> wi = load3<T>(tb.queue.dx + j, tb.queue.dy + j, tb.queue.dz + j);
  const T dist = load<T>(tb.queue.dist + j);
  T Le_r, Le_g, Le_b;
  const T pdf_l = light_pdf_of_hit<T, Kinds>(L, est, tb, load_i32<T>(tb.queue.point + j), idx, x, wi, dist, Le_r, Le_g, Le_b);
  // (the general pipeline traces BSDF rays even when they must not count; resampled
  // importance sampling, ris.h, covers every direction but the delta lobes')
  T w = bsdf_technique_weight<T>(est, rate_light, rate_bsdf, load<T>(tb.queue.pdf + j), pdf_l);
  if constexpr (Delta) w = sel(f_mask_from_i(load_i32<T>(tb.queue.delta + j) != i32_t<T>(0)), T(1.f), w);
  const T factor = sel(live, w / T(rate_bsdf), T(0.f));
  store(tb.tech.cr + j, load<T>(tb.queue.beta_r + j) * Le_r * factor);
  store(tb.tech.cg + j, load<T>(tb.queue.beta_g + j) * Le_g * factor);
  store(tb.tech.cb + j, load<T>(tb.queue.beta_b + j) * Le_b * factor);
  store(tb.tech.wb + j, w);
  if (optimal_mis(est)) store(tb.tech.pl + j, pdf_l);  // wave/optimal_mis.h
}

// Lanes [k, k + width) of the bounce packets: the rays that hit the front of an emitter
// join the hit queue at nq, in lane order (compress stores; nq is advanced). vis: whether
// the queue keeps what the visibility rays need (bounce rays traced against the emitters):
// every entry's (ends null), or those of the lanes ends marks (a path's continuation
// sample, whose paths that end there were traced against the emitters alone).
// Kinds with kind_rects: no source is a sphere. Delta: keep the samples' delta flags.
// chosen_only: one-sample MIS on paths (sample_bsdf's continuation): only the points that
// chose the BSDF technique count their hits.
template <class T, unsigned Kinds = kind_all, bool Delta = false>
TUILE_FLATTEN inline void queue_emitter_lanes(const GeomView& G, const LightView& L, TileBuffers& tb, int k, int& nq, bool vis,
                                              bool chosen_only = false, const int32_t* ends = nullptr) {
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  auto traced = f_mask_from_i(load_i32<T>(tb.tech.valid + k) != i32_t<T>(0));
  if (chosen_only) traced = traced && load<T>(tb.points.choose_light + k) < T(0.5f);
  // (no hit: most rays, against the emitters only)
  const i32_t<T> light = bounce_hit_light<T>(G, tb, k, traced);
  const auto lit = f_mask_from_i(light >= i32_t<T>(0));
  if (!any(lit)) return;
  const i32_t<T> li = max(light, i32_t<T>(0));
  const Vec3<T> o = load3<T>(r.ray.org_x + l, r.ray.org_y + l, r.ray.org_z + l);
  const Vec3<T> d = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
  const uint32_t keep = lane_bits(lit && light_front_lanes<T, (Kinds & kind_rects) == 0>(L, li, o, d));
  if (!keep) return;
  const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
  compress_store(tb.queue.x + nq, load<T>(tb.points.px + k), keep);
  compress_store(tb.queue.y + nq, load<T>(tb.points.py + k), keep);
  compress_store(tb.queue.z + nq, load<T>(tb.points.pz + k), keep);
  compress_store(tb.queue.dx + nq, d.x, keep);
  compress_store(tb.queue.dy + nq, d.y, keep);
  compress_store(tb.queue.dz + nq, d.z, keep);
  // distance from x itself (the ray started eps off it along n, on the side it leaves by)
  compress_store(tb.queue.dist + nq, load<T>(r.ray.tfar + l) + load<T>(tb.points.eps + k) * abs(dot(n, d)), keep);
  if constexpr (Delta) compress_store(tb.queue.delta + nq, load_i32<T>(tb.tech.delta + k), keep);
  compress_store(tb.queue.beta_r + nq, load<T>(tb.tech.beta_r + k), keep);
  compress_store(tb.queue.beta_g + nq, load<T>(tb.tech.beta_g + k), keep);
  compress_store(tb.queue.beta_b + nq, load<T>(tb.tech.beta_b + k), keep);
  compress_store(tb.queue.pdf + nq, load<T>(tb.tech.pdf + k), keep);
  compress_store(tb.queue.light + nq, li, keep);
  compress_store(tb.queue.point + nq, i32_t<T>(k) + lane_iota_i32<T>(), keep);
  if (vis) {
    compress_store(tb.queue.ox + nq, o.x, keep);
    compress_store(tb.queue.oy + nq, o.y, keep);
    compress_store(tb.queue.oz + nq, o.z, keep);
    compress_store(tb.queue.t + nq, load<T>(r.ray.tfar + l), keep);
    compress_store(tb.queue.needs_vis + nq, ends ? load_i32<T>(ends + k) : i32_t<T>(-1), keep);
  }
  nq += std::popcount(keep);
}

// Queues the bounce rays that hit the front of an emitter (tb.queue.count entries, all
// visible until bounce_visibility says otherwise). T = float: the scalar reference. vis and
// ends as for queue_emitter_lanes.
template <class T = vfloat, unsigned Kinds = kind_all, bool Delta = false>
inline void queue_bounce_hits(const GeomView& G, const LightView& L, TileBuffers& tb, bool vis = true, bool chosen_only = false,
                              const int32_t* ends = nullptr) {
  int nq = 0;
  // padding lanes past points.count are never valid (sample_cosine)
  const int padded = packet_padded(tb.points.count);
  for (int k = 0; k < padded; k += lane_traits<T>::width)
    queue_emitter_lanes<T, Kinds, Delta>(G, L, tb, k, nq, vis, chosen_only, ends);
  tb.queue.count = nq;
  const int qpadded = packet_padded(nq);
  for (int j = nq; j < qpadded; ++j) {  // padding: a valid light index, no contribution
    tb.queue.x[j] = tb.queue.y[j] = tb.queue.z[j] = 0.f;
    tb.queue.dx[j] = tb.queue.dy[j] = 0.f;
    tb.queue.dz[j] = 1.f;
    tb.queue.dist[j] = 1.f;
    tb.queue.beta_r[j] = tb.queue.beta_g[j] = tb.queue.beta_b[j] = 0.f;
    tb.queue.pdf[j] = 1.f;
    tb.queue.delta[j] = 0;
    tb.queue.light[j] = nq > 0 ? tb.queue.light[0] : 0;
    tb.queue.point[j] = 0;
    tb.queue.ox[j] = tb.queue.oy[j] = tb.queue.oz[j] = 0.f;
    tb.queue.t[j] = 1.f;
    tb.queue.needs_vis[j] = 0;
  }
  std::fill_n(tb.queue.vis, qpadded, 1.f);
}

// When bounce rays were traced against the emitters only, the emitter a ray reached is
// what it sees only if nothing of the scene lies in between: the visibility rays of the
// queue (tb.shadow packets, tb.queue.valid), from the bounce ray's origin along its direction,
// stopping 2^-12 of the distance short of the emitter as shadow rays do, so that both
// techniques test visibility the same way; for the entries that need one (needs_vis: the
// others' rays found their nearest hit in the whole scene). Returns the number of packets
// (rays: the number of visibility rays).
inline int bounce_visibility_rays(TileBuffers& tb, int& rays) {
  const int qpadded = packet_padded(tb.queue.count);
  for (int j = 0; j < qpadded; j += simd_width) {
    store_field(tb.shadow, &Ray16::org_x, j, load<vfloat>(tb.queue.ox + j));
    store_field(tb.shadow, &Ray16::org_y, j, load<vfloat>(tb.queue.oy + j));
    store_field(tb.shadow, &Ray16::org_z, j, load<vfloat>(tb.queue.oz + j));
    store_field(tb.shadow, &Ray16::dir_x, j, load<vfloat>(tb.queue.dx + j));
    store_field(tb.shadow, &Ray16::dir_y, j, load<vfloat>(tb.queue.dy + j));
    store_field(tb.shadow, &Ray16::dir_z, j, load<vfloat>(tb.queue.dz + j));
    store_field(tb.shadow, &Ray16::tfar, j, load<vfloat>(tb.queue.t + j) * vfloat(1.f - 1.f / 4096.f));
    store_valid(tb.queue.valid + j, f_mask_from_i(load_i32<vfloat>(tb.queue.needs_vis + j) != vint(0)));
  }
  rays = 0;
  for (int j = 0; j < tb.queue.count; ++j) rays += tb.queue.needs_vis[j] != 0;
  return qpadded / packet_width;
}

// After the visibility query: occluded entries (Embree sets tfar = -inf) see nothing.
inline void read_bounce_visibility(TileBuffers& tb) {
  for (int j = 0; j < tb.queue.count; ++j)
    if (tb.queue.needs_vis[j]) tb.queue.vis[j] = tb.shadow[j / packet_width].tfar[j % packet_width] == -INFINITY ? 0.f : 1.f;
}

// --light-paths (Estimator::light_paths), at a path's vertex 2 or later: the queued hits of
// samples of a delta lobe on paths whose first vertex is of a kind the light tracer joins
// to the camera (light_traced_kind: diffuse, a medium; first_rough 1) are the light tracer's
// (src/render/light_paths.h: paths whose vertex next to the light is specular and whose
// vertex next to the camera is rough): they count as not visible. A light sample never
// makes such a path (a delta lobe has no value for it), so no MIS weight changes. Needs the
// queue's delta flags (pipelines with delta-capable surfaces). Where the light tracer also
// takes an area source's light at near-specular vertices (LightView::lt_glossy), the hits of
// the other samples from such a vertex are its too, and so are the light samples there
// (sample_lights.h): the path tracer has none of those paths, whatever their MIS weights.
template <bool Delta>
inline void drop_light_traced_hits(const GeomView& G, const LightView& L, TileBuffers& tb) {
  const bool glossy = L.lt_glossy != nullptr && G.mat_lt_glossy != nullptr;
  for (int j = 0; j < tb.queue.count; ++j) {
    const int32_t k = tb.queue.point[j];
    if (!(tb.path.first_rough[k] >= 1.f)) continue;  // (the area sources' split: rough first vertices alone)
    if (Delta && tb.queue.delta[j]) tb.queue.vis[j] = 0.f;
    else if (glossy && L.lt_glossy[tb.queue.light[j]] != 0 && G.mat_lt_glossy[tb.points.mat[k]] != 0) tb.queue.vis[j] = 0.f;
  }
}

// Weights the visible entries of the queue and adds them to their shading points.
template <unsigned Kinds = kind_all, bool Delta = false>
inline void weight_queue(const LightView& L, const Estimator& est, float rate_light, float rate_bsdf, TileBuffers& tb) {
  const int nq = tb.queue.count;
  if (nq == 0) return;
  const int qpadded = div_up(nq, simd_width) * simd_width;
  // two batches at a time (vfloat2) where whole: the solid-angle setup is a latency-bound
  // chain, and two independent ones keep the core busy
  for_lane_batches<vfloat2>(0, qpadded, [&](auto lane, int j) {
    weight_lanes<typename decltype(lane)::type, Kinds, Delta>(L, est, rate_light, rate_bsdf, tb, j);
  });
  if (!Delta && (est.strategy == Strategy::light || est.strategy == Strategy::ris)) return;
  const bool optimal = optimal_mis(est);
  for (int j = 0; j < nq; ++j) {
    if (!(tb.queue.vis[j] > 0.f)) continue;
    const float r = tb.tech.cr[j], g = tb.tech.cg[j], b = tb.tech.cb[j];
    if (!(std::isfinite(r) && std::isfinite(g) && std::isfinite(b))) {
      ++tb.stats.rejected_bsdf;
      continue;
    }
    const int k = tb.queue.point[j];
    tb.radiance.r[k] += r;
    tb.radiance.g[k] += g;
    tb.radiance.b[k] += b;
    if (optimal) {  // what the point's BSDF sample met, for optimal_bsdf_pass
      tb.opt.hit[k] = 1;
      tb.opt.pl[k] = tb.tech.pl[j];
      tb.opt.ur[k] = r;
      tb.opt.ug[k] = g;
      tb.opt.ub[k] = b;
      tb.opt.wb[k] = tb.tech.wb[j];
    }
    if (est.aov_mis_weight) {
      const int i = tb.points.lane[k];
      tb.lanes.wsum[i] += tb.tech.wb[j];
      tb.lanes.wcnt[i] += 1.f;
    }
  }
}

// Queues the bounce rays that hit the front of an emitter, weights them, adds them
// (bounce rays traced against the whole scene: every queued emitter is visible).
template <class T = vfloat, unsigned Kinds = kind_all, bool Delta = false>
inline void weight_bounce(const GeomView& G, const LightView& L, const Estimator& est, float rate_light, float rate_bsdf,
                          TileBuffers& tb) {
  queue_bounce_hits<T, Kinds, Delta>(G, L, tb);
  weight_queue<Kinds, Delta>(L, est, rate_light, rate_bsdf, tb);
}

}  // namespace tuile
