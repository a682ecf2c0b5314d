// The tile pipelines: what one render shares with its tile tasks, and the registry of
// instantiated pipelines (run_tile specialised to the features a scene has) from which
// the renderer picks one per render. Internal to src/render.
#pragma once
#include <cstdint>
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

// The features this scene and estimator need (general_features when forced), and why.
Features pipeline_features(const SceneViews& v, const Estimator& est, bool general, std::string& why);
// The registered pipeline with those features, named after them ("general" when forced).
PipelineEntry pick_pipeline(const SceneViews& v, const Estimator& est, bool general, std::string& why);
// Whether a pipeline with these features is instantiated.
bool pipeline_registered(const Features& f);

}  // namespace tuile
