// The two ends of `tuile render`, shared by the single-process render and rank 0 of a
// distributed one: the start (output checked, scene loaded, pass plan, fingerprint, the
// film fresh or resumed from its checkpoint) and the finish (checkpoint, EXR with its
// metadata, PNG, messages, exit code).
#pragma once
#include <cstdint>
#include <string>

#include "app/cli.h"
#include "app/prepare.h"
#include "render/film.h"
#include "render/passes.h"

namespace tuile {

struct RenderJob {
  Prepared p;
  std::string out, ckpt, fingerprint;
  PassPlan plan;
  Film film;
  uint32_t spp = 0;
  uint64_t pixels = 0;
  double setup_seconds = 0;
};

// Throws (std::invalid_argument, SceneError, std::runtime_error) naming the file or flag.
RenderJob start_render_job(const RenderFlags& f);
void print_scene_warnings(const RenderFlags& f, const RenderJob& job);
// Returns the process's exit code (0, or 130 / 143 after a stop signal).
int finish_render_job(const RenderFlags& f, RenderJob& job, StopReason reason, const RenderStats& st,
                      double render_seconds, double estimated_error);

}  // namespace tuile
