// Participating media in the wavefront (pbrt-v4's volpath for homogeneous media): the
// stages a scene with media runs beside the surface stages (GeomView::has_media; a scene
// without media never calls them).
//
// - medium_flights, after a set of rays was traced (the camera's, or one BSDF sample's
//   bounce rays): each ray travels in a medium (MediumLanes::med, -1 for none) from its
//   origin to its hit. In a medium that scatters, a free flight is drawn: by one channel's
//   exponential (the hero channel, uniform over the three) through every scattering
//   segment of the ray together (an optical depth tau = -log(1 - u) in the hero channel,
//   spent segment by segment), weighted by the one-sample MIS (balance heuristic) over the
//   three channels' densities (Miller, Georgiev & Jarosz 2019; medium/homogeneous.h), so
//   each channel is unbiased whatever the others' coefficients. A homogeneous medium is its
//   own majorant: every collision is real, and its absorbed share is in the weight
//   (sigma_s / sigma_t), not a coin. A medium that only absorbs draws nothing: its
//   transmittance exp(-sigma_t d) multiplies the weight (the expectation of any tracking
//   estimator, with no variance). A ray that meets an "interface" surface passes it
//   (pbrt-v4: no vertex, no BSDF), takes the medium of the side it enters and is traced on;
//   a ray that scatters becomes a hit of its medium's row of the geometry table
//   (GeomKind::medium) at the collision, so the hit stages make it a shading point whose
//   BSDF is the medium's phase function (MaterialKind::phase). Emission (sigma_a Le) is
//   gathered along the ray: at a collision (pbrt-v4's estimator) in scattering media, in
//   closed form in absorbing ones.
// - shadow_media, for the shadow rays: the transmittance to the light through every medium
//   and interface on the way, in closed form; any other surface occludes. An occlusion
//   query first, in which interfaces do not occlude but mark the rays that meet them; only
//   those are walked.
// - point_media (wave/surface_hits.h, run by the hit stages): which medium lies on each side
//   of a shading point (ShadingPoints::medf, medb): a surface that separates two media (its
//   MediumInterface) says; any other keeps the medium its ray came through.
// Scalar per lane (the media's rays are often a minority of the lanes, and their loops
// differ per lane), but for the flights' first round of the rays that start in a
// scattering medium and meet no interface (first_flights_simd: the scalar round's
// operations, lane for lane); the numbers are lane_math's, the same bits on every machine.
#pragma once
#include <algorithm>
#include <cmath>

#include "medium/homogeneous.h"
#include "wave/surface_hits.h"

