// Stage 1, generate: camera rays for one sample of every pixel of a tile.
// Reads the tile's pixel corners and the sampler; writes the camera packets (RayHit16,
// Embree's layout) and clears the per-pixel radiance. pbrt-v4 perspective camera: fov
// over the shorter axis, raster y down. The position in the pixel follows the pixel filter
// (sample/filter.h, filter importance sampling as pbrt-v4): the default box of radius 1/2
// is the pixel corner plus the uniform pair, bit for bit; filters whose samples carry a
// weight other than 1 (gaussian, mitchell, sinc) also write it to lanes.fw and set
// lanes.weighted, which accumulate multiplies the sample's radiance by.
#pragma once
#include <algorithm>

#include "wave/tile.h"
#include "lanes/vec.h"
#include "sample/filter.h"

namespace tuile {

template <class T>
inline void camera_ray(const CameraView& c, T rx, T ry, Vec3<T>& org, Vec3<T>& dir) {
  const T sx = T(c.sx0) + rx * T(c.inv_w) * T(c.sx1 - c.sx0);
  const T sy = T(c.sy1) - ry * T(c.inv_h) * T(c.sy1 - c.sy0);
  const Vec3<T> d_cam{sx * T(c.tan_half), sy * T(c.tan_half), T(1.f)};
  const Vec3<T> d{T(c.m[0][0]) * d_cam.x + T(c.m[0][1]) * d_cam.y + T(c.m[0][2]) * d_cam.z,
                  T(c.m[1][0]) * d_cam.x + T(c.m[1][1]) * d_cam.y + T(c.m[1][2]) * d_cam.z,
                  T(c.m[2][0]) * d_cam.x + T(c.m[2][1]) * d_cam.y + T(c.m[2][2]) * d_cam.z};
  dir = normalize(d);
  org = {T(c.m[0][3]), T(c.m[1][3]), T(c.m[2][3])};
}

// Writes lanes [i, i + width(T)) of the camera packets (and the filter weights of a
// weighted filter). Kind: the filter's kind (c.filter.kind), a template so that the box
// and the triangle compute nothing more than their offsets.
template <class T, FilterKind Kind = FilterKind::box>
TUILE_FLATTEN inline void generate_lanes(const CameraView& c, TileBuffers& tb, int i) {
  const T u0 = load<T>(tb.tech.u0 + i), u1 = load<T>(tb.tech.u1 + i);
  T ox, oy;
  if constexpr (Kind == FilterKind::box) {
    ox = T(c.filter.box_a[0]) + T(c.filter.box_b[0]) * u0;  // radius 1/2: 0 + 1 u = u, the corner plus u exactly
    oy = T(c.filter.box_a[1]) + T(c.filter.box_b[1]) * u1;
  } else {
    T w;
    sample_filter(c.filter, u0, u1, ox, oy, w);
    if constexpr (Kind != FilterKind::triangle) store(tb.lanes.fw + i, w);
  }
  const T rx = load<T>(tb.lanes.fx + i) + ox;
  const T ry = load<T>(tb.lanes.fy + i) + oy;
  Vec3<T> o, d;
  camera_ray(c, rx, ry, o, d);
  RayHit16& p = tb.cam[i / packet_width];
  const int l = i % packet_width;
  store3(p.ray.org_x + l, p.ray.org_y + l, p.ray.org_z + l, o);
  store3(p.ray.dir_x + l, p.ray.dir_y + l, p.ray.dir_z + l, d);
  store(p.ray.tfar + l, T(3.0e38f));
  store(tb.lanes.Lr + i, T(0.f));
  store(tb.lanes.Lg + i, T(0.f));
  store(tb.lanes.Lb + i, T(0.f));
}

// All lanes of a tile (lanes padded up to a whole packet).
// pair: the sampler's dimension pair of the position in the pixel (SampleLayout::camera).
inline void generate(const CameraView& c, const Estimator& est, uint32_t sample, uint32_t pair, int lanes,
                     TileBuffers& tb) {
  const int padded = packet_padded(lanes);
  for (int i = lanes; i < padded; ++i) {  // padding lanes: a harmless pixel, never traced
    tb.lanes.fx[i] = tb.lanes.fx[0];
    tb.lanes.fy[i] = tb.lanes.fy[0];
    tb.lanes.pixel[i] = tb.lanes.pixel[0];
  }
  lane_pairs(est, tb, sample, pair, padded, tb.tech.u0, tb.tech.u1);
  const FilterKind kind = c.filter.kind;
  tb.lanes.weighted = c.filter.weighted();
  auto all_lanes = [&]<FilterKind K>() {
    for (int i = 0; i < padded; i += simd_width) generate_lanes<vfloat, K>(c, tb, i);  // padded: whole packets
  };
  switch (kind) {
    case FilterKind::box: all_lanes.template operator()<FilterKind::box>(); break;
    case FilterKind::triangle: all_lanes.template operator()<FilterKind::triangle>(); break;
    default: all_lanes.template operator()<FilterKind::gaussian>(); break;  // the tabulated filters (kind read at run time)
  }
  for (int k = 0; k < padded / packet_width; ++k) reset_hit(tb.cam[k]);
  std::fill_n(tb.lanes.cam_valid, lanes, -1);
  std::fill_n(tb.lanes.cam_valid + lanes, padded - lanes, 0);
  if (est.aov_mis_weight) {
    std::fill_n(tb.lanes.wsum, padded, 0.f);
    std::fill_n(tb.lanes.wcnt, padded, 0.f);
  }
}

}  // namespace tuile
