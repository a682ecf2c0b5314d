// Shared command-line handling: the render flags every subcommand takes, and scene +
// accelerator set-up with clear errors.
#pragma once
#include <string>

#include "render/render.h"
#include "scene/scene.h"

// CLI11's header costs every translation unit that includes it seconds of compile time (its
// validators are objects built in each one): only the files that define flags include it.
namespace CLI {
class App;
}

namespace tuile {

struct RenderFlags {
  std::string scene = "built-in:two-panels";
  int ris_light = 8, ris_bsdf = 1;
  std::string strategy = "mis", light_pick, light_point = "solid-angle", heuristic = "power", mis_mode = "multi";
  std::string sampler, res, output, aov, pipeline = "auto", bounce_rays = "auto";
  std::string bvh = "auto";  // --bvh: Embree's layout (EmbreeOptions::compact)
  std::string filter;  // pixel filter; "": the scene file's PixelFilter, else box
  std::string regularize;  // --regularize on|off; "": the scene file's Integrator
  bool guide = false;      // --guide
  std::string bdpt;          // --bdpt[=auto|on|off] (empty: auto; the flag alone: on)
  std::string light_paths;   // --light-paths[=auto|on|glossy|off] (empty: auto; the flag alone: on)
  std::string equiangular;   // --equiangular on | off (empty: the default)
  uint32_t guide_learn = 64;
  float guide_alpha = 0.5f;
  float beta = 2.f, alpha = 0.1f;
  int light_samples = 1, bsdf_samples = 1, spp = 0, threads = 0, tile = 16;
  int max_depth = 0;  // when not given: the scene file's (else 1)
  int rr_depth = 1;
  float rr_threshold = Estimator{}.rr_threshold;
  uint32_t seed = 0;
  bool quiet = false, stats = false, spp_given = false, tile_given = false, max_depth_given = false;
  bool strict = false;  // pbrt-v4's behaviour for missing images (an error, not a constant)
  // tuile render only (add_render_run_flags)
  double checkpoint_seconds = 0;  // > 0: save a checkpoint that often
  bool resume = false;
  double time_budget = 0, target_error = 0;
  std::string command_line;  // recorded in the EXR header
  double mpi_timeout = 300;  // under mpirun: seconds rank 0 waits for a rank's result before ending the job
};

// --light-paths asked for by name (on), not resolved by auto.
inline bool light_paths_asked(const RenderFlags& f) {
  return f.light_paths == "on" || f.light_paths == "true" || f.light_paths == "glossy";
}

void add_render_flags(CLI::App& app, RenderFlags& f);
// The flags of `tuile render` alone: --checkpoint, --resume, --time-budget, --target-error.
void add_render_run_flags(CLI::App& app, RenderFlags& f);
// --mpi-timeout (render and bench under mpirun).
void add_mpi_flags(CLI::App& app, RenderFlags& f);
// Applies the flags (command line over scene file over defaults) to the scene and options.
// Throws std::invalid_argument with a message naming the flag.
RenderOptions resolve_options(const RenderFlags& f, Scene& scene);

}  // namespace tuile
