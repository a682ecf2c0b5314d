// Paths (Estimator::max_depth > 1): what the wavefront adds to direct lighting between two
// vertices. After a vertex's light and BSDF samples (whose radiance its shading points
// hold in TileBuffers::radiance), add_vertex_radiance adds throughput x that radiance into
// each path's pixel lane; then
// continue_paths multiplies each path's throughput by its BSDF sample's f cos / p, plays
// Russian roulette (pbrt-v4's PathIntegrator rule) and clears the bounce rays of the
// paths that end, so that bounce_hits (wave/surface_hits.h) turns the others' hits into
// the next vertex's shading points, compacted.
// Reads and writes the paths' throughput and eta scale (TileBuffers::path), the BSDF samples'
// validity; reads the bounce packets (the sampled directions).
#pragma once
#include <algorithm>

#include "wave/tile.h"

namespace tuile {

// Starts every path at the camera hits: throughput 1, eta scale 1.
inline void start_paths(TileBuffers& tb) {
  const int padded = packet_padded(tb.points.count);
  std::fill_n(tb.path.throughput_r, padded, 1.f);
  std::fill_n(tb.path.throughput_g, padded, 1.f);
  std::fill_n(tb.path.throughput_b, padded, 1.f);
  std::fill_n(tb.path.eta_scale, padded, 1.f);
  std::fill_n(tb.path.rough, padded, 0.f);
  std::fill_n(tb.path.first_rough, padded, 0.f);
}

// The radiance the vertex's techniques found (TileBuffers::radiance), times the path's
// throughput, into its pixel's lane (each lane has at most one shading point per vertex).
// first: the camera's vertex, whose throughput is 1: L plus that radiance exactly.
inline void add_vertex_radiance(TileBuffers& tb, bool first) {
  const int n = tb.points.count;
  const ShadingPoints& P = tb.points;
  const PointRadiance& R = tb.radiance;
  const PathStates& S = tb.path;
  PixelLanes& La = tb.lanes;
  if (first) {
    for (int k = 0; k < n; ++k) {
      const int i = P.lane[k];
      La.Lr[i] += R.r[k];
      La.Lg[i] += R.g[k];
      La.Lb[i] += R.b[k];
    }
    return;
  }
  for (int k = 0; k < n; ++k) {
    const int i = P.lane[k];
    La.Lr[i] += S.throughput_r[k] * R.r[k];
    La.Lg[i] += S.throughput_g[k] * R.g[k];
    La.Lb[i] += S.throughput_b[k] * R.b[k];
  }
}

// Shading points [k, k + width): the throughput after the BSDF sample, and Russian
// roulette. Once the path has `rr_after` vertices or more (its depth > 1 by default), a
// path whose throughput times eta scale has a largest channel m below the threshold t
// (Estimator::rr_threshold; inv_t = 1 / t) ends with probability q = 1 - m / t and goes on
// with throughput / (1 - q); t = 1 is pbrt-v4's rule. u: one uniform number per point.
// The eta scale gathers etap^2 of every transmission through a dielectric (pbrt-v4:
// the 1 / etap^2 of radiance's transport must not decide whether a path lives). Paths
// whose throughput is 0 (a BSDF sample of no weight) or not finite end here (the latter
// counted as rejected); they would add nothing, or only NaN. Materials: the point's
// surface may transmit (else every sample reflects, eta scale stays). path_step_lanes
// computes the step (mark_path_ends reads its outcome before the trace), continue_path_lanes
// stores it.
template <class T> struct PathStep {
  T br, bg, bb, eta_scale;  // the throughput after the sample (and the roulette), the eta scale
  mask_t<T> live, finite, go;
};
template <class T, bool Materials>
TUILE_FLATTEN inline PathStep<T> path_step_lanes(const GeomView& G, const TileBuffers& tb, int k, bool roulette, float inv_t) {
  PathStep<T> p;
  p.live = f_mask_from_i(load_i32<T>(tb.tech.valid + k) != i32_t<T>(0));
  p.br = load<T>(tb.path.throughput_r + k) * load<T>(tb.tech.beta_r + k);
  p.bg = load<T>(tb.path.throughput_g + k) * load<T>(tb.tech.beta_g + k);
  p.bb = load<T>(tb.path.throughput_b + k) * load<T>(tb.tech.beta_b + k);
  p.eta_scale = load<T>(tb.path.eta_scale + k);
  if constexpr (Materials) {
    const RayHit16& r = tb.bounce[k / packet_width];
    const int l = k % packet_width;
    const Vec3<T> wi = load3<T>(r.ray.dir_x + l, r.ray.dir_y + l, r.ray.dir_z + l);
    const Vec3<T> n = load3<T>(tb.points.nx + k, tb.points.ny + k, tb.points.nz + k);
    const i32_t<T> mat = load_i32<T>(tb.points.mat + k);
    const i32_t<T> kind = gather(G.mat_kind, mat);
    const auto dielectric = f_mask_from_i(kind == i32_t<T>(static_cast<int32_t>(MaterialKind::dielectric)));
    const auto through = p.live && dielectric && dot(wi, n) < T(0.f);  // n faces the viewer
    if (any(through)) {
      const T eta = gather(G.mat_param[mp_eta], mat);
      const T etap = sel(load<T>(tb.points.side + k) > T(0.f), eta, T(1.f) / eta);
      p.eta_scale = sel(through, p.eta_scale * etap * etap, p.eta_scale);
    }
  }
  p.finite = is_finite(p.br) && is_finite(p.bg) && is_finite(p.bb);
  const T m = max(max(p.br, p.bg), p.bb);
  p.go = p.live && p.finite && m > T(0.f);
  if (roulette) {
    const T rr = m * p.eta_scale * T(inv_t);
    const auto play = rr < T(1.f);
    const T q = max(T(0.f), T(1.f) - rr);
    p.go = p.go && (!play || load<T>(tb.tech.u3 + k) >= q);
    const T scale = sel(play, T(1.f) / (T(1.f) - q), T(1.f));
    p.br = p.br * scale;
    p.bg = p.bg * scale;
    p.bb = p.bb * scale;
  }
  return p;
}
template <class T, bool Materials>
TUILE_FLATTEN inline void continue_path_lanes(const GeomView& G, TileBuffers& tb, int k, bool roulette, float inv_t) {
  const PathStep<T> p = path_step_lanes<T, Materials>(G, tb, k, roulette, inv_t);
  tb.stats.rejected_bsdf += static_cast<uint64_t>(std::popcount(lane_bits(p.live && !p.finite)));
  // an ended path keeps throughput 0 (never read again; and the same bits in every lane
  // whatever a NaN did to max above)
  store(tb.path.throughput_r + k, sel(p.go, p.br, T(0.f)));
  store(tb.path.throughput_g + k, sel(p.go, p.bg, T(0.f)));
  store(tb.path.throughput_b + k, sel(p.go, p.bb, T(0.f)));
  store(tb.path.eta_scale + k, p.eta_scale);
  // (a diffuse pipeline's samples are never specular; its paths are never regularized)
  const auto specular = f_mask_from_i(load_i32<T>(tb.tech.delta + k) != i32_t<T>(0));
  store(tb.path.rough + k, sel(specular, load<T>(tb.path.rough + k), T(1.f)));
  store_valid(tb.tech.valid + k, p.go);
}

// The materials a distant source's light paths join to the camera (src/render/light_paths.h):
// the rough kinds (light_traced_kind) and coated diffuse whose coat has constant alphas of
// coat_join_alpha or more. There the path tracer's sample from the coat must find the glint
// a near-specular surface throws, a highlight narrower than the coat's own lobe, by chance:
// dining-room's chairs (coats of 0.1) in the glints off its cups and chrome, relMSE 2.2
// times lower with them joined. A sharper coat's peak (1 / (pi alpha^2)) makes the joins'
// fireflies instead: classroom's coats of 0.05, relMSE 13 and 30 times higher on two seeds
// of five (bench/results.md, "Coated first vertices").
inline constexpr float coat_join_alpha = 0.075f;
inline bool sun_traced_material(const GeomView& G, int32_t m) noexcept {
  const int32_t kind = G.mat_kind[m];
  if (light_traced_kind(kind)) return true;
  if (kind != static_cast<int32_t>(MaterialKind::coated_diffuse)) return false;
  if (G.mat_alpha_tex != nullptr && (G.mat_alpha_tex[2 * m] >= 0 || G.mat_alpha_tex[2 * m + 1] >= 0)) return false;
  return std::min(G.mat_param[mp_ax][m], G.mat_param[mp_ay][m]) >= coat_join_alpha;
}
// A path's first vertex for the split (PathStates::first_rough): 1 rough (light_traced_kind:
// every light path's), 0.5 a coat a distant source's light paths join (their glints only),
// 0 otherwise.
inline float first_vertex_class(const GeomView& G, int32_t m) noexcept {
  return light_traced_kind(G.mat_kind[m]) ? 1.f : sun_traced_material(G, m) ? 0.5f : 0.f;
}

// Russian roulette's numbers of vertex `vertex` (where it plays; rr_pair: its dimension
// pair, SampleLayout::russian_roulette), then f(k, roulette, inv_t) for the shading points
// [k, k + width) of each batch.
template <class T, class F>
inline void path_step_batches(const Estimator& est, uint32_t sample, uint32_t rr_pair, int vertex, TileBuffers& tb, F&& f) {
  const int padded = packet_padded(tb.points.count);
  const bool roulette = vertex > est.rr_depth;
  if (roulette) point_pairs(est, tb, sample, rr_pair, padded, tb.tech.u3, nullptr);
  const float inv_t = 1.f / est.rr_threshold;
  for (int k = 0; k < padded; k += lane_traits<T>::width) f(k, roulette, inv_t);
}

// Before the continuation sample's bounce rays are traced (bounce rays against the
// emitters, src/render/tile_run.h): which paths end at this vertex (TechniqueSample::ends,
// -1), by the same rule and random numbers continue_paths applies after the trace (the
// decision reads the sample, never its hit). Their rays need only the emitters, and an
// occlusion ray to one they reach; the others' need their nearest hit in the scene.
template <bool Materials, class T = vfloat>
inline void mark_path_ends(const GeomView& G, const Estimator& est, uint32_t sample, uint32_t rr_pair, int vertex,
                           TileBuffers& tb) {
  path_step_batches<T>(est, sample, rr_pair, vertex, tb, [&](int k, bool roulette, float inv_t) {
    const PathStep<T> p = path_step_lanes<T, Materials>(G, tb, k, roulette, inv_t);
    store_valid(tb.tech.ends + k, p.live && !p.go);
  });
}

// The last vertex's BSDF samples, bounce rays against the emitters where a scene decides
// per ray (src/render/tile_run.h): every traced ray ends its path (TechniqueSample::ends).
inline void mark_all_ends(TileBuffers& tb) {
  for (int k = 0; k < packet_padded(tb.points.count); ++k) tb.tech.ends[k] = tb.tech.valid[k] ? -1 : 0;
}

// The whole step for the shading points of vertex `vertex` (1: the camera's hits), whose
// last BSDF sample (tech, bounce packets) continues the path. rr_pair: the Russian
// roulette's dimension pair of this vertex (SampleLayout::russian_roulette).
template <bool Materials, class T = vfloat>
inline void continue_paths(const GeomView& G, const Estimator& est, uint32_t sample, uint32_t rr_pair, int vertex,
                           TileBuffers& tb) {
  path_step_batches<T>(est, sample, rr_pair, vertex, tb, [&](int k, bool roulette, float inv_t) {
    continue_path_lanes<T, Materials>(G, tb, k, roulette, inv_t);
  });
  if (vertex == 1 && est.light_paths) {  // (the first vertex's kind: drop_light_traced_hits)
    for (int k = 0; k < packet_padded(tb.points.count); ++k)
      tb.path.first_rough[k] = !Materials ? 1.f : first_vertex_class(G, tb.points.mat[k]);
  }
}

}  // namespace tuile
