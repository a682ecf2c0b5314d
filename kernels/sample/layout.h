// SampleLayout: which of the sampler's dimension pairs each use of random numbers reads.
// A sample's numbers are a function of (seed, pixel, sample index, pair) only (sample/
// rng.h), so with the pairs handed out by purpose here an image does not depend on
// threads, tile order or pipeline, and a new use of random numbers gets pairs of its own
// instead of shifting the others. Per depth d (direct lighting is depth 0):
//   camera                      pair 0 (depth 0 only: the position in the pixel)
//   technique_choice(d)         one-sample MIS: which technique runs (first dimension)
//   bsdf(d, m)                  BSDF sample m < M
//   light_pick(d, j)            light sample j: the source (first dimension)
//   light_point(d, j)           light sample j: the point on the source
//   bsdf_lobe(d, m)             BSDF sample m: which lobe (first dimension; surfaces with
//                               several lobes only)
//   russian_roulette(d)         paths: whether the path goes on after vertex d (first
//                               dimension)
//   medium_flight(d, m)         scenes with media only: the free flight along BSDF sample
//                               m (m = M at depth 0: the camera ray's)
//   segment_light(d, j)         --equiangular (wave/equiangular.h): the light sample of the
//                               path's ray from vertex d through a medium (j = 0: the
//                               source and the distance, j = 1: the point on the source);
//                               j = 2, 3 at depth 0: the camera ray's
// with M = bsdf_samples and light samples j < light_passes (every source times N with
// --light-pick all). Resampled importance sampling (wave/ris.h) uses light samples j < M'
// for its light candidates and BSDF samples m < K' for its BSDF candidates, with the
// candidate's resampling number in the second dimension of light_pick(d, j) and
// bsdf_lobe(d, m), and BSDF sample K' for the path's continuation (M = K' + 1). Depth 0's pairs are 0, 1, 2 .. M + 1, then two per light sample, then
// the M lobe choices, then Russian roulette; each further depth starts after the last pair of the one before.
#pragma once
#include <cstdint>

namespace tuile {

struct SampleLayout {
  uint32_t bsdf_samples = 1;  // M
  uint32_t light_passes = 1;  // light samples per depth
  bool media = false;         // the scene has media: M + 1 pairs more per depth (medium_flight)
  bool equiangular = false;   // --equiangular in a scene with media: 4 pairs more per depth (segment_light)

  static constexpr uint32_t camera = 0;
  constexpr uint32_t per_depth() const noexcept {
    return 2 + 2 * bsdf_samples + 2 * light_passes + (media ? bsdf_samples + 1 : 0) + (equiangular ? 4 : 0);
  }
  constexpr uint32_t depth_base(uint32_t depth) const noexcept { return 1 + depth * per_depth(); }
  constexpr uint32_t technique_choice(uint32_t depth = 0) const noexcept { return depth_base(depth); }
  constexpr uint32_t bsdf(uint32_t m, uint32_t depth = 0) const noexcept { return depth_base(depth) + 1 + m; }
  constexpr uint32_t light_pick(uint32_t j, uint32_t depth = 0) const noexcept {
    return depth_base(depth) + 1 + bsdf_samples + 2 * j;
  }
  constexpr uint32_t light_point(uint32_t j, uint32_t depth = 0) const noexcept { return light_pick(j, depth) + 1; }
  constexpr uint32_t bsdf_lobe(uint32_t m, uint32_t depth = 0) const noexcept {
    return depth_base(depth) + 1 + bsdf_samples + 2 * light_passes + m;
  }
  constexpr uint32_t russian_roulette(uint32_t depth) const noexcept { return depth_base(depth) + 1 + 2 * bsdf_samples + 2 * light_passes; }
  // scenes with media (wave/media.h): the free flight along BSDF sample m < M of depth d
  // (hero channel, distance); m = M at depth 0 is the camera ray's
  constexpr uint32_t medium_flight(uint32_t m, uint32_t depth = 0) const noexcept {
    return depth_base(depth) + 2 + 2 * bsdf_samples + 2 * light_passes + m;
  }
  // --equiangular: the light sample of the ray that leaves vertex d (the path's
  // continuation) through a medium, j = 0 (source, distance) and 1 (point); j = 2 and 3 at
  // depth 0 are the camera ray's
  constexpr uint32_t segment_light(uint32_t j, uint32_t depth = 0) const noexcept {
    return medium_flight(bsdf_samples + 1, depth) + j;
  }
};

}  // namespace tuile
