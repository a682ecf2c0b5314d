// Tile state: everything one tile's stages read and write, in SoA arrays sized for the
// largest tile, allocated once per worker (the renderer's buffer pool, src/render) and
// reused for every tile and sample; and the views of the scene the stages read.
#pragma once
#include <cstdint>
#include <memory>

#include "light/pick.h"
#include "light/sample.h"
#include "mis.h"
#include "lanes/packet.h"
#include "lanes/twin.h"
#include "wave/estimator.h"
#include "wave/views.h"
#include "sample/layout.h"
#include "sample/rng.h"

namespace tuile {

inline constexpr int max_tile_side = 32;
inline constexpr int max_tile_lanes = max_tile_side * max_tile_side;
inline constexpr int max_packets = max_tile_lanes / packet_width;
// Length of TileBuffers' per-lane arrays: max_tile_lanes plus one cache line. Arrays of
// exactly 4 KiB would start at the same offset modulo 4096, so lane k of every array
// would fall in the same L1 set (12 ways for the ~30 arrays a stage touches) and loads
// would falsely wait on stores to other arrays (4K aliasing); the extra line staggers
// them.
inline constexpr int lane_array = max_tile_lanes + 16;
// Stages run whole packets of lanes as whole SIMD batches: no scalar tails.
static_assert(packet_width % simd_width == 0, "the SIMD width must divide the packet width");

// The records of one tile's state. Lanes are a tile's pixels; shading points are the
// camera hits, compacted; the emitter-hit queue holds the BSDF-sampled rays that reached
// the front of an emitter, compacted again. "This sample" arrays are rewritten for every
// sample of the tile; the sums hold the whole render's samples of the tile.

// Per tile lane (lane order: 4x4 pixel blocks, or rows; see run_tile).
struct PixelLanes {
  alignas(64) float fx[lane_array], fy[lane_array];  // pixel corner
  alignas(64) uint32_t pixel[lane_array];            // global pixel id (the sampler's key)
  alignas(64) int32_t cam_valid[lane_array];
  alignas(64) int32_t shade_of[lane_array];          // the lane's shading point, -1 without one
  alignas(64) float Lr[lane_array], Lg[lane_array], Lb[lane_array];  // emission the camera sees, this sample
  alignas(64) float wsum[lane_array], wcnt[lane_array];  // BSDF technique's MIS weights (AOV), this sample
  alignas(64) float fw[lane_array];  // the pixel filter's weight of this sample (where `weighted`)
  bool weighted = false;             // this sample's filter weights are not all 1 (generate sets it)
};

// Per tile lane, summed over the tile's samples in double, added to the film at the end.
struct TileSums {
  alignas(64) double r[lane_array], g[lane_array], b[lane_array];
  alignas(64) double rr[lane_array], gg[lane_array], bb[lane_array];  // squares
  alignas(64) double w[lane_array], wc[lane_array];                   // wsum, wcnt
  alignas(64) float max[lane_array];                                  // largest sample luminance
};

// The shading points of this sample: the camera hits, compacted.
struct ShadingPoints {
  int count = 0;
  alignas(64) float px[lane_array], py[lane_array], pz[lane_array];
  alignas(64) float nx[lane_array], ny[lane_array], nz[lane_array];
  alignas(64) float eps[lane_array];                          // ray offset scaled to the coordinates
  alignas(64) float ar[lane_array], ag[lane_array], ab[lane_array];  // the material's reflectance (textured)
  // pipelines with non-diffuse materials only (Features::bsdfs): the material, the unit
  // direction towards the viewer, and +1 / -1 where the viewer is outside / inside
  alignas(64) int32_t mat[lane_array];
  alignas(64) float wox[lane_array], woy[lane_array], woz[lane_array];
  alignas(64) float side[lane_array];
  // scenes with shading normals only (GeomView::shading_normals: vertex normals or bump mapping): the hit's geometry,
  // triangle and barycentrics, and the shading normal on the viewer's side (nx, ny, nz
  // stay the geometric normal, for ray offsets and which side a direction is on)
  alignas(64) int32_t geom[lane_array], prim[lane_array];
  alignas(64) float bu[lane_array], bv[lane_array];
  // with instances (GeomView::has_instances) and those passes: the hit's instance or -1
  alignas(64) int32_t inst[lane_array];
  alignas(64) float snx[lane_array], sny[lane_array], snz[lane_array];
  // scenes with shading normals: each point's three vertex normals, x y z of each in turn
  // (zero where its geometry has none; apply_shading_normals' scratch)
  alignas(64) float vn[9][lane_array];
  // scenes with textured roughness only (GeomView::has_rough_tex): the Trowbridge-Reitz
  // alphas at the point
  alignas(64) float ax[lane_array], ay[lane_array];
  // scenes with hair only (GeomView::has_hair): the fiber's axis (unit) and where the ray
  // met it across its width, h in [-1, 1] (bsdf/hair.h)
  alignas(64) float fx[lane_array], fy[lane_array], fz[lane_array], fh[lane_array];
  // scenes with media only (GeomView::has_media): the medium on the normal's side of the
  // point and behind it (-1: none; wave/media.h point_media)
  alignas(64) int32_t medf[lane_array], medb[lane_array];
  // scenes with media: the stretch of scattering medium its ray's segment light sample
  // covered (wave/equiangular.h), from eq_lo to eq_hi along the ray relative to the point
  // (eq_lo <= 0 <= eq_hi), eq_lo = 1 where the point is not in one
  alignas(64) float eq_lo[lane_array], eq_hi[lane_array];
  alignas(64) uint32_t pixel[lane_array];                     // global pixel id
  alignas(64) int32_t lane[lane_array];                       // tile lane
  alignas(64) float choose_light[lane_array];                 // one-sample MIS: 1 = light technique
  // --guide (wave/guide.h guide_points): the guide's share at the point (0: unguided) and
  // its distribution, found once a vertex for the light and the BSDF stages
  alignas(64) float guide_alpha[lane_array];
  alignas(64) int32_t guide_dist[lane_array];
};

// The path of each shading point (paths, Estimator::max_depth > 1, past the first vertex),
// indexed and compacted with the points: its throughput (the product of f cos / p and
// 1 / (1 - q) of Russian roulette from the camera to this point) and pbrt-v4's eta scale
// (the squared relative indices of the transmissions, which Russian roulette divides out).
struct PathStates {
  alignas(64) float throughput_r[lane_array], throughput_g[lane_array], throughput_b[lane_array];
  alignas(64) float eta_scale[lane_array];
  // 1 once the path has taken a non-specular BSDF sample (pbrt-v4's anyNonSpecularBounces),
  // else 0: where Estimator::regularize turns the next vertices' BSDFs rough
  alignas(64) float rough[lane_array];
  // --light-paths: 1 where the path's first vertex (the camera's hit) is of a kind the light
  // tracer joins to the camera (light_traced_kind), else 0 (set by continue_paths at vertex 1)
  alignas(64) float first_rough[lane_array];
};

// The radiance the light and BSDF techniques add to each shading point in this sample:
// summed into its pixel by accumulate (through PixelLanes::shade_of), or, at a path's later
// vertices, times the path's throughput into its lane (path.h).
struct PointRadiance {
  alignas(64) float r[lane_array], g[lane_array], b[lane_array];
};

// The textured shading points of this sample: point, texture, triangle, barycentrics, texel.
struct TexturedPoints {
  int count = 0;
  alignas(64) int32_t point[lane_array], texture[lane_array];
  alignas(64) uint32_t geom[lane_array], prim[lane_array];
  alignas(64) float u[lane_array], v[lane_array];
  alignas(64) const float* texel[lane_array];
};

// One technique's sample over the shading points: its random numbers, its contribution if
// the ray it traces says so, and the lanes that trace one. A BSDF sample also keeps its
// throughput (f cos / pdf) and pdf, for the emitter-hit queue.
struct TechniqueSample {
  alignas(64) float u0[lane_array], u1[lane_array], u2[lane_array], u3[lane_array];
  alignas(64) float cr[lane_array], cg[lane_array], cb[lane_array];  // contribution
  alignas(64) int32_t valid[lane_array];                             // the lane traces a ray
  // a path's continuation sample, bounce rays against the emitters: the path ends at this
  // vertex (-1; wave/path.h mark_path_ends), so its ray looks for the emitters alone
  alignas(64) int32_t ends[lane_array];
  alignas(64) float beta_r[lane_array], beta_g[lane_array], beta_b[lane_array];  // BSDF sample: f cos / pdf
  alignas(64) float pdf[lane_array];                                             // BSDF sample: its pdf
  alignas(64) int32_t delta[lane_array];                                         // BSDF sample: a specular lobe
  alignas(64) float wb[lane_array];  // the BSDF technique's MIS weight (AOV)
  // --heuristic optimal (wave/optimal_mis.h), the light stage's sample: the light and BSDF
  // techniques' densities of it (a delta source's: pl = its pick, pb = 0); the emitter-hit
  // stage: the light technique's density of each queued hit
  alignas(64) float pl[lane_array], pb[lane_array];
};

// The BSDF-sampled rays that reached the front of an emitter (the MIS weight stage runs on
// these only).
struct EmitterHitQueue {
  int count = 0;
  alignas(64) float x[lane_array], y[lane_array], z[lane_array];     // the shading point
  alignas(64) float dx[lane_array], dy[lane_array], dz[lane_array];  // the sampled direction
  alignas(64) float dist[lane_array];                                // to the emitter, from x
  alignas(64) float beta_r[lane_array], beta_g[lane_array], beta_b[lane_array];  // f cos / pdf of the sample
  alignas(64) float pdf[lane_array];                                             // the BSDF's pdf of it
  alignas(64) int32_t delta[lane_array];  // drawn from a specular lobe: MIS weight 1
  alignas(64) int32_t light[lane_array];
  alignas(64) int32_t point[lane_array];  // the entry's shading point
  // the bounce ray's origin and its distance to the emitter (for the visibility ray when
  // bounce rays see only the emitters), and 1 / 0 for a visible / occluded emitter
  alignas(64) float ox[lane_array], oy[lane_array], oz[lane_array], t[lane_array];
  alignas(64) int32_t needs_vis[lane_array];  // -1: its ray was traced against the emitters alone
  alignas(64) float vis[lane_array];
  alignas(64) int32_t valid[lane_array];
};

// Resampled importance sampling (wave/ris.h): each shading point's reservoir over the
// candidates seen so far: the sum of their resampling weights, and the kept candidate's
// integrand over its target (f Le cos / p-hat, per channel) and shadow ray.
struct RisReservoirs {
  alignas(64) float wsum[lane_array];
  alignas(64) float cr[lane_array], cg[lane_array], cb[lane_array];
  alignas(64) float ox[lane_array], oy[lane_array], oz[lane_array];
  alignas(64) float dx[lane_array], dy[lane_array], dz[lane_array], tfar[lane_array];
};

// The sampler's stream keys (sample/rng.h PairKeys) of pairs 0 .. pairs - 1, per tile lane
// (made once per tile by run_tile) and per shading point (compacted by camera_hits).
// Bit p of keyed: pair p is cached; without it the stages hash the pixel every sample.
struct SamplerKeys {
  static constexpr int pairs = 6;
  uint32_t keyed = 0;
  bool points_are_lanes = false;  // shading point k is tile lane k: points read lane_key
  alignas(64) uint32_t lane_key[pairs][3][lane_array];
  alignas(64) uint32_t point_key[pairs][3][lane_array];
  PairKeys lane_keys(int p) noexcept { return {lane_key[p][0], lane_key[p][1], lane_key[p][2]}; }
  PairKeys point_keys(int p) noexcept {
    return points_are_lanes ? lane_keys(p) : PairKeys{point_key[p][0], point_key[p][1], point_key[p][2]};
  }
  bool has(uint32_t pair) const noexcept { return pair < pairs && ((keyed >> pair) & 1u); }
};

// What one render counts, per worker.
struct TileCounters {
  uint64_t rejected_light = 0, rejected_bsdf = 0, rejected_camera = 0;
  uint64_t rays_camera = 0, rays_shadow = 0, rays_bounce = 0, rays_bounce_visibility = 0;
  uint64_t path_vertices = 0;  // shading points past the first vertex of paths (max_depth > 1)
  void reset() noexcept { *this = TileCounters{}; }
};

// --heuristic optimal (wave/optimal_mis.h): per tile lane, the moments of its pixel
// (OptimalMoment order) before this render (prior) and in it (sum), and this sample's
// alphas per channel; per shading point, what its BSDF sample met (an emitter or the sky:
// hit, the light technique's density pl, the balance-weighted contribution u and weight wb).
enum OptimalMoment : int { opt_a_ll = 0, opt_a_lb = 1, opt_a_bb = 2, opt_b_l = 3, opt_b_b = 6, opt_moments = 9 };
struct OptimalState {
  alignas(64) double prior[opt_moments][lane_array];
  alignas(64) double sum[opt_moments][lane_array];
  alignas(64) float alpha_l[3][lane_array], alpha_b[3][lane_array];
  alignas(64) int32_t hit[lane_array];
  alignas(64) float pl[lane_array], ur[lane_array], ug[lane_array], ub[lane_array], wb[lane_array];
};

// Participating media (wave/media.h): the state of one set of rays' flights, per ray (tile lanes for camera rays, shading
// points for bounce rays).
struct MediumLanes {
  alignas(64) int32_t med[lane_array];                 // in: the medium at the origin; out: at the hit
  alignas(64) float wr[lane_array], wg[lane_array], wb[lane_array];  // out: the flight's weight
  alignas(64) float er[lane_array], eg[lane_array], eb[lane_array];  // out: emission gathered, relative to the origin
  alignas(64) float u0[lane_array], u1[lane_array];   // in: hero channel, distance
  // the flight in progress
  alignas(64) float tau[lane_array], od[3][lane_array], absorb[3][lane_array];
  alignas(64) float ox[lane_array], oy[lane_array], oz[lane_array], tbase[lane_array];
  alignas(64) int32_t hero[lane_array], pending[lane_array];
  // the camera's flights, per tile lane (kept past the bounce rays' flights)
  alignas(64) float cwr[lane_array], cwg[lane_array], cwb[lane_array];
  // out: the ray's first stretch of a scattering medium that only vacuum precedes (eq_med,
  // -1 for none), from eq_a to eq_b along it (wave/equiangular.h)
  alignas(64) int32_t eq_med[lane_array];
  alignas(64) float eq_a[lane_array], eq_b[lane_array];
};

// --equiangular (wave/equiangular.h): the segment light samples of a set of rays, their
// shadow rays, contributions (times the throughput at the ray's origin) and random numbers.
struct SegmentLights {
  Ray16 shadow[max_packets];
  alignas(64) int32_t valid[lane_array];
  alignas(64) float cr[lane_array], cg[lane_array], cb[lane_array];
  alignas(64) float u0[lane_array], u1[lane_array], u2[lane_array], u3[lane_array];
  alignas(64) float br[lane_array], bg[lane_array], bb[lane_array];  // the throughput at the rays' origins
};

// --guide while it learns (src/render/guide.h): each tile lane's path of this sample,
// vertex by vertex: the point, the direction the path went on along, its density, the
// throughput after it and whether the vertex is a guided one (ok), and the light each
// vertex added to the pixel (the last row sums every vertex past the recorded ones).
struct GuidePathLanes {
  static constexpr int vertices = 16;
  alignas(64) float x[vertices][lane_array], y[vertices][lane_array], z[vertices][lane_array];
  alignas(64) float dx[vertices][lane_array], dy[vertices][lane_array], dz[vertices][lane_array];
  alignas(64) int32_t cls[vertices][lane_array];  // the point's class (wave/guide.h guide_classes)
  alignas(64) float pdf[vertices][lane_array];
  alignas(64) float tr[vertices][lane_array], tg[vertices][lane_array], tb[vertices][lane_array];
  alignas(64) float cr[vertices + 1][lane_array], cg[vertices + 1][lane_array], cb[vertices + 1][lane_array];
  alignas(64) uint8_t ok[vertices][lane_array];
  alignas(64) int32_t reached[lane_array];  // the vertices the lane's path reached this sample
};

// Owns a tile's GuidePathLanes, made on first use; a copy of the buffers starts without
// one (it holds one sample's scratch, nothing a copy needs).
struct GuidePathHolder {
  std::unique_ptr<GuidePathLanes> lanes;
  GuidePathHolder() = default;
  GuidePathHolder(const GuidePathHolder&) noexcept {}
  GuidePathHolder& operator=(const GuidePathHolder&) noexcept { return *this; }
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
      reset_query_fields(seg.shadow[p]);
      reset_hit(cam[p]);
      reset_hit(bounce[p]);
    }
  }
  PixelLanes lanes;
  TileSums sums;
  ShadingPoints points;   // the surface hits being shaded
  PathStates path;        // their paths' state
  PointRadiance radiance;  // what this sample's techniques found at each of them
  TexturedPoints textured;
  TechniqueSample tech;
  EmitterHitQueue queue;
  RisReservoirs ris;
  OptimalState opt;
  MediumLanes media;  // scenes with media only
  SegmentLights seg;  // --equiangular only
  SamplerKeys keys;
  TileCounters stats;
  GuidePathHolder guide;  // --guide while it learns
};

// One dimension pair of the sampler for the first `count` tile lanes (their pixels) or
// shading points, from the cached keys where the tile has them (the same bits); with
// v = nullptr the first dimension only.
inline void lane_pairs(const Estimator& est, TileBuffers& tb, uint32_t sample, uint32_t pair, int count, float* u,
                       float* v) noexcept {
  if (tb.keys.has(pair)) sample_pairs_keyed(est.sampler, est.seed, sample, pair, tb.keys.lane_keys(static_cast<int>(pair)), count, u, v);
  else sample_pairs(est.sampler, est.seed, tb.lanes.pixel, sample, est.spp, pair, count, u, v);
}
inline void point_pairs(const Estimator& est, TileBuffers& tb, uint32_t sample, uint32_t pair, int count, float* u,
                        float* v) noexcept {
  if (tb.keys.has(pair)) sample_pairs_keyed(est.sampler, est.seed, sample, pair, tb.keys.point_keys(static_cast<int>(pair)), count, u, v);
  else sample_pairs(est.sampler, est.seed, tb.points.pixel, sample, est.spp, pair, count, u, v);
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
