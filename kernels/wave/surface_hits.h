// Stage 2b, camera hits: turns the camera packets Embree filled into compacted shading
// points (position, facing normal, albedo, ray offset, pixel, lane), adds the radiance
// of emitters seen directly, and draws the one-sample MIS technique choice.
// Reads: camera packets, geometry/material/light tables (triangles flattened by
// build_views). Writes: shading point arrays, tile radiance, rejected_camera. SIMD per
// lane with compress stores; only texture lookups, shading normals and bump mapping
// (apply_shading_normals: pbrt-v4's BumpMap) stay scalar.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <type_traits>

#include "wave/tile.h"
#include "lanes/vec.h"

namespace tuile {

// The texture of a hit's material, or -1 (spheres and meshes without uv have none).
inline int32_t hit_texture(const GeomView& G, uint32_t geom) {
  const int32_t t = G.mat_texture[G.geom_material[geom]];  // never -1 material: build_views appends a default
  if (t < 0 || static_cast<int32_t>(geom) >= G.mesh_count || !G.uvs[geom]) return -1;
  return t;
}

// The texel (nearest, wrap) of texture t at barycentrics (u, v) of triangle prim.
inline const float* hit_texel(const GeomView& G, int32_t t, uint32_t geom, uint32_t prim, float u, float v) {
  const uint32_t* idx = G.indices[geom] + 3 * prim;
  const float* uv = G.uvs[geom];
  const float w0 = 1.f - u - v;
  float s = w0 * uv[2 * idx[0]] + u * uv[2 * idx[1]] + v * uv[2 * idx[2]];
  float q = w0 * uv[2 * idx[0] + 1] + u * uv[2 * idx[1] + 1] + v * uv[2 * idx[2] + 1];
  s -= std::floor(s);
  q -= std::floor(q);
  const int w = G.tex_w[t], h = G.tex_h[t];
  const int x = std::min(w - 1, std::max(0, static_cast<int>(s * static_cast<float>(w))));
  const int y = std::min(h - 1, std::max(0, static_cast<int>((1.f - q) * static_cast<float>(h))));
  return G.tex_rgb[t] + 3 * (static_cast<size_t>(y) * w + x);
}

// Texels in three passes over the tile's textured shading points, each prefetching what the
// next reads (vertex indices, then uv, then the texel), so that the cache misses of a
// large scene overlap instead of following one another.
inline void apply_texels(const GeomView& G, TileBuffers& tb) {
  const int nt = tb.textured.count;
  for (int j = 0; j < nt; ++j) {
    const uint32_t* idx = G.indices[tb.textured.geom[j]] + 3 * tb.textured.prim[j];
    const float* uv = G.uvs[tb.textured.geom[j]];
    for (int c = 0; c < 3; ++c) __builtin_prefetch(uv + 2 * idx[c]);
  }
  for (int j = 0; j < nt; ++j) {
    tb.textured.texel[j] = hit_texel(G, tb.textured.texture[j], tb.textured.geom[j], tb.textured.prim[j], tb.textured.u[j], tb.textured.v[j]);
    __builtin_prefetch(tb.textured.texel[j]);
  }
  for (int j = 0; j < nt; ++j) {
    const int k = tb.textured.point[j];
    const float* t = tb.textured.texel[j];
    tb.points.ar[k] = t[0];  // the texel replaces the material's constant
    tb.points.ag[k] = t[1];
    tb.points.ab[k] = t[2];
  }
}

// pbrt's mix materials: each shading point whose material is a mix takes one of its two,
// the second with probability amount, from a hash of the point's position and direction
// (deterministic, as pbrt-v4's MixMaterial::ChooseMaterial), with that material's
// reflectance (its texture is not looked up: the texels follow the hit geometry's material).
inline void resolve_mixes(const GeomView& G, ShadingPoints& P) {
  for (int k = 0; k < P.count; ++k) {
    const int32_t m = P.mat[k];
    if (G.mat_mix0[m] < 0) continue;
    uint32_t h = 0x9e3779b9u;
    for (const float f : {P.px[k], P.py[k], P.pz[k], P.wox[k], P.woy[k], P.woz[k]}) {
      h ^= std::bit_cast<uint32_t>(f) + 0x7f4a7c15u + (h << 6) + (h >> 2);
      h *= 0x85ebca6bu;
      h ^= h >> 13;
    }
    const float u = static_cast<float>(h >> 8) * 0x1p-24f;
    const int32_t chosen = u < G.mat_mix_amount[m] ? G.mat_mix1[m] : G.mat_mix0[m];
    P.mat[k] = chosen;
    P.ar[k] = G.mat_r[chosen];
    P.ag[k] = G.mat_g[chosen];
    P.ab[k] = G.mat_b[chosen];
  }
}

// Float texture t at (u, v), filtered bilinearly with repeat wrap (pbrt-v4's imagemap
// defaults; its MIP level is not chosen: the full-resolution image): texel centres at
// half-integers, v = 1 the top row (pbrt flips t = 1 - v).
inline float float_texture_bilinear(const GeomView& G, int32_t t, float u, float v) {
  const float* val = G.ftex_value[t];
  if (!std::isfinite(u) || !std::isfinite(v)) return val[0];
  const int w = G.ftex_w[t], h = G.ftex_h[t];
  const float s = u - std::floor(u), q0 = 1.f - v, q = q0 - std::floor(q0);  // in [0, 1]
  const float x = s * static_cast<float>(w) - 0.5f, y = q * static_cast<float>(h) - 0.5f;
  const float xf = std::floor(x), yf = std::floor(y);
  const float fx = x - xf, fy = y - yf;
  int x0 = static_cast<int>(xf), y0 = static_cast<int>(yf);  // in [-1, w - 1], [-1, h - 1]
  int x1 = x0 + 1, y1 = y0 + 1;
  if (x0 < 0) x0 += w;
  if (y0 < 0) y0 += h;
  if (x1 >= w) x1 -= w;
  if (y1 >= h) y1 -= h;
  const auto at = [&](int xi, int yi) {
    return val[static_cast<size_t>(yi) * static_cast<size_t>(w) + static_cast<size_t>(xi)];
  };
  return (1.f - fy) * ((1.f - fx) * at(x0, y0) + fx * at(x1, y0)) + fy * ((1.f - fx) * at(x0, y1) + fx * at(x1, y1));
}

// pbrt-v4's bump mapping (BumpMap in materials.h, then SurfaceInteraction::GetBSDF) at a
// hit of triangle prim of mesh g, barycentrics (b1, b2), position x, with the float
// texture t as the displacement d(u, v). The surface is moved to p + d n:
//   dp/du' = dp/du + (d(u + du, v) - d(u, v)) / du n + d dn/du   (likewise for v),
// and the shading normal is normalize(cross(dp/du', dp/dv')), turned to the side of the
// geometric normal (pbrt: FaceForward(ns, n); here n_view, the viewer's side, which is
// where tuile keeps every shading normal). Its pieces are pbrt-v4's Triangle's:
// - dp/du, dp/dv from the vertices' uv (without uv, pbrt's (0,0), (1,0), (1,1)); a
//   degenerate uv gives the frame around the geometric normal (CoordinateSystem);
// - without vertex normals: n is the geometric normal, outwards (cross(p0 - p2, p1 - p2),
//   turned by reverse orientation: geom_side), dp/du and dp/dv as they are, dn/du = 0;
// - with vertex normals: n the interpolated normal (as the mesh gives it, not turned to
//   the viewer), pbrt's shading frame ss = dp/du made orthogonal to n and ts = n x ss
//   (which pbrt uses as dp/dv: the same for the usual right-handed uv of equal scales), and
//   dn/du, dn/dv from the vertex normals (the unnormalised interpolation's, as pbrt; zero
//   for a degenerate uv, where pbrt takes an arbitrary frame).
// du, dv: pbrt takes half the sum of |du/dx| and |du/dy| from the camera ray's
// differentials, which it scales by max(1/8, 1/sqrt(spp)). tuile has no ray
// differentials but every shaded point is a camera hit, so the same footprint follows
// from the camera: dp/dx is the change of the hit on the tangent plane per pixel
// (GeomView::cam_dx, whose scale is fixed at pbrt's 1/8 so that an image's expectation
// does not depend on spp), du/dx, dv/dx its least-squares coordinates in dp/du, dp/dv
// (pbrt's ComputeDifferentials). Where that is 0 (or not finite) du = 0.0005, pbrt's
// fallback. du stays above 2^-16 |u|, so that u + du is not rounded back to u.
// Returns false (sn untouched) where no normal comes out (degenerate geometry, NaN).
inline bool bump_normal(const GeomView& G, int32_t t, int32_t g, int32_t prim, float b1, float b2, const vec3f& x,
                        const vec3f& n_view, vec3f& sn) {
  const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(prim);
  const float* pos = G.positions[g];
  const auto vtx = [&](int i) {
    const float* q = pos + 3 * static_cast<size_t>(idx[i]);
    return vec3f{q[0], q[1], q[2]};
  };
  const vec3f p0 = vtx(0), p1 = vtx(1), p2 = vtx(2);
  float uv[3][2] = {{0, 0}, {1, 0}, {1, 1}};
  if (const float* UV = G.uvs[g])
    for (int i = 0; i < 3; ++i) {
      uv[i][0] = UV[2 * static_cast<size_t>(idx[i])];
      uv[i][1] = UV[2 * static_cast<size_t>(idx[i]) + 1];
    }
  const float b0 = 1.f - b1 - b2;
  // pbrt-v4's Triangle: dp/du, dp/dv
  const float du02 = uv[0][0] - uv[2][0], dv02 = uv[0][1] - uv[2][1];
  const float du12 = uv[1][0] - uv[2][0], dv12 = uv[1][1] - uv[2][1];
  const vec3f dp02 = p0 - p2, dp12 = p1 - p2;
  const float det = du02 * dv12 - dv02 * du12;
  const bool degenerate_uv = !(std::fabs(det) >= 1e-9f);
  vec3f dpdu{0, 0, 0}, dpdv{0, 0, 0};
  if (!degenerate_uv) {
    const float inv = 1.f / det;
    dpdu = (dp02 * dv12 - dp12 * dv02) * inv;
    dpdv = (dp12 * du02 - dp02 * du12) * inv;
  }
  const auto unit = [](const vec3f& a, vec3f& out) {
    const float l2 = dot(a, a);
    if (!(l2 > 0.f) || !std::isfinite(l2)) return false;
    out = a * (1.f / std::sqrt(l2));
    return true;
  };
  if (degenerate_uv || !(length_sq(cross(dpdu, dpdv)) > 0.f)) {
    vec3f ngu;
    if (!unit(cross(p2 - p0, p1 - p0), ngu)) return false;
    make_basis(ngu, dpdu, dpdv);
  }
  vec3f n;  // pbrt's n: the geometric normal, outwards
  if (!unit(cross(dp02, dp12), n)) return false;
  n = n * G.geom_side[g];
  // the shading frame the bump tilts
  vec3f ns = n, ss = dpdu, ts = dpdv, dndu{0, 0, 0}, dndv{0, 0, 0};
  if (const float* N = G.normals[g]) {
    const auto nrm = [&](int i) {
      const float* q = N + 3 * static_cast<size_t>(idx[i]);
      return vec3f{q[0], q[1], q[2]};
    };
    const vec3f n0 = nrm(0), n1 = nrm(1), n2 = nrm(2);
    const vec3f ni = n0 * b0 + n1 * b1 + n2 * b2;
    const float l2 = dot(ni, ni);
    if (l2 > 1e-20f && std::isfinite(l2)) ns = ni * (1.f / std::sqrt(l2));  // as apply_shading_normals
    ts = cross(ns, dpdu);
    if (length_sq(ts) > 0.f) ss = cross(ts, ns);
    else make_basis(ns, ss, ts);
    if (!degenerate_uv) {
      const float inv = 1.f / det;
      const vec3f dn1 = n0 - n2, dn2 = n1 - n2;
      dndu = (dn1 * dv12 - dn2 * dv02) * inv;
      dndv = (dn2 * du02 - dn1 * du12) * inv;
    }
  }
  // (u, v) at the hit, and its change per pixel
  const float u = b0 * uv[0][0] + b1 * uv[1][0] + b2 * uv[2][0];
  const float v = b0 * uv[0][1] + b1 * uv[1][1] + b2 * uv[2][1];
  float dudx = 0, dvdx = 0, dudy = 0, dvdy = 0;
  {
    const vec3f rel = x - vec3f{G.cam_o[0], G.cam_o[1], G.cam_o[2]};
    const float depth = dot(vec3f{G.cam_zrow[0], G.cam_zrow[1], G.cam_zrow[2]}, rel);
    const float nr = dot(n, rel);
    // the hit moves on the tangent plane: depth (D' - D (n.D') / (n.D)), D = rel / depth
    const auto dp = [&](const float* dd) {
      const vec3f d{dd[0], dd[1], dd[2]};
      return (d - rel * (dot(n, d) / nr)) * depth;
    };
    const vec3f dpdx = dp(G.cam_dx), dpdy = dp(G.cam_dy);
    const float a00 = dot(dpdu, dpdu), a01 = dot(dpdu, dpdv), a11 = dot(dpdv, dpdv);
    float inv = 1.f / (a00 * a11 - a01 * a01);
    if (!std::isfinite(inv)) inv = 0.f;
    const float bx0 = dot(dpdu, dpdx), bx1 = dot(dpdv, dpdx), by0 = dot(dpdu, dpdy), by1 = dot(dpdv, dpdy);
    const auto clamp_d = [](float f) { return std::isfinite(f) ? std::clamp(f, -1e8f, 1e8f) : 0.f; };
    dudx = clamp_d((a11 * bx0 - a01 * bx1) * inv);
    dvdx = clamp_d((a00 * bx1 - a01 * bx0) * inv);
    dudy = clamp_d((a11 * by0 - a01 * by1) * inv);
    dvdy = clamp_d((a00 * by1 - a01 * by0) * inv);
  }
  float du = 0.5f * (std::fabs(dudx) + std::fabs(dudy));
  float dv = 0.5f * (std::fabs(dvdx) + std::fabs(dvdy));
  if (du == 0.f) du = 0.0005f;
  if (dv == 0.f) dv = 0.0005f;
  du = std::max(du, 0x1p-16f * std::fabs(u));
  dv = std::max(dv, 0x1p-16f * std::fabs(v));
  const float d = float_texture_bilinear(G, t, u, v);
  const float d_u = float_texture_bilinear(G, t, u + du, v);
  const float d_v = float_texture_bilinear(G, t, u, v + dv);
  const vec3f bu = ss + ns * ((d_u - d) / du) + dndu * d;
  const vec3f bv = ts + ns * ((d_v - d) / dv) + dndv * d;
  vec3f nb;
  if (!unit(cross(bu, bv), nb)) return false;
  sn = dot(nb, n_view) < 0.f ? vec3f{0.f, 0.f, 0.f} - nb : nb;
  return true;
}

// Shading normals (pbrt-v4's triangle meshes with "N"): the vertex normals interpolated
// by the hit's barycentrics, normalised, on the geometric normal's side (the viewer's);
// where the mesh has none, or they cancel, the geometric normal. With Materials the
// normal also decides which side is the outside (pbrt-v4 turns the geometric normal
// towards it): side = +1 where the viewer is on the interpolated normal's side.
// Then bump mapping (bump_normal) where the point's material has a displacement texture
// (the material a mix chose, as pbrt-v4: resolve_mixes runs first); spheres are not
// bumped (tuile keeps no (phi, theta) frame for them; the loader warns).
template <bool Materials> inline void apply_shading_normals(const GeomView& G, ShadingPoints& P) {
  for (int k = 0; k < P.count; ++k) {
    const float gx = P.nx[k], gy = P.ny[k], gz = P.nz[k];
    float sx = gx, sy = gy, sz = gz;
    const int32_t g = P.geom[k];
    const float* N = g < G.mesh_count ? G.normals[g] : nullptr;
    if (N) {
      const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(P.prim[k]);
      const float b1 = P.bu[k], b2 = P.bv[k], b0 = 1.f - b1 - b2;
      const float* n0 = N + 3 * idx[0];
      const float* n1 = N + 3 * idx[1];
      const float* n2 = N + 3 * idx[2];
      const float x = b0 * n0[0] + b1 * n1[0] + b2 * n2[0];
      const float y = b0 * n0[1] + b1 * n1[1] + b2 * n2[1];
      const float z = b0 * n0[2] + b1 * n1[2] + b2 * n2[2];
      const float l2 = x * x + y * y + z * z;
      if (l2 > 1e-20f && std::isfinite(l2)) {
        const float il = 1.f / std::sqrt(l2);
        sx = x * il;
        sy = y * il;
        sz = z * il;
        const float facing = sx * gx + sy * gy + sz * gz;
        if constexpr (Materials) P.side[k] = facing >= 0.f ? 1.f : -1.f;
        if (facing < 0.f) {
          sx = -sx;
          sy = -sy;
          sz = -sz;
        }
      }
    }
    if (G.has_bump && g < G.mesh_count) {
      const int32_t m = Materials ? P.mat[k] : G.geom_material[g];
      const int32_t t = G.mat_bump[m];
      vec3f sn;
      if (t >= 0 && bump_normal(G, t, g, P.prim[k], P.bu[k], P.bv[k], {P.px[k], P.py[k], P.pz[k]}, {gx, gy, gz}, sn)) {
        sx = sn.x;
        sy = sn.y;
        sz = sn.z;
      }
    }
    P.snx[k] = sx;
    P.sny[k] = sy;
    P.snz[k] = sz;
  }
}

// Textured roughness: each point's Trowbridge-Reitz alphas, from its material's float
// textures at the hit's uv (bilinear, wrap; pbrt's default (0,0), (1,0), (1,1) without uv;
// through RoughnessToAlpha = sqrt where the material remaps), or the material's constants.
// Spheres have no uv here: they take the constants.
inline void apply_roughness_textures(const GeomView& G, ShadingPoints& P) {
  const float* cu = G.mat_param[mp_ax];
  const float* cv = G.mat_param[mp_ay];
  for (int k = 0; k < P.count; ++k) {
    const int32_t m = P.mat[k];
    float a[2] = {cu[m], cv[m]};
    const int32_t g = P.geom[k];
    for (int i = 0; i < 2; ++i) {
      const int32_t t = G.mat_alpha_tex[2 * m + i];
      if (t < 0 || g >= G.mesh_count) continue;
      const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(P.prim[k]);
      float uv[3][2] = {{0, 0}, {1, 0}, {1, 1}};
      if (const float* UV = G.uvs[g])
        for (int j = 0; j < 3; ++j) {
          uv[j][0] = UV[2 * static_cast<size_t>(idx[j])];
          uv[j][1] = UV[2 * static_cast<size_t>(idx[j]) + 1];
        }
      const float b1 = P.bu[k], b2 = P.bv[k], b0 = 1.f - b1 - b2;
      const float u = b0 * uv[0][0] + b1 * uv[1][0] + b2 * uv[2][0];
      const float v = b0 * uv[0][1] + b1 * uv[1][1] + b2 * uv[2][1];
      const float r = std::max(float_texture_bilinear(G, t, u, v), 0.f);
      a[i] = G.mat_remap[m] ? std::sqrt(r) : r;
    }
    P.ax[k] = a[0];
    P.ay[k] = a[1];
  }
}

// The light a ray hit, or -1.
inline int32_t light_of_hit(const GeomView& G, uint32_t geom, uint32_t prim) {
  if (geom == invalid_id) return -1;
  if (static_cast<int32_t>(geom) < G.mesh_count) return G.tri_light[G.tri_offset[geom] + static_cast<int32_t>(prim)];
  return G.sphere_light[geom - G.mesh_count];
}

// Whether a ray from o travelling along d sees the emitting side of light l: one-sided
// planar sources emit on the side of their normal, spheres outwards (a ray starting
// inside a sphere light sees no emission, as in pbrt). Spheres: false when no source is a
// sphere (the planar test alone, the same answer).
template <class T, bool Spheres = true, int Tier = tier_gather>
inline mask_t<T> light_front_lanes(const LightView& L, const i32_t<T>& l, const Vec3<T>& o, const Vec3<T>& d) {
  if constexpr (Tier == tier_gather && !std::is_same_v<T, float>) {  // permutes of small and medium tables
    if (L.tier == tier_small) return light_front_lanes<T, Spheres, tier_small>(L, l, o, d);
    if (L.tier == tier_medium) return light_front_lanes<T, Spheres, tier_medium>(L, l, o, d);
  }
  auto front = dot(d, Vec3<T>{lget<Tier>(L.nx, l), lget<Tier>(L.ny, l), lget<Tier>(L.nz, l)}) < T(0.f);
  if (L.any_two_sided) front = front || lget<Tier>(L.two_sided, l) > T(0.f);
  if constexpr (!Spheres) return front;
  const Vec3<T> c = o - Vec3<T>{lget<Tier>(L.p0x, l), lget<Tier>(L.p0y, l), lget<Tier>(L.p0z, l)};
  const T r = lget<Tier>(L.e1x, l);
  const auto sphere = f_mask_from_i(lget<Tier>(L.type, l) == i32_t<T>(lt_sphere));
  const auto outside = dot(c, c) > r * r;
  return sel_mask(sphere, outside, front);
}
inline bool light_front(const LightView& L, int32_t l, float ox, float oy, float oz, float dx, float dy, float dz) {
  return light_front_lanes<float>(L, l, {ox, oy, oz}, {dx, dy, dz});
}

// Ray offset for a surface point: the per-axis error bound of the point projected on the
// normal (pbrt-v4's OffsetRayOrigin), never zero so the new ray starts off the plane.
template <class T> inline T offset_along_normal(const Vec3<T>& err, const Vec3<T>& n) {
  return abs(n.x) * err.x + abs(n.y) * err.y + abs(n.z) * err.z + T(1e-30f);
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
  T beta_r(1.f), beta_g(1.f), beta_b(1.f), eta_scale(1.f);
  if constexpr (Bounce) {
    hit = hit && f_mask_from_i(load_i32<T>(tb.tech.valid + i) != i32_t<T>(0));
    beta_r = load<T>(tb.points.tr + i);
    beta_g = load<T>(tb.points.tg + i);
    beta_b = load<T>(tb.points.tbl + i);
    eta_scale = load<T>(tb.points.eta_scale + i);
  }
  const i32_t<T> gi = max(geom, i32_t<T>(0));
  const T t = load<T>(p.ray.tfar + l);
  const Vec3<T> o = load3<T>(p.ray.org_x + l, p.ray.org_y + l, p.ray.org_z + l);
  const Vec3<T> d = load3<T>(p.ray.dir_x + l, p.ray.dir_y + l, p.ray.dir_z + l);
  Vec3<T> ng = load3<T>(p.Ng_x + l, p.Ng_y + l, p.Ng_z + l);
  const T len2 = dot(ng, ng);
  const auto ok = hit && len2 > T(0.f) && is_finite(len2) && is_finite(t);
  (Bounce ? tb.stats.rejected_bsdf : tb.stats.rejected_camera) += static_cast<uint64_t>(std::popcount(lane_bits(hit && !ok)));
  const uint32_t keep = lane_bits(ok);
  if constexpr (!Bounce) store(tb.lanes.shade_of + i, expand_index<T>(n, keep));
  if (!keep) return;
  ng = ng * rsqrt_nr(sel(ok, len2, T(1.f)));
  // face the viewer: diffuse reflection on both sides. 0 - n, not -n: xsimd 8 negates
  // AVX-512 lanes as 0 - x, so this keeps +0 components in every build and the reference.
  const auto back = dot(ng, d) > T(0.f);
  ng = sel(back, Vec3<T>(T(0.f), T(0.f), T(0.f)) - ng, ng);

  // The hit point and its error bound (pbrt-v4): for triangles from the barycentrics,
  // err_i = gamma(7) sum_k |b_k v_k,i|, so an axis-aligned plane at any distance keeps
  // an exact coordinate; for spheres reprojected onto the surface, err = gamma(5) |x|.
  const auto tri_i = i_mask_from_f(ok) && geom < i32_t<T>(G.mesh_count);
  const auto sphere = ok && !f_mask_from_i(tri_i);
  const i32_t<T> prim = load_i32<T>(reinterpret_cast<const int32_t*>(p.primID + l));
  // Coherent camera rays often hit one geometry, even one triangle, in every lane: then
  // broadcasts of the first hit's data replace the gathers (same values). Lanes without
  // a triangle read triangle 0.
  const int k0 = std::countr_zero(keep);
  const int32_t g0 = static_cast<int32_t>(p.geomID[l + k0]), p0 = static_cast<int32_t>(p.primID[l + k0]);
  const bool one_geom = all(!ok || f_mask_from_i(geom == i32_t<T>(g0)));
  const bool one_tri = one_geom && (g0 >= G.mesh_count || all(!ok || f_mask_from_i(prim == i32_t<T>(p0))));
  const int32_t t0 = g0 < G.mesh_count ? G.tri_offset[g0] + p0 : 0;
  i32_t<T> tri;
  Vec3<T> v0, v1, v2;
  if (one_tri) {
    const float* P = G.tri_pos + 9 * static_cast<size_t>(t0);
    tri = i32_t<T>(t0);
    v0 = {T(P[0]), T(P[1]), T(P[2])};
    v1 = {T(P[3]), T(P[4]), T(P[5])};
    v2 = {T(P[6]), T(P[7]), T(P[8])};
  } else {
    tri = sel(tri_i, gather(G.tri_offset, gi) + prim, i32_t<T>(0));
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
    const i32_t<T> s4 = sel(i_mask_from_f(sphere), gi - i32_t<T>(G.mesh_count), i32_t<T>(0)) * i32_t<T>(4);
    const Vec3<T> c = gather3(G.sphere_center, G.sphere_center + 1, G.sphere_center + 2, s4);
    Vec3<T> rel = o + d * t - c;
    rel = rel * (gather(G.sphere_center + 3, s4) / length(rel));
    const Vec3<T> xs = c + rel;
    // Not pbrt's gamma(5) |x| (its spheres sit at the origin of their object space): the
    // ray leaving the point is intersected by Embree in world space, whose sphere test
    // errs by a few 1e-6 of |o - c| and r near t = 0, so a smaller offset let 2% of the
    // rays leaving a sphere hit it again at their origin (tests/test_stress.cpp,
    // StressPaths). 2^-16 (|x_i| + r): those tests pass down to 2^-21, so a margin of 32.
    const T r = gather(G.sphere_center + 3, s4);
    const T k(0x1p-16f);
    x = sel(sphere, xs, x);
    err = sel(sphere, Vec3<T>{k * (abs(xs.x) + r), k * (abs(xs.y) + r), k * (abs(xs.z) + r)}, err);
  }

  if constexpr (Emitters && !Bounce) {
    i32_t<T> light = sel(tri_i, one_tri ? i32_t<T>(G.tri_light[t0]) : gather(G.tri_light, tri), i32_t<T>(-1));
    if (any(sphere)) {
      const i32_t<T> sl = sel(i_mask_from_f(sphere), gi - i32_t<T>(G.mesh_count), i32_t<T>(0));
      light = sel(i_mask_from_f(sphere), gather(G.sphere_light, sl), light);
    }
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
  if (G.shading_normals || G.has_rough_tex) {  // for the scalar passes (apply_shading_normals, roughness)
    compress_store(tb.points.geom + n, geom, keep);
    compress_store(tb.points.prim + n, prim, keep);
    compress_store(tb.points.bu + n, b1, keep);
    compress_store(tb.points.bv + n, b2, keep);
  }
  // Textured points are only listed here (their vertex indices prefetched); camera_hits
  // applies the texels once every batch of the tile is done (apply_texels).
  if (G.has_textures) {
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

  // compaction: n <= i, so a whole batch written at n stays inside the arrays
  compress_store(tb.points.px + n, x.x, keep);
  compress_store(tb.points.py + n, x.y, keep);
  compress_store(tb.points.pz + n, x.z, keep);
  compress_store(tb.points.nx + n, ng.x, keep);
  compress_store(tb.points.ny + n, ng.y, keep);
  compress_store(tb.points.nz + n, ng.z, keep);
  compress_store(tb.points.eps + n, offset_along_normal(err, ng), keep);
  compress_store(tb.points.ar + n, ar, keep);
  compress_store(tb.points.ag + n, ag, keep);
  compress_store(tb.points.ab + n, ab, keep);
  compress_store(reinterpret_cast<int32_t*>(tb.points.pixel + n), pixel_id, keep);
  compress_store(tb.points.lane + n, lane, keep);
  if constexpr (Bounce) {
    compress_store(tb.points.tr + n, beta_r, keep);
    compress_store(tb.points.tg + n, beta_g, keep);
    compress_store(tb.points.tbl + n, beta_b, keep);
    compress_store(tb.points.eta_scale + n, eta_scale, keep);
    n += std::popcount(keep);
    return;
  }
  // The cached stream keys of the shading pairs: while every lane so far is a shading
  // point (point k is lane k) the points read the lanes' keys; from the first lane that is
  // not, they are copied and then compacted.
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
  n += std::popcount(keep);
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
  if constexpr (Materials)
    if (G.has_rough_tex) apply_roughness_textures(G, tb.points);
  if (G.has_textures) apply_texels(G, tb);
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
    if constexpr (Materials) {
      tb.points.mat[k] = n > 0 ? tb.points.mat[0] : G.geom_material[0];
      tb.points.wox[k] = tb.points.woy[k] = 0.f;
      tb.points.woz[k] = 1.f;
      tb.points.side[k] = 1.f;
    }
    tb.points.pixel[k] = n > 0 ? tb.points.pixel[0] : 0u;
    tb.points.lane[k] = -1;
    tb.points.tr[k] = tb.points.tg[k] = tb.points.tbl[k] = 0.f;
    tb.points.eta_scale[k] = 1.f;
    if (!tb.keys.points_are_lanes)  // (padded > n means n > 0; as lanes, the padding pixels are pixel 0 already)
      for (uint32_t bits = tb.keys.keyed & ~1u; bits; bits &= bits - 1)
        for (int f = 0; f < 3; ++f) tb.keys.point_key[std::countr_zero(bits)][f][k] = tb.keys.point_key[std::countr_zero(bits)][f][0];
  }
  std::fill_n(tb.points.Sr, padded, 0.f);
  std::fill_n(tb.points.Sg, padded, 0.f);
  std::fill_n(tb.points.Sb, padded, 0.f);
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
  return n;
}

}  // namespace tuile
