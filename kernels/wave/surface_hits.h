// Stage 2b, camera hits: turns the camera packets Embree filled into compacted shading
// points (position, facing normal, albedo, ray offset, pixel, lane), adds the radiance
// of emitters seen directly, and draws the one-sample MIS technique choice.
// Reads: camera packets, geometry/material/light tables (triangles flattened by
// build_views). Writes: shading point arrays, tile radiance, rejected_camera. SIMD per
// lane with compress stores; only texture lookups (textures.h), shading normals and bump
// mapping (shading_normals.h: pbrt-v4's BumpMap) stay scalar.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <type_traits>

#include "wave/hair_frames.h"
#include "wave/instances.h"
#include "wave/shading_normals.h"
#include "wave/textures.h"
#include "wave/tile.h"
#include "lanes/vec.h"

namespace tuile {

// The light a ray hit, or -1.
inline int32_t light_of_hit(const GeomView& G, uint32_t geom, uint32_t prim) {
  if (geom == invalid_id) return -1;
  const auto g = static_cast<int32_t>(geom);
  if (is_mesh(G, g)) return G.tri_light[G.geom_first[g] + static_cast<int32_t>(prim)];
  return G.geom_light[g];
}

// Ray offset for a surface point: the per-axis error bound of the point projected on the
// normal (pbrt-v4's OffsetRayOrigin), never zero so the new ray starts off the plane.
template <class T> inline T offset_along_normal(const Vec3<T>& err, const Vec3<T>& n) {
  return abs(n.x) * err.x + abs(n.y) * err.y + abs(n.z) * err.z + T(1e-30f);
}

// The camera hits of a batch that meet a texture are listed for apply_texels (their
// vertex indices prefetched); the texels are applied once every batch of the tile is done.
inline void list_textured_points(const GeomView& G, const RayHit16& p, int l, uint32_t keep, int n, TileBuffers& tb) {
  int m = n;
  for (uint32_t bits = keep; bits; bits &= bits - 1, ++m) {
    const int k = std::countr_zero(bits);
    const uint32_t geom = p.geomID[l + k], prim = p.primID[l + k];
    const int32_t t = hit_texture(G, geom);
    if (t < 0) continue;
    __builtin_prefetch(G.indices[geom] + 3 * prim);
    const int j = tb.textured.count++;
    tb.textured.point[j] = m;
    tb.textured.texture[j] = t;
    tb.textured.geom[j] = geom;
    tb.textured.prim[j] = prim;
    tb.textured.u[j] = p.u[l + k];
    tb.textured.v[j] = p.v[l + k];
  }
}

// The cached stream keys of the shading pairs, for the points [n, n + popcount(keep)) made
// from lanes [i, i + width): while every lane so far is a shading point (point k is lane
// k) the points read the lanes' keys; from the first lane that is not, they are copied and
// then compacted.
template <class T> inline void compact_point_keys(TileBuffers& tb, uint32_t keep, int n, int i) {
  if (tb.keys.keyed & ~1u) {  // (camera hits only: no later vertex reads a cached key)
    constexpr uint32_t all = lane_traits<T>::width == 32 ? ~0u : (1u << lane_traits<T>::width) - 1u;
    if (tb.keys.points_are_lanes && !(keep == all && n == i)) {
      for (uint32_t bits = tb.keys.keyed & ~1u; bits; bits &= bits - 1)
        for (int f = 0; f < 3; ++f)
          std::copy_n(tb.keys.lane_key[std::countr_zero(bits)][f], n, tb.keys.point_key[std::countr_zero(bits)][f]);
      tb.keys.points_are_lanes = false;
    }
    if (!tb.keys.points_are_lanes)
      for (uint32_t bits = tb.keys.keyed & ~1u; bits; bits &= bits - 1) {
        const int p = std::countr_zero(bits);
        for (int f = 0; f < 3; ++f)
          compress_store(reinterpret_cast<int32_t*>(tb.keys.point_key[p][f] + n),
                         load_i32<T>(reinterpret_cast<const int32_t*>(tb.keys.lane_key[p][f] + i)), keep);
      }
  }
}

// The radiance of the emitters the camera sees directly (light: each lane's light or -1),
// added to the lanes [i, i + width) where the ray meets their emitting side.
template <class T>
inline void add_seen_emission(const LightView& L, const i32_t<T>& light, const Vec3<T>& o, const Vec3<T>& d, int i,
                              TileBuffers& tb) {
  const auto lit = f_mask_from_i(light >= i32_t<T>(0));
  if (any(lit)) {  // then the light table is not empty
    const i32_t<T> li = max(light, i32_t<T>(0));
    const auto emit = lit && light_front_lanes<T>(L, li, o, d);
    with_table_tier(L, [&](auto tier) {
      constexpr int S = decltype(tier)::value;
      T Le_r, Le_g, Le_b;
      lookup_radiance<S>(L, li, Le_r, Le_g, Le_b);
      store(tb.lanes.Lr + i, sel(emit, load<T>(tb.lanes.Lr + i) + Le_r, load<T>(tb.lanes.Lr + i)));
      store(tb.lanes.Lg + i, sel(emit, load<T>(tb.lanes.Lg + i) + Le_g, load<T>(tb.lanes.Lg + i)));
      store(tb.lanes.Lb + i, sel(emit, load<T>(tb.lanes.Lb + i) + Le_b, load<T>(tb.lanes.Lb + i)));
    });
  }
}

// Where the lanes' rays hit (lanes `ok` of packet p from lane l; keep = lane_bits(ok)): the
// point and its per-axis error bound by the geometry table's kind of each hit, and what the
// rest of the stage reads of it. This is where a new kind of geometry computes its point.
// The hit point and its error bound (pbrt-v4): for triangles from the barycentrics,
// err_i = gamma(7) sum_k |b_k v_k,i|, so an axis-aligned plane at any distance keeps an
// exact coordinate; for spheres reprojected onto the surface (see below).
template <class T> struct HitGeometry {
  Vec3<T> x, err;
  mask_t<T> triangle, sphere, curve;  // the lanes' kinds
  mask_t<T> flat_curve;               // curves facing the ray (Ng is their tangent)
  i32_t<T> tri;                // the flattened triangle (0 where the lane hit another kind)
  bool one_geom, one_tri;      // every lane hit geometry g0 (triangle t0): broadcasts, not gathers
  int32_t g0, t0;
};
template <class T>
TUILE_FLATTEN inline HitGeometry<T> hit_geometry_lanes(const GeomView& G, const RayHit16& p, int l, const mask_t<T>& ok,
                                                       uint32_t keep, const i32_t<T>& geom, const Vec3<T>& ow,
                                                       const Vec3<T>& dw, const T& t, const InstanceLanes<T>& in) {
  HitGeometry<T> h;
  // an instance's lanes: the ray in its object's space, where its rows are (Embree's t is
  // the same along the ray placed by object_from_world: the point is placed back at the end)
  const bool any_inst = G.has_instances && any(in.on);
  Vec3<T> o = ow, d = dw;
  if (any_inst) {
    o = sel(in.on, instance_apply<T>(G.inst_inv, in.m12, ow, true), ow);
    d = sel(in.on, instance_apply<T>(G.inst_inv, in.m12, dw, false), dw);
  }
  const i32_t<T> gi = max(geom, i32_t<T>(0));
  const i32_t<T> prim = load_i32<T>(reinterpret_cast<const int32_t*>(p.primID + l));
  // Coherent camera rays often hit one geometry, even one triangle, in every lane: then
  // broadcasts of the first hit's data replace the gathers (same values). Lanes without
  // a triangle read triangle 0.
  const int k0 = std::countr_zero(keep);
  const int32_t g0 = static_cast<int32_t>(p.geomID[l + k0]), p0 = static_cast<int32_t>(p.primID[l + k0]);
  const bool one_geom = all(!ok || f_mask_from_i(geom == i32_t<T>(g0)));
  // the geometry table's kind of each lane's hit
  const i32_t<T> kind = one_geom ? i32_t<T>(G.geom_kind[g0]) : gather(G.geom_kind, gi);
  const auto tri_i = i_mask_from_f(ok) && kind == i32_t<T>(static_cast<int32_t>(GeomKind::triangles));
  const auto flat_i = i_mask_from_f(ok) && kind == i32_t<T>(static_cast<int32_t>(GeomKind::flat_curve));
  const auto curve_i = (i_mask_from_f(ok) && kind == i32_t<T>(static_cast<int32_t>(GeomKind::curve))) || flat_i;
  const auto curve = f_mask_from_i(curve_i);
  // a medium's row: a scattering point on the ray (wave/media.h), exact where it is
  const auto medium = f_mask_from_i(i_mask_from_f(ok) && kind == i32_t<T>(static_cast<int32_t>(GeomKind::medium)));
  const auto sphere = ok && !f_mask_from_i(tri_i) && !curve && !medium;
  const bool mesh0 = is_mesh(G, g0);
  const bool one_tri = one_geom && (!mesh0 || all(!ok || f_mask_from_i(prim == i32_t<T>(p0))));
  const int32_t t0 = mesh0 ? G.geom_first[g0] + p0 : 0;
  i32_t<T> tri;
  Vec3<T> v0, v1, v2;
  if (!G.flat_triangles) {
    // large scenes keep no flattened table (GeomView::flat_triangles): each lane reads its
    // triangle's vertices through its mesh's indices (the same floats)
    constexpr int W = lane_traits<T>::width;
    alignas(64) float buf[9][W];
    const uint32_t tris = lane_bits(f_mask_from_i(tri_i));
    for (int k = 0; k < W; ++k) {
      if (!(tris >> k & 1u)) {
        for (auto& b : buf) b[k] = 0.f;
        continue;
      }
      const uint32_t g = p.geomID[l + k];
      const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(p.primID[l + k]);
      for (int c = 0; c < 3; ++c) {
        const float* q = G.positions[g] + 3 * static_cast<size_t>(idx[c]);
        buf[3 * c][k] = q[0];
        buf[3 * c + 1][k] = q[1];
        buf[3 * c + 2][k] = q[2];
      }
    }
    tri = sel(tri_i, gather(G.geom_first, gi) + prim, i32_t<T>(0));
    v0 = {load<T>(buf[0]), load<T>(buf[1]), load<T>(buf[2])};
    v1 = {load<T>(buf[3]), load<T>(buf[4]), load<T>(buf[5])};
    v2 = {load<T>(buf[6]), load<T>(buf[7]), load<T>(buf[8])};
  } else if (one_tri) {
    const float* P = G.tri_pos + 9 * static_cast<size_t>(t0);
    tri = i32_t<T>(t0);
    v0 = {T(P[0]), T(P[1]), T(P[2])};
    v1 = {T(P[3]), T(P[4]), T(P[5])};
    v2 = {T(P[6]), T(P[7]), T(P[8])};
  } else {
    tri = sel(tri_i, gather(G.geom_first, gi) + prim, i32_t<T>(0));
    const i32_t<T> tv = tri * i32_t<T>(9);
    v0 = gather3(G.tri_pos, G.tri_pos + 1, G.tri_pos + 2, tv);
    v1 = gather3(G.tri_pos + 3, G.tri_pos + 4, G.tri_pos + 5, tv);
    v2 = gather3(G.tri_pos + 6, G.tri_pos + 7, G.tri_pos + 8, tv);
  }
  const T b1 = load<T>(p.u + l), b2 = load<T>(p.v + l), b0 = T(1.f) - b1 - b2;
  Vec3<T> x{b0 * v0.x + b1 * v1.x + b2 * v2.x, b0 * v0.y + b1 * v1.y + b2 * v2.y, b0 * v0.z + b1 * v1.z + b2 * v2.z};
  const T g7(gamma_err(7));
  Vec3<T> err{g7 * (abs(b0 * v0.x) + abs(b1 * v1.x) + abs(b2 * v2.x)),
              g7 * (abs(b0 * v0.y) + abs(b1 * v1.y) + abs(b2 * v2.y)),
              g7 * (abs(b0 * v0.z) + abs(b1 * v1.z) + abs(b2 * v2.z))};
  if (any(sphere)) {
    const i32_t<T> s4 = sel(i_mask_from_f(sphere), gather(G.geom_first, gi), i32_t<T>(0)) * i32_t<T>(4);
    const Vec3<T> c = gather3(G.sphere_center, G.sphere_center + 1, G.sphere_center + 2, s4);
    Vec3<T> rel = o + d * t - c;
    rel = rel * (gather(G.sphere_center + 3, s4) / length(rel));
    const Vec3<T> xs = c + rel;
    // Not pbrt's gamma(5) |x| (its spheres sit at the origin of their object space): the
    // ray leaving the point is intersected in world space (accel/embree.cpp's sphere
    // test, in double; the offset was set for Embree's own sphere primitive, whose test
    // erred by a few 1e-6 of |o - c| and r near t = 0, so that a smaller offset let 2% of
    // the rays leaving a sphere hit it again at their origin: tests/test_stress.cpp,
    // StressPaths). 2^-16 (|x_i| + r): those tests passed down to 2^-21, a margin of 32.
    const T r = gather(G.sphere_center + 3, s4);
    const T k(0x1p-16f);
    x = sel(sphere, xs, x);
    err = sel(sphere, Vec3<T>{k * (abs(xs.x) + r), k * (abs(xs.y) + r), k * (abs(xs.z) + r)}, err);
  }
  if (any(curve)) {
    // A curve's point is on the ray (Embree intersects the curve in world space, its t good
    // to a few 1e-6 relative); its error bound covers the curve's width, so a ray leaving
    // the point starts outside a flat curve's ribbon and a round curve's tube: flat curves
    // face each ray, and the new ray's ribbon lies behind its origin.
    const i32_t<T> c4 = sel(curve_i, gather(G.geom_first, gi), i32_t<T>(0)) * i32_t<T>(4);
    const T r2 = T(2.f) * gather(G.sphere_center + 3, c4);
    const Vec3<T> xc = o + d * t;
    const T k(0x1p-16f);
    x = sel(curve, xc, x);
    err = sel(curve, Vec3<T>{k * abs(xc.x) + r2, k * abs(xc.y) + r2, k * abs(xc.z) + r2}, err);
  }
  if (G.has_media && any(medium)) {
    x = sel(medium, o + d * t, x);
    err = sel(medium, Vec3<T>(T(0.f), T(0.f), T(0.f)), err);
  }
  if (any_inst) {
    // placed in the world with pbrt-v4's error bound of a transformed point:
    // (gamma(3) + 1) |M| err + gamma(3) (|M| |x| + |translation|), per row
    const T g3(gamma_err(3)), g31(gamma_err(3) + 1.f);
    T xr[3], er[3];
    for (int r = 0; r < 3; ++r) {
      const float* M = G.inst_m + 4 * r;
      const T a = gather(M, in.m12), b = gather(M + 1, in.m12), c = gather(M + 2, in.m12), tr = gather(M + 3, in.m12);
      xr[r] = a * x.x + b * x.y + c * x.z + tr;
      er[r] = g31 * (abs(a) * err.x + abs(b) * err.y + abs(c) * err.z) +
              g3 * (abs(a * x.x) + abs(b * x.y) + abs(c * x.z) + abs(tr));
    }
    x = sel(in.on, Vec3<T>(xr[0], xr[1], xr[2]), x);
    err = sel(in.on, Vec3<T>(er[0], er[1], er[2]), err);
  }
  h.x = x;
  h.err = err;
  h.triangle = f_mask_from_i(tri_i);
  h.sphere = sphere;
  h.curve = curve;
  h.flat_curve = f_mask_from_i(flat_i);
  h.tri = tri;
  h.one_geom = one_geom;
  h.one_tri = one_tri;
  h.g0 = g0;
  h.t0 = t0;
  return h;
}

// Lanes [i, i + width) of the camera packets: the hits among the first `lanes` become
// shading points n, n + 1, ... in lane order (n is advanced). A hit with a degenerate
// normal or distance is rejected (counted, no shading point).
// Bounce (paths): lanes [i, i + width) of the bounce packets, one per shading point of
// the vertex before (`lanes` of them), become the next vertex's shading points, compacted
// in place (n <= i: every point is read before a store can reach it). Only the traced
// rays (tech.valid: Russian roulette has cleared the paths it ended) that hit something
// go on; they keep their tile lane, pixel, throughput and eta scale; the emission they
// reached was counted by the vertex before (emitter hits, with its MIS weight).
template <class T, bool Emitters, bool Materials = false, bool Bounce = false>
TUILE_FLATTEN inline void camera_hit_lanes(const GeomView& G, const LightView& L, TileBuffers& tb, int i, int lanes,
                                           int& n) {
  const RayHit16& p = Bounce ? tb.bounce[i / packet_width] : tb.cam[i / packet_width];
  const int l = i % packet_width;
  const i32_t<T> index = i32_t<T>(i) + lane_iota_i32<T>();
  const i32_t<T> lane = Bounce ? load_i32<T>(tb.points.lane + i) : index;
  const i32_t<T> pixel_id = load_i32<T>(reinterpret_cast<const int32_t*>((Bounce ? tb.points.pixel : tb.lanes.pixel) + i));
  const i32_t<T> geom = load_i32<T>(reinterpret_cast<const int32_t*>(p.geomID + l));
  auto hit = f_mask_from_i(geom >= i32_t<T>(0) && index < i32_t<T>(lanes));  // invalid_id reads as -1
  T beta_r(1.f), beta_g(1.f), beta_b(1.f), eta_scale(1.f), rough(0.f), first_rough(0.f);
  if constexpr (Bounce) {
    hit = hit && f_mask_from_i(load_i32<T>(tb.tech.valid + i) != i32_t<T>(0));
    beta_r = load<T>(tb.path.throughput_r + i);
    beta_g = load<T>(tb.path.throughput_g + i);
    beta_b = load<T>(tb.path.throughput_b + i);
    eta_scale = load<T>(tb.path.eta_scale + i);
    rough = load<T>(tb.path.rough + i);
    first_rough = load<T>(tb.path.first_rough + i);
  }
  const i32_t<T> gi = max(geom, i32_t<T>(0));
  const T t = load<T>(p.ray.tfar + l);
  const Vec3<T> o = load3<T>(p.ray.org_x + l, p.ray.org_y + l, p.ray.org_z + l);
  const Vec3<T> d = load3<T>(p.ray.dir_x + l, p.ray.dir_y + l, p.ray.dir_z + l);
  Vec3<T> ng = load3<T>(p.Ng_x + l, p.Ng_y + l, p.Ng_z + l);
  InstanceLanes<T> inst;
  if (G.has_instances) {
    inst = instance_lanes<T>(p, l, hit);
    if (any(inst.on)) ng = instance_normal<T>(G, inst, geom, ng);
  }
  const T len2 = dot(ng, ng);
  const auto ok = hit && len2 > T(0.f) && is_finite(len2) && is_finite(t);
  (Bounce ? tb.stats.rejected_bsdf : tb.stats.rejected_camera) += static_cast<uint64_t>(std::popcount(lane_bits(hit && !ok)));
  const uint32_t keep = lane_bits(ok);
  if constexpr (!Bounce) store(tb.lanes.shade_of + i, expand_index<T>(n, keep));
  if (!keep) return;
  ng = ng * rsqrt_nr(sel(ok, len2, T(1.f)));
  const HitGeometry<T> h = hit_geometry_lanes<T>(G, p, l, ok, keep, geom, o, d, t, inst);
  if (any(h.flat_curve)) {
    // a flat curve faces the ray (pbrt-v4's): its normal is -d without its part along the
    // tangent (Embree's Ng there), or -d where the ray runs along the curve
    const Vec3<T> w = Vec3<T>(T(0.f), T(0.f), T(0.f)) - d;
    const Vec3<T> nf = w - ng * dot(w, ng);
    const T lf = dot(nf, nf);
    const auto good = lf > T(1e-12f);
    ng = sel(h.flat_curve, sel(good, nf * rsqrt_nr(sel(good, lf, T(1.f))), w), ng);
  }
  // face the viewer: diffuse reflection on both sides. 0 - n, not -n: xsimd 8 negates
  // AVX-512 lanes as 0 - x, so this keeps +0 components in every build and the reference.
  const auto back = dot(ng, d) > T(0.f);
  ng = sel(back, Vec3<T>(T(0.f), T(0.f), T(0.f)) - ng, ng);

  const Vec3<T>& x = h.x;
  const bool one_geom = h.one_geom, one_tri = h.one_tri;
  const int32_t g0 = h.g0, t0 = h.t0;

  if constexpr (Emitters && !Bounce) {
    i32_t<T> light = sel(i_mask_from_f(h.triangle), one_tri ? i32_t<T>(G.tri_light[t0]) : gather(G.tri_light, h.tri), i32_t<T>(-1));
    if (any(h.sphere)) light = sel(i_mask_from_f(h.sphere), gather(G.geom_light, gi), light);
    add_seen_emission<T>(L, light, o, d, i, tb);
  }

  if constexpr (Materials) {
    const i32_t<T> mat = one_geom ? i32_t<T>(G.geom_material[g0]) : gather(G.geom_material, gi);
    // Embree's Ng is pbrt's outward normal of a triangle (cross(v1 - v0, v2 - v0)) and of
    // a sphere; reverse orientation turns the outside around
    const T gs = one_geom ? T(G.geom_side[g0]) : gather(G.geom_side, gi);
    compress_store(tb.points.mat + n, mat, keep);
    compress_store(tb.points.side + n, sel(back, T(0.f) - gs, gs), keep);
    compress_store(tb.points.wox + n, T(0.f) - d.x, keep);
    compress_store(tb.points.woy + n, T(0.f) - d.y, keep);
    compress_store(tb.points.woz + n, T(0.f) - d.z, keep);
  } else if (G.shading_normals) {  // the shading normal turns towards wo (shading_normals.h)
    compress_store(tb.points.wox + n, T(0.f) - d.x, keep);
    compress_store(tb.points.woy + n, T(0.f) - d.y, keep);
    compress_store(tb.points.woz + n, T(0.f) - d.z, keep);
  }
  T ar, ag, ab;
  if (one_geom) {
    const int32_t m = G.geom_material[g0];
    ar = T(G.mat_r[m]);
    ag = T(G.mat_g[m]);
    ab = T(G.mat_b[m]);
  } else {
    const i32_t<T> mat = gather(G.geom_material, gi);
    ar = gather(G.mat_r, mat);
    ag = gather(G.mat_g, mat);
    ab = gather(G.mat_b, mat);
  }
  if (G.shading_normals || G.has_rough_tex || G.has_hair || G.has_media) {  // for the scalar passes (shading normals, roughness, hair, media)
    compress_store(tb.points.geom + n, geom, keep);
    compress_store(tb.points.prim + n, load_i32<T>(reinterpret_cast<const int32_t*>(p.primID + l)), keep);
    compress_store(tb.points.bu + n, load<T>(p.u + l), keep);
    compress_store(tb.points.bv + n, load<T>(p.v + l), keep);
    if (G.has_instances) compress_store(tb.points.inst + n, inst.index, keep);
  }
  if (G.has_textures) list_textured_points(G, p, l, keep, n, tb);
  if (G.has_media) {
    compress_store(tb.points.medf + n, load_i32<T>(tb.media.med + i), keep);  // (wave/media.h point_media)
    // a collision inside its ray's stretch of medium: where along the ray the stretch lies
    // (wave/equiangular.h, collision_segment_weight)
    const MediumView& M = G.media;
    const T ea = load<T>(tb.media.eq_a + i), eb = load<T>(tb.media.eq_b + i);
    const auto inside = f_mask_from_i(geom >= i32_t<T>(M.geom0) && geom < i32_t<T>(M.geom0 + M.count) &&
                                      load_i32<T>(tb.media.eq_med + i) >= i32_t<T>(0)) &&
                        t >= ea && t <= eb;
    compress_store(tb.points.eq_lo + n, sel(inside, ea - t, T(1.f)), keep);
    compress_store(tb.points.eq_hi + n, sel(inside, eb - t, T(0.f)), keep);
  }

  // compaction: n <= i, so a whole batch written at n stays inside the arrays
  compress_store(tb.points.px + n, x.x, keep);
  compress_store(tb.points.py + n, x.y, keep);
  compress_store(tb.points.pz + n, x.z, keep);
  compress_store(tb.points.nx + n, ng.x, keep);
  compress_store(tb.points.ny + n, ng.y, keep);
  compress_store(tb.points.nz + n, ng.z, keep);
  compress_store(tb.points.eps + n, offset_along_normal(h.err, ng), keep);
  compress_store(tb.points.ar + n, ar, keep);
  compress_store(tb.points.ag + n, ag, keep);
  compress_store(tb.points.ab + n, ab, keep);
  compress_store(reinterpret_cast<int32_t*>(tb.points.pixel + n), pixel_id, keep);
  compress_store(tb.points.lane + n, lane, keep);
  if constexpr (Bounce) {
    compress_store(tb.path.throughput_r + n, beta_r, keep);
    compress_store(tb.path.throughput_g + n, beta_g, keep);
    compress_store(tb.path.throughput_b + n, beta_b, keep);
    compress_store(tb.path.eta_scale + n, eta_scale, keep);
    compress_store(tb.path.rough + n, rough, keep);
    compress_store(tb.path.first_rough + n, first_rough, keep);
    n += std::popcount(keep);
    return;
  }
  compact_point_keys<T>(tb, keep, n, i);
  n += std::popcount(keep);
}

// Each shading point's media (ShadingPoints::medf on its normal's side, medb behind it),
// from the medium its ray arrived through (medf on entry) and its surface.
inline void point_media(const GeomView& G, ShadingPoints& P) {
  const MediumView& M = G.media;
  for (int k = 0; k < P.count; ++k) {
    const int32_t g = P.geom[k];
    const int32_t in = M.geom_in[g], out = M.geom_out[g];
    if (in != out) {  // (never a medium's own row, whose sides are the same)
      const bool outside = P.side[k] > 0.f;  // the viewer is on the surface's outside
      P.medf[k] = outside ? out : in;
      P.medb[k] = outside ? in : out;
    } else {
      P.medb[k] = P.medf[k];
    }
    // a point in a medium has no surface: its normal is 0 (no offset, both sides the same
    // medium, and the light BVH's importance without a cosine, as pbrt-v4's medium
    // interactions); its BSDF, the phase function, reads none
    if (G.geom_kind[g] == static_cast<int32_t>(GeomKind::medium)) P.nx[k] = P.ny[k] = P.nz[k] = 0.f;
  }
  for (int k = P.count; k < packet_padded(P.count); ++k) P.medf[k] = P.medb[k] = -1;
}

// What both kinds of hits end with: the scalar passes (mixes, shading normals, textured
// roughness, texels), padding to whole packets, zero radiance, the one-sample MIS choice.
template <bool Materials>
inline void finish_points(const GeomView& G, const Estimator& est, uint32_t sample, uint32_t choice_pair, int n,
                          TileBuffers& tb) {
  tb.points.count = n;
  if constexpr (Materials)  // first: the bump map is the chosen material's
    if (G.has_mix) resolve_mixes(G, tb.points);
  if (G.shading_normals) apply_shading_normals<Materials>(G, tb.points);
  if constexpr (Materials) {
    if (G.has_rough_tex) apply_roughness_textures(G, tb.points);
    if (G.has_hair) apply_hair_frames(G, tb.points);
  }
  if (G.has_textures) apply_texels(G, tb);
  if (G.has_media) point_media(G, tb.points);
  // pad to whole packets with copies of a real point; padding lanes are never active
  const int padded = packet_padded(n);
  for (int k = n; k < padded; ++k) {
    tb.points.px[k] = tb.points.py[k] = tb.points.pz[k] = 0.f;
    tb.points.nx[k] = tb.points.ny[k] = 0.f;
    tb.points.nz[k] = 1.f;
    tb.points.eps[k] = 1e-6f;
    tb.points.ar[k] = tb.points.ag[k] = tb.points.ab[k] = 0.f;
    tb.points.snx[k] = tb.points.sny[k] = 0.f;
    tb.points.snz[k] = 1.f;
    tb.points.ax[k] = tb.points.ay[k] = 0.f;
    tb.points.fx[k] = 1.f;
    tb.points.fy[k] = tb.points.fz[k] = tb.points.fh[k] = 0.f;
    if constexpr (Materials) {
      tb.points.mat[k] = n > 0 ? tb.points.mat[0] : G.geom_material[0];
      tb.points.wox[k] = tb.points.woy[k] = 0.f;
      tb.points.woz[k] = 1.f;
      tb.points.side[k] = 1.f;
    }
    tb.points.pixel[k] = n > 0 ? tb.points.pixel[0] : 0u;
    tb.points.lane[k] = -1;
    tb.points.eq_lo[k] = 1.f;
    tb.points.eq_hi[k] = 0.f;
    tb.path.throughput_r[k] = tb.path.throughput_g[k] = tb.path.throughput_b[k] = 0.f;
    tb.path.eta_scale[k] = 1.f;
    tb.path.rough[k] = 0.f;
    tb.path.first_rough[k] = 0.f;
    if (!tb.keys.points_are_lanes)  // (padded > n means n > 0; as lanes, the padding pixels are pixel 0 already)
      for (uint32_t bits = tb.keys.keyed & ~1u; bits; bits &= bits - 1)
        for (int f = 0; f < 3; ++f) tb.keys.point_key[std::countr_zero(bits)][f][k] = tb.keys.point_key[std::countr_zero(bits)][f][0];
  }
  std::fill_n(tb.radiance.r, padded, 0.f);
  std::fill_n(tb.radiance.g, padded, 0.f);
  std::fill_n(tb.radiance.b, padded, 0.f);
  if (est.one_sample()) {
    point_pairs(est, tb, sample, choice_pair, padded, tb.tech.u0, nullptr);  // the choice reads one dimension
    const float c = est.one_sample_light_prob();
    for (int k = 0; k < padded; ++k) tb.points.choose_light[k] = tb.tech.u0[k] < c ? 1.f : 0.f;
  }
}

// The whole stage for lanes [0, lanes) of the tile. Emitters: false when the scene has
// no area light (no emitter lookups at all). T = float is the scalar reference.
// choice_pair: the one-sample technique choice's dimension pair (SampleLayout).
template <bool Emitters = true, class T = vfloat, bool Materials = false>
inline void camera_hits(const GeomView& G, const LightView& L, const Estimator& est, uint32_t sample,
                        uint32_t choice_pair, int lanes, TileBuffers& tb) {
  const int padded_lanes = packet_padded(lanes);
  int n = 0;
  tb.textured.count = 0;
  tb.keys.points_are_lanes = true;
  for (int i = 0; i < padded_lanes; i += lane_traits<T>::width) camera_hit_lanes<T, Emitters, Materials>(G, L, tb, i, lanes, n);
  finish_points<Materials>(G, est, sample, choice_pair, n, tb);
}

// pbrt-v4's regularization (Estimator::regularize): the shading points whose path has
// taken a non-specular BSDF sample take their material's regularized twin
// (GeomView::mat_reg), and textured alphas (has_rough_tex: per point) the same rule
// (regularized_alpha). After finish_points: a mix has chosen, the texels are looked up.
inline void regularize_points(const GeomView& G, TileBuffers& tb) {
  ShadingPoints& P = tb.points;
  for (int k = 0; k < P.count; ++k) {
    if (tb.path.rough[k] == 0.f) continue;
    const int32_t m = P.mat[k], r = G.mat_reg[m];
    if (r == m) continue;
    P.mat[k] = r;
    if (G.has_rough_tex) {
      P.ax[k] = regularized_alpha(P.ax[k]);
      P.ay[k] = regularized_alpha(P.ay[k]);
    }
  }
}

// The bounce rays' hits are scattered over the scene: before the stages read them, one
// pass over the tile's hits prefetches each triangle's row of the flattened table, its
// light index and its vertex indices (which the shading normals and texels read next), so
// that these cache misses overlap instead of following one another (the texels' passes
// in textures.h do the same).
inline void prefetch_hits(const GeomView& G, const RayHit16* packets, const int32_t* valid, int count) {
  for (int i = 0; i < count; ++i) {
    if (!valid[i]) continue;
    const RayHit16& p = packets[i / packet_width];
    const int l = i % packet_width;
    const int32_t g = static_cast<int32_t>(p.geomID[l]);
    if (g < 0 || g >= G.geom_count || !is_mesh(G, g)) continue;
    const uint32_t prim = p.primID[l];
    const size_t tri = static_cast<size_t>(G.geom_first[g]) + prim;
    if (G.flat_triangles) {
      __builtin_prefetch(G.tri_pos + 9 * tri);
      __builtin_prefetch(G.tri_pos + 9 * tri + 8);
    }
    __builtin_prefetch(G.tri_light + tri);
    if (!G.flat_triangles || G.normals[g] || G.uvs[g]) __builtin_prefetch(G.indices[g] + 3 * static_cast<size_t>(prim));
  }
}

// Paths: the hits of the bounce rays of the shading points (the vertex before) become
// the next vertex's shading points, in place (camera_hit_lanes with Bounce). The
// emission of the hits is not added: the vertex before counted it. Returns the count.
template <class T = vfloat, bool Materials = false>
inline int bounce_hits(const GeomView& G, const LightView& L, const Estimator& est, uint32_t sample, uint32_t choice_pair,
                       TileBuffers& tb) {
  const int count = tb.points.count;
  const int padded = packet_padded(count);
  int n = 0;
  tb.textured.count = 0;
  tb.keys.points_are_lanes = false;
  for (int i = 0; i < padded; i += lane_traits<T>::width) camera_hit_lanes<T, false, Materials, true>(G, L, tb, i, count, n);
  finish_points<Materials>(G, est, sample, choice_pair, n, tb);
  if constexpr (Materials)
    if (est.regularize) regularize_points(G, tb);
  return n;
}

}  // namespace tuile
