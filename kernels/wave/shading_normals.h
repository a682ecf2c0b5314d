// Shading normals of the shading points: interpolated vertex normals, and pbrt-v4's bump
// mapping by a float displacement texture. Scalar per point (only scenes with vertex
// normals or displacement run them). Reads the geometry tables, the textures and the
// shading points; writes the points' shading normals (and, with materials, which side is
// the outside).
#pragma once
#include <algorithm>
#include <cmath>

#include "wave/instances.h"
#include "wave/textures.h"

namespace tuile {
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
// inst: the point's instance (its vertices and normals placed in the world first), or -1.
inline bool bump_normal(const GeomView& G, int32_t t, int32_t g, int32_t prim, float b1, float b2, const vec3f& x,
                        const vec3f& n_view, vec3f& sn, int32_t inst = -1) {
  const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(prim);
  const float* pos = G.positions[g];
  const auto vtx = [&](int i) {
    const float* q = pos + 3 * static_cast<size_t>(idx[i]);
    const vec3f p{q[0], q[1], q[2]};
    return inst >= 0 ? instance_point(G, inst, p) : p;
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
  n = n * (inst >= 0 && instance_mirrors(G, inst) ? -G.geom_side[g] : G.geom_side[g]);
  // the shading frame the bump tilts
  vec3f ns = n, ss = dpdu, ts = dpdv, dndu{0, 0, 0}, dndv{0, 0, 0};
  if (const float* N = G.normals[g]) {
    const auto nrm = [&](int i) {
      const float* q = N + 3 * static_cast<size_t>(idx[i]);
      const vec3f n{q[0], q[1], q[2]};
      return inst >= 0 && (n.x != 0.f || n.y != 0.f || n.z != 0.f) ? instance_normal(G, inst, n) : n;
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
  // the three lookups read the texture's MIP level for the footprint (pbrt-v4's filters)
  const float width = 2.f * std::max(std::max(std::fabs(dudx), std::fabs(dvdx)), std::max(std::fabs(dudy), std::fabs(dvdy)));
  const float d = float_texture_filtered(G, t, u, v, width);
  const float d_u = float_texture_filtered(G, t, u + du, v, width);
  const float d_v = float_texture_filtered(G, t, u, v + dv, width);
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
// The vertex normals are gathered point by point (ShadingPoints::vn), the arithmetic runs
// in SIMD over whole packets (the padding lanes' results are overwritten by finish_points),
// bump mapping point by point; every lane computes the operations of the scalar
// definition above in the same order (tests/test_shading_normals.cpp holds it).
template <bool Materials> inline void apply_shading_normals(const GeomView& G, ShadingPoints& P) {
  // first a pass that prefetches the three vertex normals of every point (its indices
  // were prefetched with its hit), so that their cache misses overlap
  for (int k = 0; k < P.count; ++k) {
    const int32_t g = P.geom[k];
    const float* N = G.normals[g];
    if (!N) continue;
    const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(P.prim[k]);
    for (int i = 0; i < 3; ++i) __builtin_prefetch(N + 3 * static_cast<size_t>(idx[i]));
  }
  // the vertex normals (an instance's placed in the world, unit, as its flattened copy's)
  for (int k = 0; k < P.count; ++k) {
    const int32_t g = P.geom[k];
    const float* N = G.normals[g];  // (nullptr for every kind but meshes)
    if (!N) {
      for (int c = 0; c < 9; ++c) P.vn[c][k] = 0.f;
      continue;
    }
    const int32_t inst = G.has_instances ? P.inst[k] : -1;
    const uint32_t* idx = G.indices[g] + 3 * static_cast<size_t>(P.prim[k]);
    for (int i = 0; i < 3; ++i) {
      const float* q = N + 3 * static_cast<size_t>(idx[i]);
      vec3f nv{q[0], q[1], q[2]};
      if (inst >= 0 && (q[0] != 0.f || q[1] != 0.f || q[2] != 0.f)) nv = instance_normal(G, inst, nv);
      P.vn[3 * i][k] = nv.x;
      P.vn[3 * i + 1][k] = nv.y;
      P.vn[3 * i + 2][k] = nv.z;
    }
  }
  // On wo's side: pbrt-v4's BxDFs are two-sided in the shading frame (a diffuse surface
  // reflects light that arrives on the same side of the shading normal as wo), so where a
  // bump or an interpolated normal tilts past wo, the light on wo's side of the tilted
  // plane is the light that counts, and the BSDF samples go to that side.
  const auto to_wo_side = [&](int k, vfloat& sx, vfloat& sy, vfloat& sz) {
    const auto away = sx * vfloat::load_aligned(P.wox + k) + sy * vfloat::load_aligned(P.woy + k) +
                          sz * vfloat::load_aligned(P.woz + k) <
                      vfloat(0.f);
    sx = xsimd::select(away, -sx, sx);
    sy = xsimd::select(away, -sy, sy);
    sz = xsimd::select(away, -sz, sz);
  };
  const int end = packet_padded(P.count);
  for (int k = 0; k < end; k += static_cast<int>(vfloat::size)) {
    const vfloat gx = vfloat::load_aligned(P.nx + k), gy = vfloat::load_aligned(P.ny + k), gz = vfloat::load_aligned(P.nz + k);
    const vfloat b1 = vfloat::load_aligned(P.bu + k), b2 = vfloat::load_aligned(P.bv + k), b0 = vfloat(1.f) - b1 - b2;
    auto at = [&](int c) { return vfloat::load_aligned(P.vn[c] + k); };
    const vfloat x = b0 * at(0) + b1 * at(3) + b2 * at(6);
    const vfloat y = b0 * at(1) + b1 * at(4) + b2 * at(7);
    const vfloat z = b0 * at(2) + b1 * at(5) + b2 * at(8);
    const vfloat l2 = x * x + y * y + z * z;
    const auto ok = (l2 > vfloat(1e-20f)) & xsimd::isfinite(l2);
    const vfloat il = vfloat(1.f) / xsimd::sqrt(l2);
    vfloat sx = x * il, sy = y * il, sz = z * il;
    const vfloat facing = sx * gx + sy * gy + sz * gz;
    if constexpr (Materials)
      xsimd::select(ok, xsimd::select(facing >= vfloat(0.f), vfloat(1.f), vfloat(-1.f)), vfloat::load_aligned(P.side + k))
          .store_aligned(P.side + k);
    const auto flip = facing < vfloat(0.f);
    sx = xsimd::select(ok, xsimd::select(flip, -sx, sx), gx);
    sy = xsimd::select(ok, xsimd::select(flip, -sy, sy), gy);
    sz = xsimd::select(ok, xsimd::select(flip, -sz, sz), gz);
    if (!G.has_bump) to_wo_side(k, sx, sy, sz);
    sx.store_aligned(P.snx + k);
    sy.store_aligned(P.sny + k);
    sz.store_aligned(P.snz + k);
  }
  if (!G.has_bump) return;
  for (int k = 0; k < P.count; ++k) {
    const int32_t g = P.geom[k];
    if (!is_mesh(G, g)) continue;
    const int32_t m = Materials ? P.mat[k] : G.geom_material[g];
    const int32_t t = G.mat_bump[m];
    vec3f sn;
    if (t >= 0 && bump_normal(G, t, g, P.prim[k], P.bu[k], P.bv[k], {P.px[k], P.py[k], P.pz[k]}, {P.nx[k], P.ny[k], P.nz[k]},
                              sn, G.has_instances ? P.inst[k] : -1)) {
      P.snx[k] = sn.x;
      P.sny[k] = sn.y;
      P.snz[k] = sn.z;
    }
  }
  for (int k = 0; k < end; k += static_cast<int>(vfloat::size)) {
    vfloat sx = vfloat::load_aligned(P.snx + k), sy = vfloat::load_aligned(P.sny + k), sz = vfloat::load_aligned(P.snz + k);
    to_wo_side(k, sx, sy, sz);
    sx.store_aligned(P.snx + k);
    sy.store_aligned(P.sny + k);
    sz.store_aligned(P.snz + k);
  }
}

}  // namespace tuile
