// The BSDF of shading points [k, k + width): the material, reflectance, normal, direction
// towards the viewer and side the camera-hit stage stored (bsdf/material.h). With Bsdfs =
// bsdf_diffuse only the reflectance and normal are read (the other arrays are not filled).
#pragma once
#include "bsdf/material.h"
#include "wave/tile.h"

namespace tuile {

template <class T, unsigned Bsdfs>
inline SurfaceBsdf<T, Bsdfs> load_surface_bsdf(const GeomView& G, const ShadingPoints& P, int k, const Vec3<T>& n) noexcept {
  SurfaceBsdf<T, Bsdfs> b;
  b.G = &G;
  b.rho = {load<T>(P.ar + k), load<T>(P.ag + k), load<T>(P.ab + k)};
  b.n = n;
  if constexpr (Bsdfs == bsdf_diffuse) {
    b.mat = i32_t<T>(0);
    b.kind = i32_t<T>(0);
    b.wo = Vec3<T>(T(0.f), T(0.f), T(0.f));
    b.side = T(1.f);
    b.ax = b.ay = T(0.f);
    b.fiber = Vec3<T>(T(1.f), T(0.f), T(0.f));
    b.fiber_h = T(0.f);
  } else {
    b.mat = load_i32<T>(P.mat + k);
    b.kind = gather(G.mat_kind, b.mat);
    b.wo = load3<T>(P.wox + k, P.woy + k, P.woz + k);
    b.side = load<T>(P.side + k);
    if (G.has_rough_tex) {
      b.ax = load<T>(P.ax + k);
      b.ay = load<T>(P.ay + k);
    } else {
      b.ax = gather(G.mat_param[mp_ax], b.mat);
      b.ay = gather(G.mat_param[mp_ay], b.mat);
    }
    if ((Bsdfs & bsdf_hair) != 0 && G.has_hair) {
      b.fiber = load3<T>(P.fx + k, P.fy + k, P.fz + k);
      b.fiber_h = load<T>(P.fh + k);
    } else {
      b.fiber = Vec3<T>(T(1.f), T(0.f), T(0.f));
      b.fiber_h = T(0.f);
    }
  }
  return b;
}

}  // namespace tuile
