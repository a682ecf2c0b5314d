// run_tile: one tile's stages back to back (generate, trace camera rays, camera hits and
// the camera rays that escaped, sample lights, trace shadow rays, sample the BSDF, trace
// bounce rays, MIS weight of the emitters hit and of the sky the escaped rays see,
// accumulate), a template over Features. Included only by the translation units in
// src/render/pipelines/, each of which instantiates a share of the registered pipelines
// (register_pipeline_part), so that both cores of a build compile them. Internal to src/render.
#pragma once
#include "render/tile_pipeline.h"
#include "render/guide.h"

#include <x86intrin.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <iterator>
#include <stdexcept>
#include <utility>

#include "wave/accumulate.h"
#include "wave/emitter_hits.h"
#include "wave/equiangular.h"
#include "wave/escaped.h"
#include "wave/generate.h"
#include "wave/media.h"
#include "wave/optimal_mis.h"
#include "wave/path.h"
#include "wave/ris.h"
#include "wave/sample_bsdf.h"
#include "wave/sample_lights.h"
#include "wave/surface_hits.h"

namespace tuile::pipeline_detail {


// Keeps a copy of a packet about to be traced, for the roofline replay (first pass only).
template <class P> inline void record(std::vector<RecordedPacket<P>>& out, const P& p, const int32_t* valid) {
  RecordedPacket<P> r;
  r.packet = p;
  std::memcpy(r.valid, valid, sizeof(r.valid));
  out.push_back(r);
}

// Times the stages of a tile when profiling; a single well-predicted branch otherwise. Reads
// the time-stamp counter once per stage boundary (clock_gettime costs several times more),
// converted to seconds with the ratio of counter ticks to wall
// time over the whole render. What is left for the "scheduling" row is the time between
// tiles (task scheduling).
struct StageTimer {
  ThreadProfile* tp;
  const TileContext& c;
  int tile;
  uint64_t t0 = 0;
  int depth = -1;  // paths: the vertex (0-based) whose stages run, for the per-vertex rows; -1 outside paths
  StageTimer(ThreadProfile* p, const TileContext& ctx, int t) : tp(p), c(ctx), tile(t) {}
  void start() {
#ifndef TUILE_NO_PROFILE_HOOKS
    if (tp) t0 = __rdtsc();
#endif
  }
  // Runs f outside the current stage's time (the roofline's packet copies).
  template <class F> void untimed(F&& f) {
    const uint64_t a = __rdtsc();
    f();
    t0 += __rdtsc() - a;
  }
  // Ends the running stage as s and starts the next one: one counter read per stage
  // boundary, and no time falls between stages.
  void lap([[maybe_unused]] Stage s) {
#ifdef TUILE_NO_PROFILE_HOOKS
    return;
#endif
    if (!tp) return;
    const uint64_t t1 = __rdtsc();
    tp->stage_ticks[static_cast<int>(s)] += t1 - t0;
    if (depth >= 0) tp->depth_ticks[std::min(depth, profile_depths - 1)][static_cast<int>(s)] += t1 - t0;
    if (c.profile->trace && tp->events.size() < c.profile->max_events)
      tp->events.push_back({s, tile, static_cast<double>(t0 - c.origin_ticks), static_cast<double>(t1 - t0)});
    t0 = t1;
  }
};

inline int active_lanes(const int32_t* valid) {
  if constexpr (packet_width % simd_width == 0) {
    int n = 0;
    for (int l = 0; l < packet_width; l += simd_width)
      n += count(f_mask_from_i(load_i32<vfloat>(valid + l) != vint(0)));
    return n;
  }
  int n = 0;
  for (int l = 0; l < packet_width; ++l) n += valid[l] != 0;
  return n;
}

// A set of shadow rays (S.valid lanes of [0, count)): occlusion queries, counted, with the
// media's transmittance (wave/media.h trace_shadow_lanes).
inline void trace_shadow_set(const TileContext& c, TileBuffers& tb, const ShadowLanes& S, int count, StageTimer& timer,
                             bool rec, ThreadProfile* tp) {
  clear_high_vector_registers();
  trace_shadow_lanes(
      c.v.geom, S, count,
      [&](const int32_t* valid, Ray16& s, int32_t* crossed) {
        const int active = active_lanes(valid);
        if (!active) return;
        if (rec) timer.untimed([&] { record(tp->rays.shadow, s, valid); });
        c.accel.occluded16(valid, s, false, crossed);
        tb.stats.rays_shadow += static_cast<uint64_t>(active);
      },
      [&](const int32_t* valid, RayHit16& q) { c.accel.intersect16(valid, q, false, Bvh::scene); });
}

// The shadow packets' valid lanes (tb.tech.valid) of the shading points.
inline void trace_shadow(const TileContext& c, TileBuffers& tb, StageTimer& timer, bool rec, ThreadProfile* tp) {
  trace_shadow_set(c, tb, shadow_lanes(tb), tb.points.count, timer, rec, tp);
}

// --equiangular in a scene with media (wave/equiangular.h): the segment light samples of
// rays [0, count) of packets (their flights in tb.media), pair0 and pair1 their random
// numbers (per tile lane or per shading point), beta the throughput at their origins (null:
// 1), each unoccluded one added to its pixel lane (lane[k], null: k).
inline void run_segment_lights(const TileContext& c, TileBuffers& tb, const Estimator& e, uint32_t s, uint32_t pair0,
                               uint32_t pair1, const RayHit16* packets, const int32_t* valid, int count, bool per_lane,
                               const float* const* beta, const int32_t* lane, StageTimer& timer, bool rec,
                               ThreadProfile* tp) {
  SegmentLights& S = tb.seg;
  const int padded = packet_padded(count);
  if (per_lane) {
    lane_pairs(e, tb, s, pair0, padded, S.u0, S.u1);
    lane_pairs(e, tb, s, pair1, padded, S.u2, S.u3);
  } else {
    point_pairs(e, tb, s, pair0, padded, S.u0, S.u1);
    point_pairs(e, tb, s, pair1, padded, S.u2, S.u3);
  }
  for (int k = 0; k < padded; k += simd_width)
    segment_light_lanes<vfloat, kind_all>(c.v.geom, c.v.lights, e, c.rate_light, c.rate_bsdf, packets, valid, count,
                                          tb.media, beta, S, k);
  timer.lap(Stage::sample_lights);
  const ShadowLanes sl{S.shadow, S.valid, S.cr, S.cg, S.cb, nullptr, nullptr, nullptr, tb.media.eq_med, tb.media.eq_med};
  trace_shadow_set(c, tb, sl, count, timer, rec, tp);
  timer.lap(Stage::intersect_shadow);
  PixelLanes& La = tb.lanes;
  for (int k = 0; k < count; ++k) {
    if (!S.valid[k] || S.shadow[k / packet_width].tfar[k % packet_width] == -INFINITY) continue;
    const int i = lane ? lane[k] : k;
    La.Lr[i] += S.cr[k];
    La.Lg[i] += S.cg[k];
    La.Lb[i] += S.cb[k];
  }
}

// The bounce packets' valid lanes: nearest hits in the scene or among the emitters, counted.
inline void trace_bounce(const TileContext& c, TileBuffers& tb, StageTimer& timer, int packets, bool rec, ThreadProfile* tp,
                         Bvh bvh) {
  clear_high_vector_registers();
  for (int p = 0; p < packets; ++p) {
    const int32_t* valid = tb.tech.valid + p * packet_width;
    const int active = active_lanes(valid);
    if (!active) continue;
    if (rec) timer.untimed([&] { record(bvh == Bvh::emitters ? tp->rays.bounce_emitters : tp->rays.bounce, tb.bounce[p], valid); });
    c.accel.intersect16(valid, tb.bounce[p], false, bvh);
    tb.stats.rays_bounce += static_cast<uint64_t>(active);
  }
}

// A path's continuation rays, bounce rays against the emitters: those of the paths that go
// on against the whole scene (their next vertex), those of the paths that end at this vertex
// (tb.tech.ends) against the emitters alone, since only the emitter they reach counts.
inline void trace_bounce_split(const TileContext& c, TileBuffers& tb, StageTimer& timer, int packets, bool rec,
                               ThreadProfile* tp) {
  clear_high_vector_registers();
  for (int p = 0; p < packets; ++p) {
    const int32_t* valid = tb.tech.valid + p * packet_width;
    const int32_t* ends = tb.tech.ends + p * packet_width;
    alignas(64) int32_t on[packet_width], off[packet_width];
    int n_on = 0, n_off = 0;
    for (int l = 0; l < packet_width; ++l) {
      on[l] = valid[l] && !ends[l] ? -1 : 0;
      off[l] = valid[l] && ends[l] ? -1 : 0;
      n_on += on[l] != 0;
      n_off += off[l] != 0;
    }
    if (n_on + n_off == 0) continue;
    if (rec) timer.untimed([&] {
      if (n_on) record(tp->rays.bounce, tb.bounce[p], on);
      if (n_off) record(tp->rays.bounce_emitters, tb.bounce[p], off);
    });
    if (n_on) c.accel.intersect16(on, tb.bounce[p], false, Bvh::scene);
    if (n_off) c.accel.intersect16(off, tb.bounce[p], false, Bvh::emitters);
    tb.stats.rays_bounce += static_cast<uint64_t>(n_on + n_off);
  }
}

// A scene with a sky, bounce rays against the emitters: the rays of the paths that end
// (tb.tech.ends) that reached no emitter leave the scene only if nothing of it lies in their
// way. Their occlusion rays to infinity, gathered into whole packets (tb.shadow, free
// between the light samples and the emitter hits' visibility rays); a ray blocked gets
// tfar -inf in its bounce packet (Embree's mark), which escaped_bounce reads as not
// escaped.
inline void escape_rays(const TileContext& c, TileBuffers& tb, StageTimer& timer, bool rec, ThreadProfile* tp) {
  alignas(64) int32_t from[max_tile_lanes], on[max_tile_lanes];
  int n = 0;
  for (int k = 0; k < tb.points.count; ++k)
    if (tb.tech.valid[k] && tb.tech.ends[k] && tb.bounce[k / packet_width].geomID[k % packet_width] == invalid_id) from[n++] = k;
  if (n == 0) return;
  for (int j = 0; j < packet_padded(n); ++j) {
    Ray16& q = tb.shadow[j / packet_width];
    const int l = j % packet_width;
    on[j] = j < n ? -1 : 0;
    if (j >= n) continue;
    const Ray16& r = tb.bounce[from[j] / packet_width].ray;
    const int i = from[j] % packet_width;
    q.org_x[l] = r.org_x[i];
    q.org_y[l] = r.org_y[i];
    q.org_z[l] = r.org_z[i];
    q.dir_x[l] = r.dir_x[i];
    q.dir_y[l] = r.dir_y[i];
    q.dir_z[l] = r.dir_z[i];
    q.tfar[l] = r.tfar[i];
  }
  for (int p = 0; p < packets_for(n); ++p) {
    if (rec) timer.untimed([&] { record(tp->rays.shadow, tb.shadow[p], on + p * packet_width); });
    c.accel.occluded16(on + p * packet_width, tb.shadow[p], false);
  }
  for (int j = 0; j < n; ++j)
    if (tb.shadow[j / packet_width].tfar[j % packet_width] == -INFINITY) tb.bounce[from[j] / packet_width].ray.tfar[from[j] % packet_width] = -INFINITY;
  tb.stats.rays_bounce_visibility += static_cast<uint64_t>(n);
}

// --guide while it learns (render/guide.h): each path's vertices of this sample, kept per
// tile lane (GuidePathLanes), then, once the sample is done, the light that reached each
// guided vertex along the direction its path went on (the light the later vertices added,
// over the throughput up to them) recorded into the guide.
inline GuidePathLanes& guide_lanes(TileBuffers& tb) {
  if (!tb.guide.lanes) tb.guide.lanes = std::make_unique<GuidePathLanes>();
  return *tb.guide.lanes;
}

inline void guide_start(TileBuffers& tb, int lanes) { std::fill_n(guide_lanes(tb).reached, lanes, 0); }

// After add_vertex_radiance at vertex `vertex` (1: the camera's hits): what it added.
inline void guide_vertex_light(TileBuffers& tb, int vertex, bool first) {
  GuidePathLanes& g = *tb.guide.lanes;
  const int row = std::min(vertex - 1, GuidePathLanes::vertices);
  const bool add = vertex - 1 > GuidePathLanes::vertices;  // the last row sums the deeper vertices
  for (int k = 0; k < tb.points.count; ++k) {
    const int i = tb.points.lane[k];
    const float r = first ? tb.radiance.r[k] : tb.path.throughput_r[k] * tb.radiance.r[k];
    const float gg = first ? tb.radiance.g[k] : tb.path.throughput_g[k] * tb.radiance.g[k];
    const float b = first ? tb.radiance.b[k] : tb.path.throughput_b[k] * tb.radiance.b[k];
    g.cr[row][i] = add ? g.cr[row][i] + r : r;
    g.cg[row][i] = add ? g.cg[row][i] + gg : gg;
    g.cb[row][i] = add ? g.cb[row][i] + b : b;
    g.reached[i] = vertex;
    if (vertex <= GuidePathLanes::vertices) g.ok[vertex - 1][i] = 0;  // (guide_vertex_path: if the path goes on)
  }
}

// After continue_paths at vertex `vertex`: the paths that go on from a guided point along a
// sample that is not a delta lobe's.
inline void guide_vertex_path(const GeomView& G, TileBuffers& tb, int vertex) {
  if (vertex > GuidePathLanes::vertices) return;
  GuidePathLanes& g = *tb.guide.lanes;
  const int v = vertex - 1;
  for (int k = 0; k < tb.points.count; ++k) {
    const int i = tb.points.lane[k];
    const int32_t kind = G.mat_kind[tb.points.mat[k]];
    const bool ok = tb.tech.valid[k] && !tb.tech.delta[k] && tb.tech.pdf[k] > 0.f && guided_kind<float>(kind);
    g.ok[v][i] = ok;
    if (!ok) continue;
    const RayHit16& r = tb.bounce[k / packet_width];
    const int l = k % packet_width;
    g.x[v][i] = tb.points.px[k];
    g.y[v][i] = tb.points.py[k];
    g.z[v][i] = tb.points.pz[k];
    g.dx[v][i] = r.ray.dir_x[l];
    g.dy[v][i] = r.ray.dir_y[l];
    g.dz[v][i] = r.ray.dir_z[l];
    // the record is L_in cos / p at a surface: the guide learns the light times the cosine
    // at the point (the product a diffuse surface integrates), not the light alone; in a
    // medium, L_in / p (the phase function has no cosine)
    const bool medium = kind == static_cast<int32_t>(MaterialKind::phase);
    const float nx = G.shading_normals ? tb.points.snx[k] : tb.points.nx[k];
    const float ny = G.shading_normals ? tb.points.sny[k] : tb.points.ny[k];
    const float nz = G.shading_normals ? tb.points.snz[k] : tb.points.nz[k];
    const float cosine = medium ? 1.f : std::abs(nx * r.ray.dir_x[l] + ny * r.ray.dir_y[l] + nz * r.ray.dir_z[l]);
    g.pdf[v][i] = tb.tech.pdf[k] / std::max(cosine, 1e-6f);
    g.cls[v][i] = medium ? guide_medium_class
                         : guide_class<float>(Vec3<float>(tb.points.nx[k], tb.points.ny[k], tb.points.nz[k]));
    g.tr[v][i] = tb.path.throughput_r[k];
    g.tg[v][i] = tb.path.throughput_g[k];
    g.tb[v][i] = tb.path.throughput_b[k];
  }
}

// Once the sample is done: each guided vertex's record, from the deepest vertex back.
inline void guide_record_sample(Guide& guide, TileBuffers& tb, int lanes) {
  GuidePathLanes& g = *tb.guide.lanes;
  for (int i = 0; i < lanes; ++i) {
    float sr = 0, sg = 0, sb = 0;  // the light of the vertices past v
    for (int v = std::min(g.reached[i], GuidePathLanes::vertices + 1) - 1; v >= 0; --v) {
      if (v < GuidePathLanes::vertices && g.ok[v][i]) {
        auto in = [](float s, float t) { return t > 0.f ? s / t : 0.f; };
        const float L = luminance(in(sr, g.tr[v][i]), in(sg, g.tg[v][i]), in(sb, g.tb[v][i]));
        guide.record(g.x[v][i], g.y[v][i], g.z[v][i], g.cls[v][i], g.dx[v][i], g.dy[v][i], g.dz[v][i],
                     L / g.pdf[v][i]);
      }
      sr += g.cr[v][i];
      sg += g.cg[v][i];
      sb += g.cb[v][i];
    }
  }
}

// Resampled importance sampling of one vertex's direct light (wave/ris.h): the light
// candidates, the BSDF candidates traced against the emitters, then one shadow ray per
// shading point for the kept candidate.
template <Features F>
void run_ris(const TileContext& c, TileBuffers& tb, StageTimer& timer, const Estimator& e, uint32_t s, uint32_t d,
             int packets, bool rec, ThreadProfile* tp) {
  const SceneViews& v = c.v;
  const SampleLayout& layout = c.layout;
  ris_clear(tb);
  LightPass pass;
  pass.fixed_light = F.pick ? -1 : 0;
  for (int j = 0; j < e.ris_light; ++j)
    ris_light_candidates<F.kinds, F.pick, F.bsdfs>(v.geom, v.lights, e, pass, s, layout.light_pick(static_cast<uint32_t>(j), d),
                                                   layout.light_point(static_cast<uint32_t>(j), d), tb);
  timer.lap(Stage::sample_lights);
  for (int m = 0; m < e.ris_bsdf; ++m) {
    const uint32_t mm = static_cast<uint32_t>(m);
    sample_bsdf<F.bsdfs>(v.geom, e, s, layout.bsdf(mm, d), layout.bsdf_lobe(mm, d), tb);
    timer.lap(Stage::sample_bsdf);
    trace_bounce(c, tb, timer, packets, rec, tp, Bvh::emitters);
    timer.lap(Stage::intersect_bounce);
    ris_bsdf_candidates<F.kinds, F.bsdfs>(v.geom, v.lights, e, s, layout.bsdf_lobe(mm, d), tb);
    timer.lap(Stage::sample_lights);
  }
  ris_finish(tb);
  timer.lap(Stage::sample_lights);
  trace_shadow(c, tb, timer, rec, tp);
  timer.lap(Stage::intersect_shadow);
  accumulate_shadow(tb);
  timer.lap(Stage::accumulate);
}

// The tile's lanes, one per pixel: 4x4 pixel blocks, one per packet of 16 (a smaller
// footprint than a row of 16, so Embree's packets are more coherent), where the tile
// divides into them (returns true); rows otherwise. Every lane's numbers depend on its pixel
// only, so the image does not change.
inline bool set_tile_lanes(const TileContext& c, TileBuffers& tb, int x0, int y0, int tw, int th) {
  const bool blocks = tw % 4 == 0 && th % 4 == 0 && packet_width == 16;
  int i = 0;
  auto set_lane = [&](int x, int y) {
    tb.lanes.fx[i] = static_cast<float>(x);
    tb.lanes.fy[i] = static_cast<float>(y);
    tb.lanes.pixel[i++] = static_cast<uint32_t>(y) * static_cast<uint32_t>(c.width) + static_cast<uint32_t>(x);
  };
  if (blocks) {
    for (int by = y0; by < y0 + th; by += 4)
      for (int bx = x0; bx < x0 + tw; bx += 4)
        for (int j = 0; j < 16; ++j) set_lane(bx + j % 4, by + j / 4);
  } else {
    for (int y = y0; y < y0 + th; ++y)
      for (int x = x0; x < x0 + tw; ++x) set_lane(x, y);
  }
  return blocks;
}

// The sampler's keys of the pairs this pipeline draws (pair numbers as run_tile draws
// them), hashed once per pixel for all of the tile's samples.
template <Features F> void hash_tile_keys(const TileContext& c, TileBuffers& tb, int lanes, int cam_packets) {
  const Estimator& est = c.est;
  const SampleLayout& layout = c.layout;
  tb.keys.keyed = 0;
  if (cacheable(est.sampler)) {
    auto bit = [](uint32_t pair) { return pair < SamplerKeys::pairs ? 1u << pair : 0u; };
    uint32_t want = bit(SampleLayout::camera);
    if (est.one_sample()) want |= bit(layout.technique_choice());
    if constexpr (F.bsdf)
      for (int m = 0; m < c.bsdf_passes; ++m) {
        want |= bit(layout.bsdf(static_cast<uint32_t>(m)));
        if (F.bsdfs != bsdf_diffuse) want |= bit(layout.bsdf_lobe(static_cast<uint32_t>(m)));
      }
    if constexpr (F.light)
      for (int j = 0; j < c.light_passes; ++j) {
        if (F.pick && est.pick != LightPick::all) want |= bit(layout.light_pick(static_cast<uint32_t>(j)));
        want |= bit(layout.light_point(static_cast<uint32_t>(j)));
      }
    const int padded = cam_packets * packet_width;
    for (int i = lanes; i < padded; ++i) tb.lanes.pixel[i] = tb.lanes.pixel[0];  // as generate pads
    for (uint32_t bits = want; bits; bits &= bits - 1) {
      const int p = std::countr_zero(bits);
      make_pair_keys(est.seed, tb.lanes.pixel, static_cast<uint32_t>(p), padded, tb.keys.lane_keys(p));
    }
    tb.keys.keyed = want;
  }
}

// Scenes with media: the camera rays' flights (wave/media.h), from the camera's medium;
// their weights kept per tile lane (MediumLanes::cw*) for the paths' first throughput.
inline void camera_media(const TileContext& c, TileBuffers& tb, uint32_t s, int lanes) {
  const GeomView& G = c.v.geom;
  MediumLanes& ml = tb.media;
  const int padded = packet_padded(lanes);
  std::fill_n(ml.med, padded, G.media.camera);
  if (!G.media.absorb_only)  // (absorbing flights draw nothing)
    lane_pairs(c.est, tb, s, c.layout.medium_flight(c.layout.bsdf_samples, 0), padded, ml.u0, ml.u1);
  medium_flights(G, tb.cam, tb.lanes.cam_valid, lanes, ml, tb.stats.rejected_camera,
                 [&](const int32_t* valid, RayHit16& p) { c.accel.intersect16(valid, p, false, Bvh::scene); });
  std::copy_n(ml.wr, padded, ml.cwr);
  std::copy_n(ml.wg, padded, ml.cwg);
  std::copy_n(ml.wb, padded, ml.cwb);
}

// After the camera hits: what the camera's lanes saw directly (emitters, the sky) through
// the media, and the emission on the way.
inline void camera_media_seen(TileBuffers& tb, int lanes) {
  MediumLanes& ml = tb.media;
  for (int i = 0; i < lanes; ++i) {
    tb.lanes.Lr[i] = tb.lanes.Lr[i] * ml.cwr[i] + ml.er[i];
    tb.lanes.Lg[i] = tb.lanes.Lg[i] * ml.cwg[i] + ml.eg[i];
    tb.lanes.Lb[i] = tb.lanes.Lb[i] * ml.cwb[i] + ml.eb[i];
  }
}

// The paths' first throughput: the camera ray's flight.
inline void camera_media_paths(TileBuffers& tb) {
  const MediumLanes& ml = tb.media;
  for (int k = 0; k < tb.points.count; ++k) {
    const int i = tb.points.lane[k];
    tb.path.throughput_r[k] = ml.cwr[i];
    tb.path.throughput_g[k] = ml.cwg[i];
    tb.path.throughput_b[k] = ml.cwb[i];
  }
}

// Scenes with media: the flights of BSDF sample m's bounce rays (depth d) from the medium
// on their side of each point; their weights join the samples' throughput (so the emitters
// and the sky they reach, and the paths that go on, carry them). emission: the ray is the
// path's continuation, whose medium emission counts (pbrt-v4: the segments before the last
// vertex).
inline void bounce_media(const TileContext& c, TileBuffers& tb, const Estimator& e, uint32_t s, uint32_t d, uint32_t m,
                         bool emission, StageTimer& timer, bool rec, ThreadProfile* tp) {
  const GeomView& G = c.v.geom;
  MediumLanes& ml = tb.media;
  const int n = tb.points.count, padded = packet_padded(n);
  for (int k = 0; k < padded; ++k) ml.med[k] = bounce_ray_medium(tb, k);
  if (!G.media.absorb_only) point_pairs(e, tb, s, c.layout.medium_flight(m, d), padded, ml.u0, ml.u1);
  medium_flights(G, tb.bounce, tb.tech.valid, n, ml, tb.stats.rejected_bsdf,
                 [&](const int32_t* valid, RayHit16& p) { c.accel.intersect16(valid, p, false, Bvh::scene); });
  // --equiangular: the continuation's segment light samples, from the throughput at the
  // point times the BSDF sample's weight (before the flight's)
  if (emission && e.equiangular) {
    SegmentLights& S = tb.seg;
    for (int k = 0; k < packet_padded(n); ++k) {
      S.br[k] = tb.path.throughput_r[k] * tb.tech.beta_r[k];
      S.bg[k] = tb.path.throughput_g[k] * tb.tech.beta_g[k];
      S.bb[k] = tb.path.throughput_b[k] * tb.tech.beta_b[k];
    }
    const float* beta[3] = {S.br, S.bg, S.bb};
    timer.lap(Stage::media);
    run_segment_lights(c, tb, e, s, c.layout.segment_light(0, d), c.layout.segment_light(1, d), tb.bounce, tb.tech.valid, n,
                       false, beta, tb.points.lane, timer, rec, tp);
    timer.lap(Stage::sample_lights);
  }
  for (int k = 0; k < n; ++k) {
    if (!tb.tech.valid[k]) continue;
    if (emission) {
      tb.radiance.r[k] += tb.tech.beta_r[k] * ml.er[k];
      tb.radiance.g[k] += tb.tech.beta_g[k] * ml.eg[k];
      tb.radiance.b[k] += tb.tech.beta_b[k] * ml.eb[k];
    }
    tb.tech.beta_r[k] *= ml.wr[k];
    tb.tech.beta_g[k] *= ml.wg[k];
    tb.tech.beta_b[k] *= ml.wb[k];
  }
}

// One vertex's light samples (the light technique: c.light_passes of them, each a shadow
// ray), or resampled importance sampling of its direct light (run_ris).
template <Features F>
void run_light_samples(const TileContext& c, TileBuffers& tb, StageTimer& timer, const Estimator& e, uint32_t s, uint32_t d,
                       int packets, bool rec, ThreadProfile* tp) {
  const SceneViews& v = c.v;
  const SampleLayout& layout = c.layout;
  // (a pipeline with the light stages may run a scene without lights: the general one,
  // forced or standing in for all, whose empty light table has nothing to pick from)
  if (v.lights.count == 0) {
  } else if (tb.points.count > 0 && e.strategy == Strategy::ris) {
    if constexpr (F.bsdf) run_ris<F>(c, tb, timer, e, s, d, packets, rec, tp);
  } else if (tb.points.count > 0) {
    for (int j = 0; j < c.light_passes; ++j) {
      LightPass pass;
      pass.fixed_light = e.pick == LightPick::all ? j % c.light_count : (F.pick ? -1 : 0);
      pass.rate_light = c.rate_light;
      pass.rate_bsdf = c.rate_bsdf;
      const uint32_t pick_pair = layout.light_pick(static_cast<uint32_t>(j), d);
      const uint32_t point_pair = layout.light_point(static_cast<uint32_t>(j), d);
      // (--guide: the general pipeline's guided instantiation, only while a guide is there,
      // so that an unguided render runs the code it ran before)
      if constexpr (F == general_features) {
        if (v.geom.guide)
          sample_lights<F.kinds, F.pick, F.bsdfs, true>(v.geom, v.lights, e, pass, s, pick_pair, point_pair, tb);
        else
          sample_lights<F.kinds, F.pick, F.bsdfs, false>(v.geom, v.lights, e, pass, s, pick_pair, point_pair, tb);
      } else {
        sample_lights<F.kinds, F.pick, F.bsdfs>(v.geom, v.lights, e, pass, s, pick_pair, point_pair, tb);
      }
      timer.lap(Stage::sample_lights);
      trace_shadow(c, tb, timer, rec, tp);
      timer.lap(Stage::intersect_shadow);
      accumulate_shadow(tb);
      if (optimal_mis(e)) optimal_light_pass(tb, e, c.rate_light, c.rate_bsdf);
      timer.lap(Stage::accumulate);
    }
  }
}

// One vertex's BSDF samples: each traced, its emitter hits queued and MIS-weighted; the last
// one is the path's continuation (continuation rays need their nearest hit in the scene).
template <Features F>
void run_bsdf_samples(const TileContext& c, TileBuffers& tb, StageTimer& timer, const Estimator& e, uint32_t s, uint32_t d,
                      int packets, bool rec, ThreadProfile* tp, bool last) {
  const SceneViews& v = c.v;
  const SampleLayout& layout = c.layout;
  if (tb.points.count > 0) {
    // the last vertex's bounce rays may look for the emitters alone (then a visibility
    // ray); a path's other bounce rays need their nearest hit in the scene
    // (where a scene decides per ray, the last vertex's rays are split as a path's
    // continuation is, every one of them ending there: a scene with media, whose rays that
    // start in a medium need the scene, or a sky, to which the rays that reach no emitter
    // need an occlusion ray)
    const bool per_ray = v.geom.has_media || v.lights.sky_count > 0;
    const bool against_emitters = last && c.bounce_against_emitters && !per_ray;
    // resampled importance sampling took its BSDF candidates (run_ris): what is left is
    // the last BSDF sample, for the path's continuation and the delta lobes
    const bool ris = e.strategy == Strategy::ris;
    for (int m = ris ? c.bsdf_passes - 1 : 0; m < c.bsdf_passes; ++m) {
      const bool continuation = !last && m == c.bsdf_passes - 1;
      if (ris && !continuation && (F.bsdfs & bsdf_delta_capable) == 0) break;
      const uint32_t pair = layout.bsdf(static_cast<uint32_t>(m), d), lobe_pair = layout.bsdf_lobe(static_cast<uint32_t>(m), d);
      const bool only_delta = e.strategy == Strategy::light || ris;
      if constexpr (F == general_features) {  // (as the light samples)
        if (v.geom.guide) sample_bsdf<F.bsdfs, true>(v.geom, e, s, pair, lobe_pair, tb, only_delta, continuation);
        else sample_bsdf<F.bsdfs, false>(v.geom, e, s, pair, lobe_pair, tb, only_delta, continuation);
      } else {
        sample_bsdf<F.bsdfs>(v.geom, e, s, pair, lobe_pair, tb, only_delta, continuation);
      }
      // (bounce rays against the emitters: a path's continuation rays against the whole scene
      // only for the paths that go on)
      const bool split = c.bounce_against_emitters && (continuation || (last && per_ray));
      if (split) {
        if (continuation) mark_path_ends<F.bsdfs != bsdf_diffuse>(v.geom, e, s, layout.russian_roulette(d), static_cast<int>(d) + 1, tb);
        else mark_all_ends(tb);
        if (v.geom.has_media) ends_in_vacuum(tb);
      }
      timer.lap(Stage::sample_bsdf);
      if (split) trace_bounce_split(c, tb, timer, packets, rec, tp);
      else trace_bounce(c, tb, timer, packets, rec, tp, against_emitters ? Bvh::emitters : Bvh::scene);
      if constexpr ((F.kinds & kind_sky) != 0)
        if (split && v.lights.sky_count > 0) escape_rays(c, tb, timer, rec, tp);
      timer.lap(Stage::intersect_bounce);
      if (!against_emitters) prefetch_hits(v.geom, tb.bounce, tb.tech.valid, tb.points.count);  // for the emitters' queue and the next hits
      if (v.geom.has_media) {
        bounce_media(c, tb, e, s, d, static_cast<uint32_t>(m), continuation, timer, rec, tp);
        timer.lap(Stage::media);
      }
      constexpr bool delta = (F.bsdfs & bsdf_delta_capable) != 0;
      const bool optimal = optimal_mis(e);
      if (optimal) optimal_bsdf_clear(tb);
      queue_bounce_hits<vfloat, F.kinds, delta>(v.geom, v.lights, tb, against_emitters || split,
                                                continuation && e.one_sample(), split ? tb.tech.ends : nullptr);
      int vis_rays = 0;
      const int qpackets = (against_emitters || split) && tb.queue.count > 0 ? bounce_visibility_rays(tb, vis_rays) : 0;
      if (vis_rays > 0) {
        timer.lap(Stage::mis_weight);
        clear_high_vector_registers();
        for (int p = 0; p < qpackets; ++p) {
          if (!active_lanes(tb.queue.valid + p * packet_width)) continue;  // (split: the entries whose rays saw the scene)
          if (rec) timer.untimed([&] { record(tp->rays.shadow, tb.shadow[p], tb.queue.valid + p * packet_width); });
          c.accel.occluded16(tb.queue.valid + p * packet_width, tb.shadow[p], false);
        }
        tb.stats.rays_bounce_visibility += static_cast<uint64_t>(vis_rays);
        timer.lap(Stage::intersect_bounce);
        read_bounce_visibility(tb);
      }
      if (e.light_paths && d >= 1 && (delta || v.lights.lt_glossy != nullptr))
        drop_light_traced_hits<delta>(v.geom, v.lights, tb);
      weight_queue<F.kinds, delta>(v.lights, e, c.rate_light, c.rate_bsdf, tb);
      // the rays that left the scene see the sky (those traced against the emitters alone:
      // where their occlusion ray to infinity met nothing, escape_rays)
      if constexpr ((F.kinds & kind_sky) != 0)
        escaped_bounce<vfloat, delta>(v.lights, e, c.rate_light, c.rate_bsdf, tb, continuation && e.one_sample());
      if (optimal) optimal_bsdf_pass(tb, e, c.rate_light, c.rate_bsdf, delta, e.aov_mis_weight);
      timer.lap(Stage::mis_weight);
    }
  }
}

// The tile pipeline, instantiated per Features (wave/features.h): it leaves out what its
// scenes do not need.
template <Features F>
void run_tile(const TileContext& c, TileBuffers& tb, ThreadProfile* tp, int tile, uint32_t begin, uint32_t end) {
  const SceneViews& v = c.v;
  const Estimator& est = c.est;
  Film& film = c.film;
  const int ts = c.tile_size;
  const int x0 = (tile % c.tiles_x) * ts, y0 = (tile / c.tiles_x) * ts;
  const int tw = std::min(ts, c.width - x0), th = std::min(ts, c.height - y0);
  const int lanes = tw * th;
  StageTimer timer(tp, c, tile);
  timer.start();
  const bool blocks = set_tile_lanes(c, tb, x0, y0, tw, th);
  const int cam_packets = packets_for(lanes);
  timer.lap(Stage::generate);
  clear_tile_sums(tb, lanes);
  timer.lap(Stage::accumulate);
  const SampleLayout& layout = c.layout;
  Estimator deep = est;  // paths past the first vertex: the MIS-weight AOV is the first vertex's
  deep.aov_mis_weight = false;
  // --heuristic optimal applies at the first vertex; the power heuristic after it
  const bool optimal = optimal_mis(est);
  if (optimal) {
    deep.heuristic = Heuristic::power;
    optimal_tile_start(tb, lanes, c.opt_prior);
  }
  hash_tile_keys<F>(c, tb, lanes, cam_packets);
  // --guide while it learns: the general pipeline's paths record into it
  Guide* const rec_guide = F == general_features && est.max_depth > 1 ? c.guide_rec : nullptr;
  timer.lap(Stage::generate);
  for (uint32_t s = begin; s < end; ++s) {
    generate(v.camera, est, s, layout.camera, lanes, tb);
    if (optimal) optimal_alphas(tb, lanes, c.opt_prior_samples + (s - begin), s == begin);
    timer.lap(Stage::generate);
    const bool rec = tp && c.profile->record_rays && s == begin;
    clear_high_vector_registers();
    for (int p = 0; p < cam_packets; ++p) {
      if (rec) timer.untimed([&] { record(tp->rays.camera, tb.cam[p], tb.lanes.cam_valid + p * packet_width); });
      c.accel.intersect16(tb.lanes.cam_valid + p * packet_width, tb.cam[p], true);
    }
    tb.stats.rays_camera += static_cast<uint64_t>(lanes);
    timer.lap(Stage::intersect_camera);
    const bool media = v.geom.has_media;
    if (media) {
      camera_media(c, tb, s, lanes);
      timer.lap(Stage::media);
    }
    camera_hits<F.emitter_lookup, vfloat, F.bsdfs != bsdf_diffuse>(v.geom, v.lights, est, s, layout.technique_choice(),
                                                                   lanes, tb);
    if constexpr ((F.kinds & kind_sky) != 0) escaped_camera(v.lights, tb, lanes);  // the sky, seen directly
    if (media) camera_media_seen(tb, lanes);
    timer.lap(Stage::camera_hits);
    if (media && est.equiangular) {  // the camera rays' segment light samples
      const float* const none[3] = {nullptr, nullptr, nullptr};
      run_segment_lights(c, tb, est, s, layout.segment_light(2), layout.segment_light(3), tb.cam, tb.lanes.cam_valid, lanes,
                         true, none, nullptr, timer, rec, tp);
      timer.lap(Stage::sample_lights);
    }
    // Direct lighting is the first vertex; paths (max_depth > 1) go on from the last BSDF
    // sample of each vertex, compacted (bounce_hits), until no path is left or the depth
    // is reached. In a scene with media every sample runs as a path (the camera ray's
    // flight is its first throughput).
    const bool paths = est.max_depth > 1 || media;
    if (paths) start_paths(tb);
    if (rec_guide) guide_start(tb, lanes);
    if (media) camera_media_paths(tb);
    for (int vertex = 1;; ++vertex) {
      const uint32_t d = static_cast<uint32_t>(vertex - 1);
      const bool last = vertex >= est.max_depth;
      const Estimator& e = vertex == 1 ? est : deep;
      if (paths) timer.depth = vertex - 1;
      const int packets = packets_for(tb.points.count);
      if (tp && paths) {
        const int row = std::min(vertex - 1, profile_depths - 1);
        tp->depth_points[row] += static_cast<uint64_t>(tb.points.count);
        tp->depth_packets[row] += static_cast<uint64_t>(packets);
        tp->depth_lane_packets[row] += static_cast<uint64_t>(cam_packets);
      }
      if constexpr (F == general_features)  // --guide: each point's share and distribution, once
        if (c.v.geom.guide && tb.points.count > 0) guide_points<F.bsdfs>(c.v.geom, tb);
      if constexpr (F.light) run_light_samples<F>(c, tb, timer, e, s, d, packets, rec, tp);
      if constexpr (F.bsdf) run_bsdf_samples<F>(c, tb, timer, e, s, d, packets, rec, tp, last);
      if (!paths) break;
      add_vertex_radiance(tb, vertex == 1 && !media);
      if (rec_guide) guide_vertex_light(tb, vertex, vertex == 1 && !media);
      timer.lap(Stage::accumulate);
      if constexpr (!F.bsdf) break;  // (pipeline_features gives paths the BSDF stages)
      if (last || tb.points.count == 0) break;
      continue_paths<F.bsdfs != bsdf_diffuse>(v.geom, e, s, layout.russian_roulette(d), vertex, tb);
      if (rec_guide) guide_vertex_path(v.geom, tb, vertex);
      timer.lap(Stage::sample_bsdf);
      timer.depth = vertex;  // the next vertex's hits
      bounce_hits<vfloat, F.bsdfs != bsdf_diffuse>(v.geom, v.lights, e, s, layout.technique_choice(d + 1), tb);
      tb.stats.path_vertices += static_cast<uint64_t>(tb.points.count);
      timer.lap(Stage::camera_hits);
    }
    timer.depth = -1;
    if (paths) std::fill_n(tb.lanes.shade_of, cam_packets * packet_width, -1);  // every vertex is in the lanes' radiance
    if (rec_guide) guide_record_sample(*rec_guide, tb, lanes);
    // one sample of every pixel into the tile's double sums
    accumulate_samples(tb, lanes, est.aov_mis_weight);
    timer.lap(Stage::accumulate);
  }
  // The tile's sums into the film, once. Each pixel belongs to one tile, so the film
  // gets the same bits for any thread count and tile order. A fresh film (0) gets the
  // bits of adding sample by sample; a film that already holds samples (progressive
  // renders) gets its old sum plus this render's partial sum: other rounding than adding
  // one sample at a time, equally deterministic.
  const FilmSums fs{film.sum.data(),    film.sum_sq.data(),           film.w_sum.data(), film.w_cnt.data(),
                    film.max_sample.data(), static_cast<size_t>(c.width)};
  if (c.fresh_film && blocks && can_stream_tile(x0, tw, th, fs)) stream_tile_to_film(tb, x0, y0, th, fs, est.aov_mis_weight);
  else add_tile_to_film(tb, lanes, fs, est.aov_mis_weight);
  if (optimal) optimal_tile_end(tb, lanes, c.opt_film);
  timer.lap(Stage::accumulate);
}

// The registered pipelines of part Part (pipeline_part_of), into their slots of table (the
// index order of registered_pipelines). Each src/render/pipelines/part_<k>.cpp
// instantiates it for its k; tile_pipeline.cpp calls every part once.
template <int Part, size_t I> void register_one(TileFn* table) {
  constexpr bool mine = general_pipeline_only ? I == 0 && Part == 0 : pipeline_part_of(registered_pipelines[I]) == Part;
  if constexpr (mine) table[I] = &run_tile<registered_pipelines[I]>;
}
template <int Part, size_t... I> void register_indices(TileFn* table, std::index_sequence<I...>) {
  (register_one<Part, I>(table), ...);
}

}  // namespace tuile::pipeline_detail

namespace tuile {
template <int Part> void register_pipeline_part(TileFn* table) {
  pipeline_detail::register_indices<Part>(table, std::make_index_sequence<pipeline_count>());
}
}  // namespace tuile
