// The tile pipelines: what one render shares with its tile tasks, and the registry of
// instantiated pipelines (run_tile specialised to the features a scene has) from which
// the renderer picks one per render. Internal to src/render.
#pragma once
#include <array>
#include <cstdint>
#include <iterator>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render/film.h"
#include "render/profile.h"
#include "render/views.h"
#include "scene/scene.h"
#include "sample/layout.h"
#include "wave/features.h"
#include "wave/tile.h"

namespace tuile {

class Guide;  // render/guide.h

// What one render shares with its tile tasks.
struct TileContext {
  const SceneViews& v;
  const Accel& accel;
  const Estimator& est;
  Film& film;
  int tile_size, tiles_x, width, height;
  int light_passes, bsdf_passes, light_count;
  SampleLayout layout;    // the sampler's dimension pairs by purpose
  float rate_light, rate_bsdf;  // n_i (multi-sample) or c_i (one-sample) of each technique (LightPass)
  bool bounce_against_emitters;   // bounce rays against the emitters, then visibility rays
  bool fresh_film;        // the film held no samples (zeros) when the render began
  Profile* profile;       // null when not profiling
  uint64_t origin_ticks;
  // --heuristic optimal: the moments of the pixels' earlier samples (9 per pixel, null
  // for none), how many samples they hold, and the film's own moment sums
  const double* opt_prior = nullptr;
  uint64_t opt_prior_samples = 0;
  double* opt_film = nullptr;
  // --guide while it learns: the guide the general pipeline's paths record into (null: none)
  Guide* guide_rec = nullptr;
};

// Per-thread profiling state.
struct ThreadProfile {
  uint64_t stage_ticks[stage_count] = {};
  // paths: the same per vertex (the last row gathers the deeper ones), the shading points
  // each vertex had and the packets of bounce rays it traced for them (first BSDF pass)
  uint64_t depth_ticks[profile_depths][stage_count] = {};
  uint64_t depth_points[profile_depths] = {}, depth_packets[profile_depths] = {}, depth_lane_packets[profile_depths] = {};
  std::vector<TraceEvent> events;
  RayRecord rays;
};

using TileFn = void (*)(const TileContext&, TileBuffers&, ThreadProfile*, int, uint32_t, uint32_t);
struct PipelineEntry {
  std::string name;
  TileFn fn;
};

// What a pipeline is chosen by. The scene's part is its feature bits as finalize_scene
// states them (SceneFeature, src/scene/scene.h: the one list of what a scene can have),
// the kinds of surface its geometry has and how many sources; the estimator's part is the
// strategy, the pick and the depth.
struct PipelineFacts {
  uint32_t scene = 0;            // SceneFeature bits
  int lights = 0;                // how many sources: 0, 1, or 2 for more
  bool materials = false;        // surfaces other than diffuse (SceneViews::has_materials)
  bool delta_surfaces = false;   // some surface can have a delta lobe (bsdf_delta_capable)
  Strategy strategy = Strategy::mis;
  bool pick_all = false;  // --light-pick all
  bool paths = false;     // max depth > 1
  constexpr bool has(uint32_t bit) const { return (scene & bit) != 0; }
};

// The scene bits a pipeline is chosen by (the others, such as textures or spheres, are read
// at run time): a new bit here adds the pipelines features_for gives it, by itself.
inline constexpr uint32_t pipeline_scene_bits[] = {feat_area_lights, feat_delta_lights, feat_rect_lights_only, feat_sky};

// The features of the pipeline for those facts: the stages and lookups they need, and no
// others.
constexpr Features features_for(const PipelineFacts& x) {
  const bool area = x.has(feat_area_lights), delta = x.has(feat_delta_lights);
  // A sky (and the escaped-ray stage it needs) runs in the general pipeline alone: no
  // specialisation for it has been measured to pay yet, and each would add compile time.
  // Media (their stages, wave/media.h, and the phase functions' points) likewise.
  if (x.has(feat_sky) || x.has(feat_media)) return general_features;
  Features f;
  f.light = x.lights > 0 && (x.strategy != Strategy::bsdf || delta);
  const bool ris = x.strategy == Strategy::ris && x.lights > 0;
  // a specular surface needs its BSDF samples whatever the strategy: no light sample finds
  // the light it reflects (sample_bsdf traces only those under --strategy light)
  f.bsdf = area && (x.strategy != Strategy::light || x.delta_surfaces);
  f.pick = f.light && x.lights > 1 && !x.pick_all;
  f.emitter_lookup = area;  // only area sources are seen by camera and bounce rays
  f.kinds = !area && !delta             ? kind_finite
            : !area                     ? kind_delta
            : delta                     ? kind_finite
            : x.has(feat_rect_lights_only) ? kind_area | kind_rects
                                        : kind_area;
  // (the phase function of points in a medium: only in the general pipeline, which media
  // scenes run)
  f.bsdfs = x.materials ? bsdf_all & ~bsdf_phase : bsdf_diffuse;
  if (x.materials) f.kinds = kind_finite;  // one pipeline per technique for every other surface
  if (x.paths && (area || delta)) {
    // paths go on along a BSDF sample at every vertex, and their bounce rays look up the
    // emitters they reach whatever the sources
    f.bsdf = true;
    f.emitter_lookup = true;
    if (!area) f.kinds = kind_finite;
  }
  if (ris) {  // the BSDF candidates and the last BSDF sample run on every scene with lights
    f.bsdf = true;
    f.emitter_lookup = true;
    if (!area) f.kinds = kind_finite;
  }
  if (!f.light && !f.bsdf) f = Features{kind_finite, false, false, false, false, bsdf_diffuse};
  return f;
}

// The registry: every feature set some scene and estimator can need, derived from every
// combination of the scene bits a pipeline is chosen by (pipeline_scene_bits) and the other
// facts (general_features first). A new fact or feature bit adds its pipelines here by
// itself; a combination features_for cannot produce gets none.
struct PipelineRegistry {
  Features f[64] = {};
  size_t count = 0;
};
constexpr PipelineRegistry derive_pipelines() {
  PipelineRegistry r;
  auto add = [&r](const Features& f) {
    for (size_t i = 0; i < r.count; ++i)
      if (r.f[i] == f) return;
    r.f[r.count++] = f;
  };
  add(general_features);
  constexpr size_t nbits = std::size(pipeline_scene_bits);
  for (uint32_t subset = 0; subset < 1u << nbits; ++subset) {
    uint32_t scene = 0;
    for (size_t b = 0; b < nbits; ++b)
      if (subset & 1u << b) scene |= pipeline_scene_bits[b];
    // a scene has as many sources as kinds of source at least
    const int groups = ((scene & feat_area_lights) != 0) + ((scene & feat_delta_lights) != 0) + ((scene & feat_sky) != 0);
    for (int lights = 0; lights < 3; ++lights) {
      if ((groups > 0) != (lights > 0) || groups > lights) continue;
      for (int materials = 0; materials < 2; ++materials)
        for (int delta_surfaces = 0; delta_surfaces <= materials; ++delta_surfaces)
          for (Strategy st : {Strategy::light, Strategy::bsdf, Strategy::mis, Strategy::ris})
            for (int pick_all = 0; pick_all < 2; ++pick_all)
              for (int paths = 0; paths < 2; ++paths)
                add(features_for({scene, lights, materials != 0, delta_surfaces != 0, st, pick_all != 0, paths != 0}));
    }
  }
  return r;
}
inline constexpr PipelineRegistry pipeline_registry = derive_pipelines();
inline constexpr size_t pipeline_count = pipeline_registry.count;
static_assert(pipeline_count < std::size(PipelineRegistry{}.f), "the registry's array holds every pipeline");
inline constexpr std::array<Features, pipeline_count> registered_pipelines = [] {
  std::array<Features, pipeline_count> a{};
  for (size_t i = 0; i < pipeline_count; ++i) a[i] = pipeline_registry.f[i];
  return a;
}();
// The translation unit that compiles a pipeline (src/render/pipelines/part_<k>.cpp), so
// that a parallel build compiles them side by side. Pipelines that share stage
// instantiations (the same BSDF kinds, the same light kinds) go together: a stage
// instantiated in two parts is compiled twice. Measured: the BSDF pipelines (with the
// general one), the diffuse area-light ones, the other diffuse ones.
constexpr int pipeline_part_of(const Features& f) {
  return f == general_features || f.bsdfs != bsdf_diffuse ? 0 : f.kinds == kind_area ? 2 : 1;
}
inline constexpr int pipeline_parts = 3;
// A build with -DTUILE_PIPELINES=general (CI's sanitizer tree, where instrumenting 24
// pipelines costs most of its build) compiles the general pipeline alone and runs it for
// every feature set: the same images, since every specialised pipeline equals it bit for
// bit (Pipeline.SpecialisedEqualsGeneral, in the trees that compile them all), and the
// same stages and kernels, every one of which the general pipeline runs.
#ifdef TUILE_GENERAL_PIPELINE_ONLY
inline constexpr bool general_pipeline_only = true;
#else
inline constexpr bool general_pipeline_only = false;
#endif
// Fills table[i] for the pipelines i of part Part (defined in render/tile_run.h,
// instantiated by render/pipelines/part_<Part>.cpp).
template <int Part> void register_pipeline_part(TileFn* table);

// The features this scene and estimator need (general_features when forced), and why.
Features pipeline_features(const SceneViews& v, const Estimator& est, bool general, std::string& why);
// The registered pipeline with those features, named after them ("general" when forced).
PipelineEntry pick_pipeline(const SceneViews& v, const Estimator& est, bool general, std::string& why);
// Whether a pipeline with these features is instantiated.
bool pipeline_registered(const Features& f);

}  // namespace tuile
