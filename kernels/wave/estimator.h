// Estimator: which Monte Carlo estimator a render runs (technique, light pick and point,
// MIS heuristic and mode, sample counts, sampler, seed, path depth and Russian roulette),
// as the stages read it.
#pragma once
#include <cstdint>

#include "light/table.h"
#include "mis.h"
#include "sample/rng.h"

namespace tuile {

// ris: resampled importance sampling of the light and BSDF techniques' candidates (wave/ris.h)
enum class Strategy : int { light = 0, bsdf = 1, mis = 2, ris = 3 };
// bvh: the light BVH (light/bvh.h), which depends on the shading point and its normal
enum class LightPick : int { all = 0, uniform = 1, area = 2, power = 3, bvh = 4 };
enum class MisMode : int { multi = 0, one = 1 };

struct Estimator {
  Strategy strategy = Strategy::mis;
  LightPick pick = LightPick::power;
  LightPoint point = LightPoint::solid_angle;
  Heuristic heuristic = Heuristic::power;
  MisParams mis;
  MisMode mode = MisMode::multi;
  int light_samples = 1;
  int bsdf_samples = 1;
  // --strategy ris: candidates per shading point from the light picker (M) and from BSDF
  // sampling (K)
  int ris_light = 8;
  int ris_bsdf = 1;
  SamplerKind sampler = SamplerKind::sobol;
  bool aov_mis_weight = false;  // accumulate the BSDF technique's MIS weight (AOV) at all
  uint32_t seed = 0;
  uint32_t spp = 16;
  // Paths: vertices that take a light sample and a BSDF sample (pbrt-v4's maxdepth: 1 is
  // direct lighting), the vertex after which Russian roulette may end a path (pbrt-v4:
  // after the BSDF sample of vertex 2 on, i.e. rr_depth 1), and the throughput below which
  // it plays: a path whose largest channel times eta scale m is below rr_threshold goes on
  // with probability m / rr_threshold. pbrt-v4's rule is 1; tuile's default 0.25 ends fewer
  // paths: 1.2-1.4 times the efficiency on the corpus's rooms (bench/results.md, "Russian
  // roulette's threshold").
  int max_depth = 1;
  int rr_depth = 1;
  float rr_threshold = 0.25f;
  // pbrt-v4's `regularize` (biased, off by default): once a path has taken a non-specular
  // BSDF sample, every later vertex's Trowbridge-Reitz alphas below 0.3 become
  // clamp(2 alpha, 0.1, 0.3) (smooth surfaces turn glossy), so that light sampling finds the
  // caustics through them (GeomView::mat_reg, wave/surface_hits.h regularize_points).
  bool regularize = false;
  // --guide (wave/guide.h, src/render/guide.h): path guiding, learned over the first
  // guide_learn samples (iterations ending at samples 1, 2, 4, ...), a share guide_alpha
  // of the directions drawn from it at diffuse points; unbiased
  bool guide = false;
  uint32_t guide_learn = 64;
  float guide_alpha = 0.5f;
  // --light-paths (src/render/light_paths.h): the caustic paths, whose first vertex from the
  // camera is rough (light_traced_kind: diffuse, a medium) and whose vertex next to an area
  // light scatters by a delta lobe, or whose first vertex is rough or a coated diffuse
  // (sun_traced_material) and whose vertex next to a distant source is near-specular
  // (GeomView::mat_lt_glossy), are traced from the lights and joined to the camera; the path
  // tracer leaves them out (drop_light_traced_hits; the light stage, sample_lights.h).
  // Unbiased: the two estimators split path space.
  bool light_paths = false;
  // --bdpt (src/render/bdpt.h): bidirectional path tracing replaces the path tracer and its
  // techniques (every strategy of a light and a camera subpath, balance heuristic).
  bool bdpt = false;
  // --light-paths=glossy: also an area light's light at a near-specular vertex (the same
  // bound as a distant source's) after a rough first one: the light tracer's, both of the
  // path tracer's techniques there left out (veach-mis's caustics of its small bright
  // source off its smoothest plate). Needs light_paths.
  bool light_paths_glossy = false;
  // --equiangular (wave/equiangular.h): in scenes with media, each path ray's direct light
  // scattered along its first stretch of a scattering medium, from a point drawn by
  // equiangular sampling towards a source (Kulla & Fajardo 2012), MIS-weighted against the
  // light samples at the free flights' collisions; unbiased
  bool equiangular = false;

  // probability of choosing the light technique in one-sample MIS
  float one_sample_light_prob() const {
    return static_cast<float>(light_samples) / static_cast<float>(light_samples + bsdf_samples);
  }
  bool one_sample() const { return strategy == Strategy::mis && mode == MisMode::one; }
};

}  // namespace tuile
