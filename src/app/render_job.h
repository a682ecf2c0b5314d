// The two ends of `tuile render`, shared by the single-process render and rank 0 of a
// distributed one: the start (output checked, scene loaded, pass plan, fingerprint, the
// film fresh or resumed from its checkpoint) and the finish (checkpoint, EXR with its
// metadata, PNG, messages, exit code).
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "app/cli.h"
#include "app/prepare.h"
#include "render/film.h"
#include "render/passes.h"

namespace tuile {

struct RenderJob {
  std::shared_ptr<Prepared> p;  // shared with the Python module's scene, which renders it again
  std::string out, ckpt;
  std::string fingerprint;  // made when a checkpoint is read or written (empty until then)
  PassPlan plan;
  Film film;
  uint32_t spp = 0;
  uint64_t pixels = 0;
  double setup_seconds = 0;
};

// Throws (std::invalid_argument, SceneError, std::runtime_error) naming the file or flag.
// With `loaded` (a scene loaded and its BVH built before, by the Python module), the flags
// are resolved against it and f.scene is not read.
RenderJob start_render_job(const RenderFlags& f, std::shared_ptr<Prepared> loaded = nullptr);
// The passes of the job (film.samples .. spp), stopped by `cancel` (a stop signal, or
// KeyboardInterrupt in Python), --time-budget or --target-error; checkpoints every
// --checkpoint seconds; a progress line on stderr when `progress`.
struct JobRun {
  PassesResult res;
  double seconds = 0;           // the render's wall time
  double estimated_error = 0;   // --target-error: the image's estimated relMSE (NaN without it)
};
JobRun run_render_job(const RenderFlags& f, RenderJob& job, const std::atomic<bool>* cancel, bool progress);
void print_scene_warnings(const RenderFlags& f, const RenderJob& job);
// Returns the process's exit code (0, or 130 / 143 after a stop signal).
int finish_render_job(const RenderFlags& f, RenderJob& job, StopReason reason, const RenderStats& st,
                      double render_seconds, double estimated_error);

}  // namespace tuile
