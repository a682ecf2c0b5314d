// A render as a sequence of passes: sample ranges fixed in advance by the plan (never by
// the clock), so that a render interrupted and resumed, or stopped by a budget, adds the
// same per-pass sums in the same order as one that ran through. Each pass renders into a
// fresh film that is added to the image only when every tile of it is done: a cancelled
// pass is dropped whole, and an image always holds complete passes (one sample count for
// every pixel). The first pass of a fresh film renders in place (nothing to protect).
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>

#include "render/film.h"
#include "render/render.h"

namespace tuile {

enum class PassSchedule : int {
  fixed = 0,     // passes of pass_spp samples per pixel (the last one cut to spp)
  doubling = 1,  // 1, 1, 2, 4, 8, ... samples per pixel: the total doubles every pass
};

struct PassPlan {
  PassSchedule schedule = PassSchedule::fixed;
  uint32_t pass_spp = 1;
  // The end of the pass that starts at `done` (< spp).
  uint32_t next_end(uint32_t done, uint32_t spp) const noexcept;
};

// Fixed passes of about 2^23 samples (at least one sample per pixel): small enough that a
// budget or a checkpoint is never far away (a fraction of a second on simple scenes, a
// few seconds on large ones), large enough that adding a pass to the image costs little
// against rendering it. A test build with TUILE_TEST_SCALE = k (CI's sanitizer tree) makes
// them 2^23 / k samples.
PassPlan fixed_passes(uint64_t pixels) noexcept;
inline PassPlan doubling_passes() noexcept { return {PassSchedule::doubling, 1}; }

enum class StopReason { complete, cancelled, time_budget, target_met, failed };

struct PassControl {
  const std::atomic<bool>* cancel = nullptr;  // set: stop at the next tile boundary, drop that pass
  double time_budget = 0;  // seconds (> 0): no pass starts that would end after it, at the last pass's speed
  std::function<bool(const Film&)> target_met;  // after each pass: true stops the render
  std::function<void(const Film&, const RenderStats&)> after_pass;  // checkpoints, progress
};

struct PassesResult {
  RenderStats stats;  // the counters of the passes that were kept
  StopReason reason = StopReason::complete;
};

// Renders film.samples .. spp (film.samples is where a resumed render starts; it must be a
// pass boundary of the plan).
PassesResult render_passes(Renderer& renderer, Film& film, uint32_t spp, const PassPlan& plan, const PassControl& ctl);

}  // namespace tuile
