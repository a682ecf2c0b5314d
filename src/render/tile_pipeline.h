// The tile pipelines: what one render shares with its tile tasks, and the registry of
// instantiated pipelines (run_tile specialised to the features a scene has) from which
// the renderer picks one per render. Internal to src/render.
#pragma once
#include <cstdint>
#include <iterator>
#include <string>
#include <vector>

#include "accel/embree.h"
#include "render/film.h"
#include "render/profile.h"
#include "render/views.h"
#include "sample/layout.h"
#include "wave/features.h"
#include "wave/tile.h"

namespace tuile {

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

// The instantiated pipelines, one list. pick_pipeline chooses among them by the features a
// scene and estimator need; a combination missing here is a bug (it throws). Their code is
// compiled in pipeline_parts translation units (src/render/pipelines/part_<k>.cpp, pipeline
// i in part i % pipeline_parts), so a parallel build compiles them side by side.
inline constexpr Features registered_pipelines[] = {
    general_features,                                                               // also mixed/mis/pick/materials
    {kind_all, false, false, false, false, bsdf_diffuse},                           // no-lights
    {kind_delta, true, false, true, false, bsdf_diffuse},
    {kind_delta, true, false, false, false, bsdf_diffuse},
    {kind_area | kind_rects, true, true, true, true, bsdf_diffuse},
    {kind_area | kind_rects, true, true, false, true, bsdf_diffuse},
    {kind_area | kind_rects, true, false, true, true, bsdf_diffuse},
    {kind_area | kind_rects, true, false, false, true, bsdf_diffuse},
    {kind_area | kind_rects, false, true, false, true, bsdf_diffuse},
    {kind_area, true, true, true, true, bsdf_diffuse},
    {kind_area, true, true, false, true, bsdf_diffuse},
    {kind_area, true, false, true, true, bsdf_diffuse},
    {kind_area, true, false, false, true, bsdf_diffuse},
    {kind_area, false, true, false, true, bsdf_diffuse},
    {kind_all, true, true, true, true, bsdf_diffuse},
    {kind_all, true, true, false, true, bsdf_diffuse},
    {kind_all, true, false, true, true, bsdf_diffuse},
    {kind_all, true, false, false, true, bsdf_diffuse},
    // scenes with other surfaces than diffuse: every kind of source and surface
    {kind_all, true, true, false, true, bsdf_all},
    {kind_all, false, true, false, true, bsdf_all},
    {kind_all, true, false, true, true, bsdf_all},
    {kind_all, true, false, false, true, bsdf_all},
    {kind_all, true, false, true, false, bsdf_all},
    {kind_all, true, false, false, false, bsdf_all},
};
inline constexpr size_t pipeline_count = std::size(registered_pipelines);
// The part that compiles each pipeline (same order as registered_pipelines). Pipelines that
// share stage instantiations (the same BSDF kinds, the same light kinds) go together: a
// stage instantiated in two parts is compiled twice.
inline constexpr int pipeline_part[] = {0, 1, 1, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0};
static_assert(std::size(pipeline_part) == pipeline_count);
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
