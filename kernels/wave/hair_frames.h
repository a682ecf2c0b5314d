// Hair's per-point geometry (scalar pass, after the hit stages compacted the shading points
// and resolved mixes): for each point whose material is hair, the fiber's axis and where the
// ray met the fiber across its width (bsdf/hair.h, hair_offset), written to
// ShadingPoints::fx, fy, fz, fh. On a curve (GeomView::curve_points), the axis is the cubic
// Bezier segment's derivative at Embree's u (the segment is the primID) and the centre and
// radius its value there; on other shapes (pbrt-v4 allows hair on any), the shading
// normal's basis tangent stands for the axis and h is 0 (a hit on the fiber's centre line).
// Reads: geom, prim, bu (the hit stages store them when GeomView::has_hair), px.., wox..,
// the normal. Writes: fx, fy, fz, fh.
#pragma once
#include "bsdf/hair.h"
#include "wave/instances.h"
#include "wave/tile.h"

namespace tuile {

// A cubic Bezier segment of 4 control points (x y z r each) at u: centre, derivative, radius.
inline void bezier_at(const float* p, float u, vec3f& c, vec3f& d, float& r) {
  const float v = 1.f - u;
  const float b0 = v * v * v, b1 = 3.f * v * v * u, b2 = 3.f * v * u * u, b3 = u * u * u;
  const float d0 = v * v, d1 = 2.f * v * u, d2 = u * u;
  for (int a = 0; a < 3; ++a) {
    const float x0 = p[a], x1 = p[4 + a], x2 = p[8 + a], x3 = p[12 + a];
    (&c.x)[a] = b0 * x0 + b1 * x1 + b2 * x2 + b3 * x3;
    (&d.x)[a] = 3.f * (d0 * (x1 - x0) + d1 * (x2 - x1) + d2 * (x3 - x2));
  }
  r = b0 * p[3] + b1 * p[7] + b2 * p[11] + b3 * p[15];
}

inline void apply_hair_frames(const GeomView& G, ShadingPoints& P) {
  for (int k = 0; k < P.count; ++k) {
    P.fx[k] = 1.f;
    P.fy[k] = P.fz[k] = P.fh[k] = 0.f;
    if (G.mat_kind[P.mat[k]] != static_cast<int32_t>(MaterialKind::hair)) continue;
    const vec3f n = G.shading_normals ? vec3f{P.snx[k], P.sny[k], P.snz[k]} : vec3f{P.nx[k], P.ny[k], P.nz[k]};
    vec3f t, b;
    make_basis(n, t, b);
    float h = 0.f;
    const float* cp = P.geom[k] >= 0 && P.geom[k] < G.geom_count ? G.curve_points[P.geom[k]] : nullptr;
    if (cp) {
      const float* seg = cp + 16 * static_cast<size_t>(P.prim[k]);
      float placed[16];
      if (G.has_instances && P.inst[k] >= 0) {  // an instance's fiber, placed in the world
        const float s = instance_scale(G, P.inst[k]);
        for (int j = 0; j < 4; ++j) {
          const vec3f q = instance_point(G, P.inst[k], {seg[4 * j], seg[4 * j + 1], seg[4 * j + 2]});
          placed[4 * j] = q.x;
          placed[4 * j + 1] = q.y;
          placed[4 * j + 2] = q.z;
          placed[4 * j + 3] = seg[4 * j + 3] * s;
        }
        seg = placed;
      }
      vec3f c, d;
      float r;
      bezier_at(seg, std::clamp(P.bu[k], 0.f, 1.f), c, d, r);
      float l = length(d);
      if (!(l > 0.f) || !std::isfinite(l)) {  // a degenerate derivative: the chord
        d = vec3f{seg[12] - seg[0], seg[13] - seg[1], seg[14] - seg[2]};
        l = length(d);
      }
      if (l > 0.f && std::isfinite(l)) {
        t = d * (1.f / l);
        h = hair_offset(vec3f{P.px[k], P.py[k], P.pz[k]}, c, t, vec3f{P.wox[k], P.woy[k], P.woz[k]}, r);
      }
    }
    P.fx[k] = t.x;
    P.fy[k] = t.y;
    P.fz[k] = t.z;
    P.fh[k] = h;
  }
}

}  // namespace tuile