namespace tuile {

// How many interfaces one ray may pass before it is dropped (counted as rejected).
inline constexpr int max_interface_crossings = 64;

// The far end of a ray's stretch of medium that meets nothing (MediumLanes::eq_b).
inline constexpr float segment_far = 1e30f;

namespace media_detail {

inline float expn(float x) { return lane_math::exp_nonpositive(x); }  // e^x, x <= 0 (-inf: 0)

// e^(-sigma * d) with 0 * inf = 0 (a channel that does not extinguish transmits 1).
inline float transmit(float sigma, float d) { return sigma > 0.f ? expn(-sigma * d) : 1.f; }

// Where a ray (lane l of packet r) that hit an interface at distance t goes on: the medium
// of the side it enters, and its new origin just past the surface.
inline void cross_interface(const GeomView& G, RayHit16& r, int l, float t, int32_t& med) {
  const int32_t g = static_cast<int32_t>(r.geomID[l]);
  const Vec3<float> o{r.ray.org_x[l], r.ray.org_y[l], r.ray.org_z[l]};
  const Vec3<float> d{r.ray.dir_x[l], r.ray.dir_y[l], r.ray.dir_z[l]};
  Vec3<float> ng{r.Ng_x[l], r.Ng_y[l], r.Ng_z[l]};
  const float len2 = dot(ng, ng);
  ng = len2 > 0.f ? ng * (1.f / std::sqrt(len2)) : d;
  // pbrt's outside: the side of a mesh's interpolated vertex normals where it has them
  // (as apply_shading_normals decides a point's side), else Embree's Ng times the
  // geometry's side (reverse orientation)
  Vec3<float> out = ng * G.geom_side[g];
  if (const float* N = G.normals[g]) {
    const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(r.primID[l]);
    const float b1 = r.u[l], b2 = r.v[l], b0 = 1.f - b1 - b2;
    const Vec3<float> ni{b0 * N[3 * idx[0]] + b1 * N[3 * idx[1]] + b2 * N[3 * idx[2]],
                         b0 * N[3 * idx[0] + 1] + b1 * N[3 * idx[1] + 1] + b2 * N[3 * idx[2] + 1],
                         b0 * N[3 * idx[0] + 2] + b1 * N[3 * idx[1] + 2] + b2 * N[3 * idx[2] + 2]};
    if (dot(ni, ni) > 1e-20f) out = ni;
  }
  const bool entering = dot(out, d) < 0.f;
  med = entering ? G.media.geom_in[g] : G.media.geom_out[g];
  const HitGeometry<float> h = hit_geometry_lanes<float>(G, r, l, true, 1u, g, o, d, t, InstanceLanes<float>{});
  const Vec3<float> n = dot(ng, d) < 0.f ? Vec3<float>(0.f, 0.f, 0.f) - ng : ng;  // the side the ray leaves by
  const Vec3<float> x = h.x + n * offset_along_normal(h.err, n);
  r.ray.org_x[l] = x.x;
  r.ray.org_y[l] = x.y;
  r.ray.org_z[l] = x.z;
  r.ray.tfar[l] = 3.0e38f;
  r.geomID[l] = invalid_id;
}

// medium_flights where the media only absorb and no surface is an interface
// (MediumView::absorb_only): every ray stops at its hit, its weight its origin medium's
// transmittance to it (none: the weight of a flight through no medium). The scalar rounds'
// operations for such a ray (the absorbing branch with nothing before it, then the weight
// of a flight that passed), in SIMD: the same bits; lanes not traced, or past count, get
// the weight 1 as there.
inline void absorbing_flights(const MediumView& M, const RayHit16* packets, const int32_t* valid, int count, MediumLanes& ml) {
  using T = vfloat;
  using I = vint;
  const float e0 = expn(-0.f);
  const float pass0 = (e0 + e0 + e0) * (1.f / 3.f);
  const float inv0 = pass0 > 0.f ? 1.f / pass0 : 0.f;
  const float w0 = e0 * inv0;  // no medium
  float* w[3] = {ml.wr, ml.wg, ml.wb};
  float* e[3] = {ml.er, ml.eg, ml.eb};
  for (int p = 0; p < packets_for(count); ++p) {
    const RayHit16& r = packets[p];
    for (int l0 = 0; l0 < packet_width; l0 += simd_width) {
      const int k = p * packet_width + l0;
      const vmask traced = f_mask_from_i((load_i32<T>(valid + k) != I(0)) && (lane_iota_i32<T>() + I(k) < I(count)));
      const I m = load_i32<T>(ml.med + k);
      const vmask in = traced && f_mask_from_i(m >= I(0));
      const vmask hit = f_mask_from_i(load_i32<T>(reinterpret_cast<const int32_t*>(r.geomID) + l0) != I(static_cast<int32_t>(invalid_id)));
      const T t = sel(hit, load<T>(r.ray.tfar + l0), T(INFINITY));
      const I ms = sel(i_mask_from_f(in), m, I(0));
      for (int c = 0; c < 3; ++c) {
        const T st = gather(M.sigma_t[c], ms);
        const T tr = sel(st > T(0.f), lane_math::exp_nonpositive(-st * t), T(1.f));
        store(w[c] + k, sel(in, T(1.f) * tr * T(e0) * T(inv0), sel(traced, T(w0), T(1.f))));
        store(e[c] + k, T(0.f));
      }
      store(ml.eq_med + k, I(-1));
      store(ml.pending + k, I(0));
    }
  }
}

// The first round of medium_flights for the lanes [l0, l0 + simd_width) of packet r (tile
// lanes from k0) that start in a medium that scatters and whose hit, if any, is not an
// interface (pending and ml.med >= 0 on entry; count bounds the lanes): each flight ends in
// this round, at a collision or at the hit (or nowhere), as the scalar round computes it,
// operation for operation, so every lane has the scalar bits. The other lanes are left as
// they were, pending, for the scalar rounds.
inline void first_flights_simd(const GeomView& G, RayHit16& r, int l0, int k0, int count, MediumLanes& ml) {
  using T = vfloat;
  using I = vint;
  const MediumView& M = G.media;
  const int k = k0 + l0;
  const I lane = lane_iota_i32<T>() + I(k);
  const I m = load_i32<T>(ml.med + k);
  const I g = load_i32<T>(reinterpret_cast<const int32_t*>(r.geomID + l0));
  const auto hit_i = g != I(-1);
  const auto in_med = m >= I(0);
  const I ms = sel(in_med, m, I(0));
  const auto pending_i = (load_i32<T>(ml.pending + k) != I(0)) && (lane < I(count)) && in_med;
  if (none(f_mask_from_i(pending_i))) return;
  const auto interface_i = hit_i && (gather(M.geom_interface, sel(hit_i, g, I(0))) != I(0));
  const auto scatters_i = gather(M.scatters, ms) != I(0);
  const vmask mine = f_mask_from_i(pending_i && scatters_i && !interface_i);
  if (none(mine)) return;
  const vmask hit = f_mask_from_i(hit_i);
  const T t = sel(hit, load<T>(r.ray.tfar + l0), T(INFINITY));
  const T st[3] = {gather(M.sigma_t[0], ms), gather(M.sigma_t[1], ms), gather(M.sigma_t[2], ms)};
  const I hero = load_i32<T>(ml.hero + k);
  const T sh = sel(f_mask_from_i(hero == I(0)), st[0], sel(f_mask_from_i(hero == I(1)), st[1], st[2]));
  const T tau = load<T>(ml.tau + k);
  const vmask scattered = mine && (sh > T(0.f)) && (tau < sh * t);
  const vmask passed = mine && !scattered;
  const T ts = tau / sh;
  T E[3];
  for (int c = 0; c < 3; ++c) {
    const T od = sel(scattered, T(0.f) + st[c] * ts, sel(st[c] > T(0.f), T(0.f) + st[c] * t, T(0.f)));
    E[c] = lane_math::exp_nonpositive(-od);
  }
  // a collision: the weight tr sigma_s / pdf and the emission tr sigma_a Le / pdf
  T pdf = T(0.f);
  for (int c = 0; c < 3; ++c) pdf += st[c] * E[c];
  pdf *= T(1.f / 3.f);
  const T inv_s = sel(pdf > T(0.f), T(1.f) / pdf, T(0.f));
  // the hit (or nowhere): the weight tr / P(flight this far)
  T pass = T(0.f);
  for (int c = 0; c < 3; ++c) pass += E[c];
  pass *= T(1.f / 3.f);
  const T inv_p = sel(pass > T(0.f), T(1.f) / pass, T(0.f));
  const vmask emits = scattered && f_mask_from_i(gather(M.emits, ms) != I(0));
  float* w[3] = {ml.wr + k, ml.wg + k, ml.wb + k};
  float* e[3] = {ml.er + k, ml.eg + k, ml.eb + k};
  for (int c = 0; c < 3; ++c) {
    const T tr = E[c] * T(1.f);
    const T ws = tr * gather(M.sigma_s[c], ms) * inv_s;
    const T wp = T(1.f) * E[c] * inv_p;
    store(w[c], sel(scattered, ws, sel(passed, wp, load<T>(w[c]))));
    const T old_e = load<T>(e[c]);
    store(e[c], sel(emits, old_e + tr * gather(M.emit[c], ms) * inv_s, old_e));
  }
  // a collision becomes a hit of the medium's row at it; the ray as it left its origin
  const auto scattered_i = i_mask_from_f(scattered);
  store(reinterpret_cast<int32_t*>(r.geomID + l0), sel(scattered_i, I(M.geom0) + ms, g));
  store(reinterpret_cast<int32_t*>(r.primID + l0), sel(scattered_i, I(0), load_i32<T>(reinterpret_cast<const int32_t*>(r.primID + l0))));
  store(r.u + l0, sel(scattered, T(0.f), load<T>(r.u + l0)));
  store(r.v + l0, sel(scattered, T(0.f), load<T>(r.v + l0)));
  store(r.Ng_x + l0, sel(scattered, -load<T>(r.ray.dir_x + l0), load<T>(r.Ng_x + l0)));
  store(r.Ng_y + l0, sel(scattered, -load<T>(r.ray.dir_y + l0), load<T>(r.Ng_y + l0)));
  store(r.Ng_z + l0, sel(scattered, -load<T>(r.ray.dir_z + l0), load<T>(r.Ng_z + l0)));
  store(r.ray.tfar + l0, sel(scattered, T(0.f) + ts, load<T>(r.ray.tfar + l0)));
  store(ml.pending + k, sel(i_mask_from_f(mine), I(0), load_i32<T>(ml.pending + k)));
  // the ray's first stretch of scattering medium: from its origin to its hit
  const auto mine_i = i_mask_from_f(mine);
  store(ml.eq_med + k, sel(mine_i, m, load_i32<T>(ml.eq_med + k)));
  store(ml.eq_a + k, sel(mine, T(0.f), load<T>(ml.eq_a + k)));
  store(ml.eq_b + k, sel(mine, min(t, T(segment_far)), load<T>(ml.eq_b + k)));
}

}  // namespace media_detail

// The medium a bounce ray of shading point k starts in (-1: vacuum): that of the side of
// the point it leaves by.
inline int32_t bounce_ray_medium(const TileBuffers& tb, int k) {
  const RayHit16& r = tb.bounce[k / packet_width];
  const int l = k % packet_width;
  const float side = tb.points.nx[k] * r.ray.dir_x[l] + tb.points.ny[k] * r.ray.dir_y[l] + tb.points.nz[k] * r.ray.dir_z[l];
  return side >= 0.f ? tb.points.medf[k] : tb.points.medb[k];
}

// Bounce rays against the emitters in a scene with media and no "interface" surfaces: of
// the rays of paths that end (TechniqueSample::ends), those that start in a medium need
// their nearest hit in the scene (their flight decides what they reach) and are unmarked;
// a ray that starts in vacuum meets a surface before any medium.
inline void ends_in_vacuum(TileBuffers& tb) {
  for (int k = 0; k < tb.points.count; ++k)
    if (tb.tech.ends[k] && bounce_ray_medium(tb, k) >= 0) tb.tech.ends[k] = 0;
}

// The flights of rays [0, count) of the packets (valid[k] != 0: traced), each in medium
// ml.med[k] at its origin, with ml.u0 / ml.u1 its random numbers. Afterwards each traced
// ray's hit is where its path goes on: a surface (interfaces passed), a scattering point
// (GeomKind::medium, the ray's tfar its distance) or none; its origin and tfar are the
// original origin's (interfaces passed leave the direction as it was); ml.w* is the weight
// of what happened (per channel), ml.e* the emission gathered on the way (to multiply by
// the throughput at the origin), ml.med the medium at the hit. trace(valid, packet)
// re-traces the lanes that passed an interface. Rays dropped (too many interfaces) get
// valid 0, counted in rejected.
template <bool Simd = true, class Trace>
inline void medium_flights(const GeomView& G, RayHit16* packets, int32_t* valid, int count, MediumLanes& ml,
                           uint64_t& rejected, Trace&& trace) {
  using namespace media_detail;
  const MediumView& M = G.media;
  if constexpr (Simd)
    if (M.absorb_only) return absorbing_flights(M, packets, valid, count, ml);
  // the weight of a flight that met no medium (the general rule below with no optical
  // depth: the same bits), for the rays that start in none and stop at their first hit
  const float pass0 = (expn(-0.f) + expn(-0.f) + expn(-0.f)) * (1.f / 3.f);
  const float w0 = expn(-0.f) * (pass0 > 0.f ? 1.f / pass0 : 0.f);
  // every ray's optical depth to its collision and hero channel, in SIMD (the log of the
  // rays that never need it costs less than a branch per ray); the scalar bits
  int k1 = 0;
  for (; k1 + simd_width <= count; k1 += simd_width) {
    const vfloat u1 = load<vfloat>(ml.u1 + k1), u0 = load<vfloat>(ml.u0 + k1);
    store(ml.tau + k1, -lane_math::log_positive(max(vfloat(1.f) - u1, vfloat(1e-30f))));
    store(ml.hero + k1, min(to_i32(u0 * vfloat(3.f)), vint(2)));
  }
  for (int k = k1; k < count; ++k) {
    ml.tau[k] = -lane_math::log_positive(std::max(1.f - ml.u1[k], 1e-30f));
    ml.hero[k] = std::min(static_cast<int>(ml.u0[k] * 3.f), 2);
  }
  bool any = false;
  for (int k = 0; k < count; ++k) {
    ml.wr[k] = ml.wg[k] = ml.wb[k] = 1.f;
    ml.er[k] = ml.eg[k] = ml.eb[k] = 0.f;
    ml.eq_med[k] = -1;
    ml.pending[k] = valid[k] != 0;
    if (!ml.pending[k]) continue;
    const RayHit16& r = packets[k / packet_width];
    const int l = k % packet_width;
    if (ml.med[k] < 0 && (r.geomID[l] == invalid_id || !M.geom_interface[r.geomID[l]])) {
      ml.wr[k] = ml.wg[k] = ml.wb[k] = w0;
      ml.pending[k] = 0;
      continue;
    }
    any = true;
    for (int c = 0; c < 3; ++c) ml.od[c][k] = 0.f, ml.absorb[c][k] = 1.f;
    ml.ox[k] = r.ray.org_x[l];
    ml.oy[k] = r.ray.org_y[l];
    ml.oz[k] = r.ray.org_z[l];
    ml.tbase[k] = 0.f;
  }
  // the flights that end in their first round without an interface, in SIMD
  if (Simd && any)
    for (int p = 0; p < packets_for(count); ++p)
      for (int l0 = 0; l0 < packet_width; l0 += simd_width) first_flights_simd(G, packets[p], l0, p * packet_width, count, ml);
  for (int round = 0; any; ++round) {
    bool again = false;
    for (int k = 0; k < count; ++k) {
      if (!ml.pending[k]) continue;
      RayHit16& r = packets[k / packet_width];
      const int l = k % packet_width;
      const bool hit = r.geomID[l] != invalid_id;
      const float t = hit ? r.ray.tfar[l] : INFINITY;
      const int32_t m = ml.med[k];
      float* od[3] = {&ml.od[0][k], &ml.od[1][k], &ml.od[2][k]};
      float* ab[3] = {&ml.absorb[0][k], &ml.absorb[1][k], &ml.absorb[2][k]};
      float* e[3] = {&ml.er[k], &ml.eg[k], &ml.eb[k]};
      bool scattered = false;
      float ts = t;
      if (m >= 0) {
        const float st[3] = {M.sigma_t[0][m], M.sigma_t[1][m], M.sigma_t[2][m]};
        if (M.scatters[m]) {
          // the ray's first stretch of scattering medium, where only vacuum came before
          if (ml.eq_med[k] < 0 && *ab[0] == 1.f && *ab[1] == 1.f && *ab[2] == 1.f) {
            ml.eq_med[k] = m;
            ml.eq_a[k] = ml.tbase[k];
            ml.eq_b[k] = std::min(ml.tbase[k] + t, segment_far);
          }
          const float sh = st[ml.hero[k]];
          if (sh > 0.f && ml.tau[k] < sh * t) {  // (sh * inf = inf)
            scattered = true;
            ts = ml.tau[k] / sh;
            for (int c = 0; c < 3; ++c) *od[c] += st[c] * ts;
          } else {
            if (sh > 0.f) ml.tau[k] -= sh * t;
            for (int c = 0; c < 3; ++c) *od[c] = st[c] > 0.f ? *od[c] + st[c] * t : *od[c];
          }
          if (scattered) {
            float tr[3], pdf = 0.f;
            for (int c = 0; c < 3; ++c) {
              tr[c] = expn(-*od[c]) * *ab[c];
              pdf += st[c] * expn(-*od[c]);
            }
            pdf *= 1.f / 3.f;
            const float inv = pdf > 0.f ? 1.f / pdf : 0.f;
            ml.wr[k] = tr[0] * M.sigma_s[0][m] * inv;
            ml.wg[k] = tr[1] * M.sigma_s[1][m] * inv;
            ml.wb[k] = tr[2] * M.sigma_s[2][m] * inv;
            if (M.emits[m])  // pbrt-v4's collision estimator of sigma_a Le
              for (int c = 0; c < 3; ++c) *e[c] += tr[c] * M.emit[c][m] * inv;
          }
        } else {
          // absorption alone: transmittance (and emission) in closed form
          float reach = 0.f;  // the probability that the flight came this far
          for (int c = 0; c < 3; ++c) reach += expn(-*od[c]);
          reach *= 1.f / 3.f;
          for (int c = 0; c < 3; ++c) {
            const float tr = transmit(st[c], t);
            if (M.emits[m] && st[c] > 0.f && reach > 0.f)
              *e[c] += *ab[c] * expn(-*od[c]) / reach * M.emit[c][m] * (1.f - tr) / st[c];
            *ab[c] *= tr;
          }
        }
      }
      if (scattered) {
        // the hit of the medium's row, at the collision; the ray as it left its origin
        const float dx = r.ray.dir_x[l], dy = r.ray.dir_y[l], dz = r.ray.dir_z[l];
        r.geomID[l] = static_cast<uint32_t>(M.geom0 + m);
        r.primID[l] = 0;
        r.u[l] = r.v[l] = 0.f;
        r.Ng_x[l] = -dx;
        r.Ng_y[l] = -dy;
        r.Ng_z[l] = -dz;
        r.ray.tfar[l] = ml.tbase[k] + ts;
        r.ray.org_x[l] = ml.ox[k];
        r.ray.org_y[l] = ml.oy[k];
        r.ray.org_z[l] = ml.oz[k];
        ml.pending[k] = 0;
        continue;
      }
      if (hit && M.geom_interface[r.geomID[l]]) {
        if (round + 1 >= max_interface_crossings) {
          valid[k] = 0;
          ++rejected;
          r.geomID[l] = invalid_id;
          ml.wr[k] = ml.wg[k] = ml.wb[k] = 0.f;
          ml.pending[k] = 0;
          continue;
        }
        int32_t next = -1;
        cross_interface(G, r, l, t, next);
        ml.med[k] = next;
        ml.tbase[k] += t;
        again = true;
        continue;
      }
      // a surface, or nothing: the flight passed every medium on the way
      float pass = 0.f;
      for (int c = 0; c < 3; ++c) pass += expn(-*od[c]);
      pass *= 1.f / 3.f;
      const float inv = pass > 0.f ? 1.f / pass : 0.f;
      ml.wr[k] = ml.absorb[0][k] * expn(-*od[0]) * inv;
      ml.wg[k] = ml.absorb[1][k] * expn(-*od[1]) * inv;
      ml.wb[k] = ml.absorb[2][k] * expn(-*od[2]) * inv;
      if (ml.tbase[k] > 0.f) {
        r.ray.org_x[l] = ml.ox[k];
        r.ray.org_y[l] = ml.oy[k];
        r.ray.org_z[l] = ml.oz[k];
        if (hit) r.ray.tfar[l] = ml.tbase[k] + t;
      }
      ml.pending[k] = 0;
    }
    if (!again) break;
    alignas(64) int32_t v[packet_width];
    for (int p = 0; p < packets_for(count); ++p) {
      bool some = false;
      for (int l = 0; l < packet_width; ++l) {
        const int k = p * packet_width + l;
        v[l] = k < count && ml.pending[k] ? -1 : 0;
        some = some || v[l];
      }
      if (some) trace(v, packets[p]);
    }
  }
}

// A set of shadow rays for the media's stages: the packets, which lanes were traced, each
// lane's contribution (times the transmittance when unoccluded) and the media at the
// rays' origins: medf on the side of the origin's geometric normal n, medb behind it (n
// null: medf, a point in a medium). The light stage's (shadow_lanes) and the segment light
// samples' (wave/equiangular.h).
struct ShadowLanes {
  Ray16* rays;
  const int32_t* valid;
  float *cr, *cg, *cb;
  const float *nx, *ny, *nz;
  const int32_t *medf, *medb;
};

// The light stage's shadow rays: tb.shadow from the shading points.
inline ShadowLanes shadow_lanes(TileBuffers& tb) {
  return {tb.shadow, tb.tech.valid, tb.tech.cr, tb.tech.cg, tb.tech.cb, tb.points.nx, tb.points.ny, tb.points.nz,
          tb.points.medf, tb.points.medb};
}

namespace media_detail {

// The shadow rays of packet p in lanes [l0, l0 + simd_width) where lanes is set, after an
// occlusion query in which no surface but those rays pass between media could stop them,
// and which met none of those: an occluded one's (Embree's tfar -inf) contribution is 0;
// another ran in the medium at its origin alone (by its point's geometric normal), whose
// transmittance over its length multiplies its contribution. In SIMD, the operations of
// shadow_walk's single segment in order: the same bits.
inline void shadow_one_medium(const MediumView& M, const ShadowLanes& S, int p, int l0, const vmask& lanes) {
  using T = vfloat;
  using I = vint;
  Ray16& s = S.rays[p];
  const int k = p * packet_width + l0;
  const T tfar = load<T>(s.tfar + l0);
  const vmask occluded = lanes && (tfar == T(-INFINITY));
  const T side = S.nx ? load<T>(S.nx + k) * load<T>(s.dir_x + l0) + load<T>(S.ny + k) * load<T>(s.dir_y + l0) +
                            load<T>(S.nz + k) * load<T>(s.dir_z + l0)
                      : T(0.f);
  const I m = sel(i_mask_from_f(side >= T(0.f)), load_i32<T>(S.medf + k), load_i32<T>(S.medb + k));
  const vmask in = lanes && !occluded && f_mask_from_i(m >= I(0));
  if (none(in) && none(occluded)) return;
  const I ms = sel(i_mask_from_f(in), m, I(0));
  T tr[3];
  for (int c = 0; c < 3; ++c) {
    const T st = gather(M.sigma_t[c], ms);
    tr[c] = sel(st > T(0.f), lane_math::exp_nonpositive(-st * tfar), T(1.f));
  }
  float* contribution[3] = {S.cr + k, S.cg + k, S.cb + k};
  for (int c = 0; c < 3; ++c) {
    const T old = load<T>(contribution[c]);
    store(contribution[c], sel(occluded, T(0.f), sel(in, old * tr[c], old)));
  }
  const vmask dark = in && !(tr[0] + tr[1] + tr[2] > T(0.f));
  store(s.tfar + l0, sel(dark, T(-INFINITY), tfar));
}

// The lanes of [l0, l0 + simd_width) of packet p whose flag is set, below count.
inline vmask flagged_lanes(const int32_t* flags, int p, int l0, int count) {
  const vint lane = lane_iota_i32<vfloat>() + vint(p * packet_width + l0);
  return f_mask_from_i((load_i32<vfloat>(flags + l0) != vint(0)) && (lane < vint(count)));
}

// The shadow rays of packet p whose lanes[l] is set, walked through the media: each
// starts in the medium on its side of its point (medf / medb by the geometric normal),
// passes the surfaces rays pass between media (taking the medium of the side it enters)
// and multiplies its contribution (tb.tech.c*) by the transmittance of every segment; any
// other surface occludes it (tfar = -inf, as Embree marks occlusion). trace(valid,
// packet): nearest hits in the scene.
template <class Trace>
inline void shadow_walk(const GeomView& G, const ShadowLanes& S, int p, const int32_t* lanes, Trace&& trace) {
  const MediumView& M = G.media;
  alignas(64) RayHit16 q{};
  reset_query_fields(q);
  alignas(64) int32_t v[packet_width];
  int32_t med[packet_width];
  float T[3][packet_width], left[packet_width];
  Ray16& s = S.rays[p];
  bool some = false;
  for (int l = 0; l < packet_width; ++l) {
    const int k = p * packet_width + l;
    v[l] = lanes[l] ? -1 : 0;
    if (!v[l]) continue;
    some = true;
    q.ray.org_x[l] = s.org_x[l];
    q.ray.org_y[l] = s.org_y[l];
    q.ray.org_z[l] = s.org_z[l];
    q.ray.dir_x[l] = s.dir_x[l];
    q.ray.dir_y[l] = s.dir_y[l];
    q.ray.dir_z[l] = s.dir_z[l];
    q.ray.tfar[l] = s.tfar[l];
    left[l] = s.tfar[l];
    q.geomID[l] = invalid_id;
    const float side = S.nx ? S.nx[k] * s.dir_x[l] + S.ny[k] * s.dir_y[l] + S.nz[k] * s.dir_z[l] : 0.f;
    med[l] = side >= 0.f ? S.medf[k] : S.medb[k];
    T[0][l] = T[1][l] = T[2][l] = 1.f;
  }
  for (int round = 0; some; ++round) {
    trace(v, q);
    some = false;
    for (int l = 0; l < packet_width; ++l) {
      if (!v[l]) continue;
      const bool hit = q.geomID[l] != invalid_id;
      const float t = hit ? q.ray.tfar[l] : left[l];
      if (med[l] >= 0)
        for (int c = 0; c < 3; ++c) T[c][l] *= transmit(M.sigma_t[c][med[l]], t);
      if (hit && M.geom_interface[q.geomID[l]] && round + 1 < max_interface_crossings) {
        cross_interface(G, q, l, t, med[l]);
        left[l] -= t;
        q.ray.tfar[l] = left[l];
        some = true;
        continue;
      }
      if (hit) T[0][l] = T[1][l] = T[2][l] = 0.f;
      v[l] = 0;
      const int k = p * packet_width + l;
      S.cr[k] *= T[0][l];
      S.cg[k] *= T[1][l];
      S.cb[k] *= T[2][l];
      s.tfar[l] = T[0][l] + T[1][l] + T[2][l] > 0.f ? s.tfar[l] : -INFINITY;
    }
  }
}

}  // namespace media_detail

// The shadow rays of a scene with media but no surface rays pass between media
// (MediumView::has_interfaces false), after their occlusion queries: every surface
// occludes, so an unoccluded ray runs in the medium at its origin alone
// (media_detail::shadow_one_medium, in SIMD). The numbers of walking the same rays.
inline void shadow_transmittance(const GeomView& G, const ShadowLanes& S, int count) {
  for (int p = 0; p < packets_for(count); ++p)
    for (int l0 = 0; l0 < packet_width; l0 += simd_width)
      media_detail::shadow_one_medium(G.media, S, p, l0, media_detail::flagged_lanes(S.valid + p * packet_width, p, l0, count));
}

// The shadow rays of the shading points [0, count) (valid lanes, tb.shadow) of a scene
// with surfaces rays pass between media: first an occlusion query per packet in which
// those surfaces do not occlude but mark the rays that meet them (occlude(valid, packet,
// crossed), crossed by the packet's ray ids, which this sets to the lanes); an occluded
// ray's contribution is 0, an unoccluded one that met none runs in the medium at its
// origin alone, and only the rest are walked through the media (shadow_walk, trace(valid,
// packet): nearest hits). The same numbers as walking every ray, at the cost of an
// occlusion query for the rays that stay in one medium (most, where the interfaces bound
// a room or a volume the lights are inside).
template <class Occlude, class Trace>
inline void shadow_media(const GeomView& G, const ShadowLanes& S, int count, Occlude&& occlude, Trace&& trace) {
  for (int p = 0; p < packets_for(count); ++p) {
    const int32_t* valid = S.valid + p * packet_width;
    bool any = false;
    for (int l = 0; l < packet_width; ++l) any = any || valid[l];
    if (!any) continue;
    Ray16& s = S.rays[p];
    alignas(64) int32_t crossed[packet_width] = {}, walk[packet_width] = {};
    for (int l = 0; l < packet_width; ++l) s.id[l] = static_cast<uint32_t>(l);
    occlude(valid, s, crossed);
    alignas(64) int32_t one[packet_width];
    bool some = false;
    for (int l = 0; l < packet_width; ++l) {
      walk[l] = valid[l] && crossed[l] && s.tfar[l] != -INFINITY;
      one[l] = valid[l] && !walk[l];
      some = some || walk[l];
    }
    for (int l0 = 0; l0 < packet_width; l0 += simd_width)
      media_detail::shadow_one_medium(G.media, S, p, l0, media_detail::flagged_lanes(one, p, l0, count));
    if (some) media_detail::shadow_walk(G, S, p, walk, trace);
  }
}

// The shadow rays of the shading points [0, count) (tb.shadow, valid lanes tb.tech.valid) in
// any scene: occlusion queries (occlude(valid, packet, crossed), crossed null where no surface
// rays pass between media), then the media's transmittance where the scene has media
// (shadow_media where some surface is an interface, else shadow_transmittance). An occluded
// ray's tfar is -inf; a contribution (tb.tech.c*) carries its transmittance. trace(valid,
// packet): nearest hits in the scene. The tile pipelines' shadow stage and the light tracer's
// rays to the camera (src/render/light_paths.cpp).
template <class Occlude, class Trace>
inline void trace_shadow_lanes(const GeomView& G, const ShadowLanes& S, int count, Occlude&& occlude, Trace&& trace) {
  if (G.has_media && G.media.has_interfaces) {
    shadow_media(G, S, count, occlude, trace);
    return;
  }
  for (int p = 0; p < packets_for(count); ++p) occlude(S.valid + p * packet_width, S.rays[p], nullptr);
  if (G.has_media) shadow_transmittance(G, S, count);
}
template <class Occlude, class Trace>
inline void trace_shadow_rays(const GeomView& G, TileBuffers& tb, int count, Occlude&& occlude, Trace&& trace) {
  trace_shadow_lanes(G, shadow_lanes(tb), count, occlude, trace);
}

// Every valid shadow ray of [0, count) walked through the media (shadow_walk), with no
// occlusion query first: the reference the tests hold shadow_media to.
template <class Trace>
inline void shadow_media_walked(const GeomView& G, TileBuffers& tb, int count, Trace&& trace) {
  for (int p = 0; p < packets_for(count); ++p) {
    int32_t lanes[packet_width];
    for (int l = 0; l < packet_width; ++l) {
      const int k = p * packet_width + l;
      lanes[l] = k < count && tb.tech.valid[k] ? 1 : 0;
    }
    media_detail::shadow_walk(G, shadow_lanes(tb), p, lanes, trace);
  }
}

}  // namespace tuile
