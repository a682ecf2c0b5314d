// The light table as kernels read it: SoA arrays per source (kind, corner, edges,
// normal, radiance, area, the constants the maps need), read per lane by index with
// gathers or, for small and medium tables, permutes (the same values in every tier).
#pragma once
#include <type_traits>

#include "lanes/vec.h"
#include "light/kinds.h"
#include "light/sky_map.h"
#include "sample/spherical.h"

namespace tuile {

enum class LightPoint : int { area = 0, solid_angle = 1 };

struct LightBvhView;
struct AlphaShape;  // wave/alpha.h

struct LightView {
  int32_t count = 0;
  // how the tables are read per lane (table_tier): arrays padded to small_table_size or
  // medium_table_size where count fits, then lookup_small / lookup_medium read them
  int tier = 0;
  const int32_t* type = nullptr;  // LightKind
  const float *p0x = nullptr, *p0y = nullptr, *p0z = nullptr;
  const float *e1x = nullptr, *e1y = nullptr, *e1z = nullptr;
  const float *e2x = nullptr, *e2y = nullptr, *e2z = nullptr;
  const float *nx = nullptr, *ny = nullptr, *nz = nullptr;  // unit normal of the emitting side
  const float *Lr = nullptr, *Lg = nullptr, *Lb = nullptr;
  const float* area = nullptr;
  const float* two_sided = nullptr;   // 1 or 0
  // constants of planar sources (light_geom_derive): edge lengths, their inverses, and 1
  // for parallelograms with orthogonal edges (sampled with Urena's map)
  const float *len1 = nullptr, *len2 = nullptr, *inv_len1 = nullptr, *inv_len2 = nullptr, *rect = nullptr;
  // unit edge directions e1 * inv_len1, e2 * inv_len2 (the same bits light_geom_derive
  // computes); a rectangle's normal n is cross(ex, ey), so rectangle pipelines read these
  // six instead of the edges, their inverse lengths and the normal
  const float *exx = nullptr, *exy = nullptr, *exz = nullptr, *eyx = nullptr, *eyy = nullptr, *eyz = nullptr;
  bool any_two_sided = true;  // false: every two_sided entry is 0 (rectangle pipelines skip reading it)
  bool one_radiance = false;  // every source has the radiance of source 0 (broadcast, not read per lane)
  const float* pick_pdf = nullptr;    // probability of picking each source (1 with "all")
  const float* alias_prob = nullptr;  // alias table of pick_pdf
  const int32_t* alias_idx = nullptr;
  // the light BVH (light/bvh.h) when sources are picked with it (--light-pick bvh); then
  // pick_pdf and the alias table are not read for picks
  const LightBvhView* bvh = nullptr;
  // the sources of the kind_sky group (light/kinds/infinite.h), which the rays that escape
  // the scene see (wave/escaped.h): their indices in this table
  int32_t sky_count = 0;
  const int32_t* sky_light = nullptr;
  // the environment maps of the skies (a sky entry's p0.x is its map's index, -1 for a
  // constant sky) and which of their distributions the light technique samples
  // (sky_dist_compensated where BSDF sampling covers every direction: set per estimator)
  const SkyMapView* sky_maps = nullptr;
  int32_t sky_map_count = 0;
  int sky_dist = sky_dist_full;
  // Cut-out emitters (wave/alpha.h): per source, its shape in alpha_shapes or -1, and its
  // triangle in that mesh; nullptr when no source has an alpha
  const int32_t* alpha_shape = nullptr;
  const int32_t* alpha_prim = nullptr;
  const AlphaShape* alpha_shapes = nullptr;
  // --light-paths: per source, 1 where the light tracer takes the source's light at
  // near-specular vertices (GeomView::mat_lt_glossy): distant sources, and area ones where
  // that split is on; nullptr: none
  const int32_t* lt_glossy = nullptr;
};

// How a light table is read per lane: tier_gather (any size), tier_small (tables padded to
// small_table_size: lookup_small), tier_medium (padded to medium_table_size: lookup_medium).
inline constexpr int tier_gather = 0, tier_small = 1, tier_medium = 2;
inline int table_tier(size_t count) noexcept {
  return count <= static_cast<size_t>(small_table_size)    ? tier_small
         : count <= static_cast<size_t>(medium_table_size) ? tier_medium
                                                             : tier_gather;
}
// A table read per lane in tier Tier (the same values in every tier).
template <int Tier, class Base, class I> inline auto lget(const Base* base, const I& i) {
  if constexpr (Tier == tier_small) return lookup_small(base, i);
  else if constexpr (Tier == tier_medium) return lookup_medium(base, i);
  else return gather(base, i);
}
// Runs f(std::integral_constant<int, tier>) for the tables' tier.
template <class F> inline void with_table_tier(const LightView& L, F&& f) {
  if (L.tier == tier_small) f(std::integral_constant<int, tier_small>{});
  else if (L.tier == tier_medium) f(std::integral_constant<int, tier_medium>{});
  else f(std::integral_constant<int, tier_gather>{});
}

// Geometry of the sources of each lane.
template <class T> struct LightGeom {
  i32_t<T> type;  // LightKind
  Vec3<T> p0, e1, e2, n;
  T area, two_sided;
  T len1, len2, inv_len1, inv_len2, rect;  // light_geom_derive
  Vec3<T> ex, ey;                          // e1 * inv_len1, e2 * inv_len2 (light_geom_derive)
  // the table's environment maps and the distribution sampled (LightView's): a sky's map
  // is sky_maps[p0.x] (none where p0.x < 0), its frame e1, e2, n (light/kinds/infinite.h)
  const SkyMapView* sky_maps = nullptr;
  int32_t sky_map_count = 0;
  int sky_dist = sky_dist_full;
};

// The sky maps of the table, for a LightGeom read from it.
template <class T> inline void attach_sky_maps(const LightView& L, LightGeom<T>& g) {
  g.sky_maps = L.sky_maps;
  g.sky_map_count = L.sky_map_count;
  g.sky_dist = L.sky_dist;
}

// The unit edges of a source's LightGeom from its edges and inverse lengths: the bits the
// table's ex, ey hold (light_geom_derive, build_views).
template <class T> inline void derive_unit_edges(LightGeom<T>& g) {
  g.ex = g.e1 * g.inv_len1;
  g.ey = g.e2 * g.inv_len2;
}

// The fields every planar source has (gather_light adds the kind, the area and the
// rectangle flag).
template <int Tier, class I, class T> inline void gather_planar_fields(const LightView& L, const I& idx, LightGeom<T>& g) {
  g.p0 = {lget<Tier>(L.p0x, idx), lget<Tier>(L.p0y, idx), lget<Tier>(L.p0z, idx)};
  g.e1 = {lget<Tier>(L.e1x, idx), lget<Tier>(L.e1y, idx), lget<Tier>(L.e1z, idx)};
  g.e2 = {lget<Tier>(L.e2x, idx), lget<Tier>(L.e2y, idx), lget<Tier>(L.e2z, idx)};
  g.n = {lget<Tier>(L.nx, idx), lget<Tier>(L.ny, idx), lget<Tier>(L.nz, idx)};
  g.two_sided = lget<Tier>(L.two_sided, idx);
  g.len1 = lget<Tier>(L.len1, idx);
  g.len2 = lget<Tier>(L.len2, idx);
  g.inv_len1 = lget<Tier>(L.inv_len1, idx);
  g.inv_len2 = lget<Tier>(L.inv_len2, idx);
}

template <int Tier = tier_gather, class I> inline auto gather_light(const LightView& L, const I& idx) {
  using T = decltype(gather(L.area, idx));
  LightGeom<T> g;
  g.type = lget<Tier>(L.type, idx);
  gather_planar_fields<Tier>(L, idx, g);
  g.area = lget<Tier>(L.area, idx);
  g.rect = lget<Tier>(L.rect, idx);
  derive_unit_edges(g);
  attach_sky_maps(L, g);
  return g;
}

// The fields a rectangle source needs: its corner, unit edges and edge lengths (and
// whether it is two-sided, where any source is); its normal is cross(ex, ey) and its area
// len1 len2, bit for bit the table's (light_geom_derive, build_views). e1, e2 and the
// inverse lengths are not read: no rectangle path uses them (0 here).
template <int Tier = tier_gather, class I> inline auto gather_rect_light(const LightView& L, const I& idx) {
  using T = decltype(gather(L.area, idx));
  LightGeom<T> g;
  g.type = i32_t<T>(static_cast<int32_t>(LightKind::parallelogram));
  g.p0 = {lget<Tier>(L.p0x, idx), lget<Tier>(L.p0y, idx), lget<Tier>(L.p0z, idx)};
  g.ex = {lget<Tier>(L.exx, idx), lget<Tier>(L.exy, idx), lget<Tier>(L.exz, idx)};
  g.ey = {lget<Tier>(L.eyx, idx), lget<Tier>(L.eyy, idx), lget<Tier>(L.eyz, idx)};
  g.len1 = lget<Tier>(L.len1, idx);
  g.len2 = lget<Tier>(L.len2, idx);
  g.two_sided = L.any_two_sided ? lget<Tier>(L.two_sided, idx) : T(0.f);
  g.n = cross(g.ex, g.ey);
  g.area = g.len1 * g.len2;
  g.rect = T(1.f);
  g.e1 = g.e2 = Vec3<T>(T(0.f), T(0.f), T(0.f));
  g.inv_len1 = g.inv_len2 = T(0.f);
  return g;
}

// A source's radiance per lane (source 0's where every source has the same).
template <int Tier, class I, class T> inline void lookup_radiance(const LightView& L, const I& idx, T& r, T& g, T& b) {
  if (L.one_radiance) {
    r = T(L.Lr[0]);
    g = T(L.Lg[0]);
    b = T(L.Lb[0]);
    return;
  }
  r = lget<Tier>(L.Lr, idx);
  g = lget<Tier>(L.Lg, idx);
  b = lget<Tier>(L.Lb, idx);
}

template <class T> inline LightGeom<T> broadcast_light(const LightView& L, int32_t i) {
  LightGeom<T> g;
  g.type = i32_t<T>(L.type[i]);
  g.p0 = {T(L.p0x[i]), T(L.p0y[i]), T(L.p0z[i])};
  g.e1 = {T(L.e1x[i]), T(L.e1y[i]), T(L.e1z[i])};
  g.e2 = {T(L.e2x[i]), T(L.e2y[i]), T(L.e2z[i])};
  g.n = {T(L.nx[i]), T(L.ny[i]), T(L.nz[i])};
  g.area = T(L.area[i]);
  g.two_sided = T(L.two_sided[i]);
  g.len1 = T(L.len1[i]);
  g.len2 = T(L.len2[i]);
  g.inv_len1 = T(L.inv_len1[i]);
  g.inv_len2 = T(L.inv_len2[i]);
  g.rect = T(L.rect[i]);
  g.ex = {T(L.exx[i]), T(L.exy[i]), T(L.exz[i])};
  g.ey = {T(L.eyx[i]), T(L.eyy[i]), T(L.eyz[i])};
  attach_sky_maps(L, g);
  return g;
}

template <class T> inline mask_t<T> type_is(const i32_t<T>& type, int32_t t) {
  if constexpr (std::is_same_v<T, float>) return type == t;
  else return f_mask_from_i(type == i32_t<T>(t));
}

// The per-source constants of LightGeom that follow from its edges (computed once per
// source by the renderer; tests that build a LightGeom by hand call this too).
template <class T> inline void light_geom_derive(LightGeom<T>& g) {
  g.len1 = length(g.e1);
  g.len2 = length(g.e2);
  const mask_t<T> ok = g.len1 > T(0.f) && g.len2 > T(0.f);
  g.inv_len1 = T(1.f) / sel(ok, g.len1, T(1.f));
  g.inv_len2 = T(1.f) / sel(ok, g.len2, T(1.f));
  derive_unit_edges(g);
  g.rect = sel(type_is<T>(g.type, static_cast<int32_t>(LightKind::parallelogram)) && parallelogram_is_rectangle(g.e1, g.e2), T(1.f), T(0.f));
  // a rectangle's area is the product of its edge lengths, so the rectangle pipelines
  // derive it instead of reading it
  g.area = sel(g.rect > T(0.5f), g.len1 * g.len2, g.area);
}

}  // namespace tuile
