// Tile state: everything one tile's stages read and write, in SoA arrays sized for the
// largest tile, allocated once per worker (the renderer's buffer pool, src/render) and
// reused for every tile and sample; and the views of the scene the stages read.
#pragma once
#include <cstdint>

#include "light/lights.h"
#include "mis.h"
#include "lanes/packet.h"
#include "wave/estimator.h"
#include "sample/rng.h"

namespace tuile {

inline constexpr int max_tile_side = 32;
inline constexpr int max_tile_lanes = max_tile_side * max_tile_side;
inline constexpr int max_packets = max_tile_lanes / packet_width;
// Length of TileBuffers' per-lane arrays: max_tile_lanes plus one cache line. Arrays of
// exactly 4 KiB would start at the same offset modulo 4096, so lane k of every array
// would fall in the same L1 set (12 ways for the ~30 arrays a stage touches) and loads
// would falsely wait on stores to other arrays (4K aliasing); the extra line staggers
// them. Measured: two-panels +3.5%, cornell +3% (medians of 5, same run).
inline constexpr int lane_array = max_tile_lanes + 16;
// Stages run whole packets of lanes as whole SIMD batches: no scalar tails.
static_assert(packet_width % simd_width == 0, "the SIMD width must divide the packet width");

// Per-geometry data the hit stages look up by Embree's geomID / primID.
struct GeomView {
  int32_t mesh_count = 0;
  const int32_t* geom_material = nullptr;      // per geomID (meshes then spheres), never -1
  const float* sphere_center = nullptr;        // per sphere: centre xyz and radius
  bool has_textures = false;
  // Every triangle of every mesh, flattened: triangle tri_offset[geomID] + primID.
  const int32_t* tri_offset = nullptr;         // per geomID (0 for spheres)
  const float* tri_pos = nullptr;              // per triangle: v0 v1 v2, xyz each (9 floats)
  const int32_t* tri_light = nullptr;          // per triangle: light or -1
  const int32_t* sphere_light = nullptr;       // per sphere: light or -1
  const float *mat_r = nullptr, *mat_g = nullptr, *mat_b = nullptr;
  const int32_t* mat_texture = nullptr;
  const uint32_t* const* indices = nullptr;    // per mesh
  const float* const* positions = nullptr;     // per mesh, xyz per vertex
  const float* const* uvs = nullptr;           // per mesh, nullptr without uv
  const float* const* tex_rgb = nullptr;       // per texture
  const int32_t *tex_w = nullptr, *tex_h = nullptr;
};

struct CameraView {
  float m[3][4];          // world_from_camera
  float sx0, sx1, sy0, sy1;  // screen window
  float tan_half;         // tan(fov / 2)
  float inv_w, inv_h;
};

struct alignas(64) TileBuffers {
  RayHit16 cam[max_packets];
  Ray16 shadow[max_packets];
  RayHit16 bounce[max_packets];
  // the packets' constant fields, once (the stages write rays and reset hits only)
  TileBuffers() noexcept {
    for (int p = 0; p < max_packets; ++p) {
      reset_query_fields(cam[p]);
      reset_query_fields(shadow[p]);
      reset_query_fields(bounce[p]);
      reset_hit(cam[p]);
      reset_hit(bounce[p]);
    }
  }

  // per tile pixel (lane = row-major index inside the tile)
  alignas(64) float fx[lane_array], fy[lane_array];  // pixel corner
  alignas(64) uint32_t pixel[lane_array];                 // global pixel id (rng key)
  alignas(64) int32_t cam_valid[lane_array];
  alignas(64) int32_t shade_of[lane_array];  // the lane's shading point, -1 without one
  alignas(64) float Lr[lane_array], Lg[lane_array], Lb[lane_array];
  alignas(64) float wsum[lane_array], wcnt[lane_array];  // MIS weight of the BSDF technique (AOV)

  // per tile pixel, summed over the tile's samples in double, added to the Film at the end
  alignas(64) double acc_r[lane_array], acc_g[lane_array], acc_b[lane_array];
  alignas(64) double acc_rr[lane_array], acc_gg[lane_array], acc_bb[lane_array];  // squares
  alignas(64) double acc_w[lane_array], acc_wc[lane_array];  // wsum, wcnt
  alignas(64) float acc_max[lane_array];                          // largest sample luminance

  // compacted shading points: the camera hits
  int shade_count = 0;
  alignas(64) float px[lane_array], py[lane_array], pz[lane_array];
  alignas(64) float nx[lane_array], ny[lane_array], nz[lane_array];
  alignas(64) float eps[lane_array];                 // ray offset scaled to the coordinates
  alignas(64) float ar[lane_array], ag[lane_array], ab[lane_array];  // albedo
  alignas(64) uint32_t spix[lane_array];              // global pixel id
  alignas(64) int32_t slane[lane_array];              // tile lane
  alignas(64) float choose_light[lane_array];         // one-sample MIS: 1 = light technique
  // camera hits: the textured shading points (point, texture, triangle, barycentrics, texel)
  int tex_count = 0;
  alignas(64) int32_t tex_point[lane_array], tex_id[lane_array];
  alignas(64) uint32_t tex_geom[lane_array], tex_prim[lane_array];
  alignas(64) float tex_u[lane_array], tex_v[lane_array];
  alignas(64) const float* texel[lane_array];
  // radiance the light and BSDF techniques add to each shading point in this sample
  // (summed into its pixel by accumulate, through shade_of)
  alignas(64) float Sr[lane_array], Sg[lane_array], Sb[lane_array];

  // per technique sample (over shading points)
  alignas(64) float u0[lane_array], u1[lane_array], u2[lane_array], u3[lane_array];
  alignas(64) float cr[lane_array], cg[lane_array], cb[lane_array];
  alignas(64) int32_t valid[lane_array];
  alignas(64) int32_t hit_light[lane_array];
  alignas(64) float wb[lane_array];

  // queue of bounce rays that hit an emitter (the MIS weight stage runs on it only)
  int queue_count = 0;
  alignas(64) float qx[lane_array], qy[lane_array], qz[lane_array];
  alignas(64) float qnx[lane_array], qny[lane_array], qnz[lane_array];
  alignas(64) float qdx[lane_array], qdy[lane_array], qdz[lane_array];
  alignas(64) float qdist[lane_array];
  alignas(64) float qar[lane_array], qag[lane_array], qab[lane_array];
  alignas(64) int32_t qlight[lane_array];
  alignas(64) int32_t qpoint[lane_array];  // the entry's shading point
  // the bounce ray's origin and its distance to the emitter (for the visibility ray when
  // bounce rays see only the emitters), and 1 / 0 for a visible / occluded emitter
  alignas(64) float qox[lane_array], qoy[lane_array], qoz[lane_array], qt[lane_array];
  alignas(64) float qvis[lane_array];
  alignas(64) int32_t qvalid[lane_array];

  // The sampler's stream keys (rng.h PairKeys) of pairs 0 .. key_pairs - 1, per tile lane
  // (made once per tile by run_tile) and per shading point (compacted by camera_hits).
  // Bit p of keyed: pair p is cached; without it the stages hash the pixel every sample.
  static constexpr int key_pairs = 5;
  uint32_t keyed = 0;
  bool points_are_lanes = false;  // shading point k is tile lane k: points read lane_key
  alignas(64) uint32_t lane_key[key_pairs][3][lane_array];
  alignas(64) uint32_t point_key[key_pairs][3][lane_array];
  PairKeys lane_keys(int p) noexcept { return {lane_key[p][0], lane_key[p][1], lane_key[p][2]}; }
  PairKeys point_keys(int p) noexcept {
    return points_are_lanes ? lane_keys(p) : PairKeys{point_key[p][0], point_key[p][1], point_key[p][2]};
  }
  bool has_keys(uint32_t pair) const noexcept { return pair < key_pairs && ((keyed >> pair) & 1u); }

  // statistics of one render
  uint64_t rejected_light = 0, rejected_bsdf = 0, rejected_camera = 0;
  uint64_t rays_camera = 0, rays_shadow = 0, rays_bounce = 0, rays_bounce_visibility = 0;
  void reset_statistics() noexcept {
    rejected_light = rejected_bsdf = rejected_camera = 0;
    rays_camera = rays_shadow = rays_bounce = rays_bounce_visibility = 0;
  }
};

// One dimension pair of the sampler for the first `count` tile lanes (their pixels) or
// shading points, from the cached keys where the tile has them (the same bits); with
// v = nullptr the first dimension only.
inline void lane_pairs(const Estimator& est, TileBuffers& tb, uint32_t sample, uint32_t pair, int count, float* u,
                       float* v) noexcept {
  if (tb.has_keys(pair)) sample_pairs_keyed(est.sampler, est.seed, sample, pair, tb.lane_keys(static_cast<int>(pair)), count, u, v);
  else sample_pairs(est.sampler, est.seed, tb.pixel, sample, est.spp, pair, count, u, v);
}
inline void point_pairs(const Estimator& est, TileBuffers& tb, uint32_t sample, uint32_t pair, int count, float* u,
                        float* v) noexcept {
  if (tb.has_keys(pair)) sample_pairs_keyed(est.sampler, est.seed, sample, pair, tb.point_keys(static_cast<int>(pair)), count, u, v);
  else sample_pairs(est.sampler, est.seed, tb.spix, sample, est.spp, pair, count, u, v);
}

// Stores lanes [k, k + width) of rays (origin, direction, tfar) into an array of packets
// (Ray16 or RayHit16), packet k / 16 at lane k % 16, as store_field.
template <class P, class T>
inline void store_rays(P* packets, int k, const Vec3<T>& org, const Vec3<T>& dir, const T& tfar) noexcept {
  store_field(packets, &Ray16::org_x, k, org.x);
  store_field(packets, &Ray16::org_y, k, org.y);
  store_field(packets, &Ray16::org_z, k, org.z);
  store_field(packets, &Ray16::dir_x, k, dir.x);
  store_field(packets, &Ray16::dir_y, k, dir.y);
  store_field(packets, &Ray16::dir_z, k, dir.z);
  store_field(packets, &Ray16::tfar, k, tfar);
}

// pbrt-v4's gamma(n) = n u / (1 - n u), u = 2^-24: bounds on floating-point error.
inline constexpr float gamma_err(int n) { return (static_cast<float>(n) * 0x1p-24f) / (1 - static_cast<float>(n) * 0x1p-24f); }

}  // namespace tuile
