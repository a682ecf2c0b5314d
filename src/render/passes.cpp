// render_passes: the pass loop with its stop rules (cancel flag, time budget, target).
#include "render/passes.h"

#include <algorithm>
#include <chrono>

#ifndef TUILE_PASS_DIVISOR
#define TUILE_PASS_DIVISOR 1
#endif

namespace tuile {

uint32_t PassPlan::next_end(uint32_t done, uint32_t spp) const noexcept {
  const uint64_t step = schedule == PassSchedule::doubling ? std::max<uint64_t>(1, done) : std::max<uint32_t>(1, pass_spp);
  return static_cast<uint32_t>(std::min<uint64_t>(spp, done + step));
}

PassPlan fixed_passes(uint64_t pixels) noexcept {
  const uint64_t target = (uint64_t(1) << 23) / TUILE_PASS_DIVISOR;
  const uint64_t per_pass = std::max<uint64_t>(1, target / std::max<uint64_t>(1, pixels));
  return {PassSchedule::fixed, static_cast<uint32_t>(std::min<uint64_t>(per_pass, 1u << 20))};
}

PassesResult render_passes(Renderer& renderer, Film& film, uint32_t spp, const PassPlan& plan, const PassControl& ctl) {
  PassesResult out;
  renderer.set_cancel_flag(ctl.cancel);
  const auto t0 = std::chrono::steady_clock::now();
  double last_seconds_per_sample = 0;
  Film pass;
  while (film.samples < spp) {
    if (ctl.cancel && ctl.cancel->load()) {
      out.reason = StopReason::cancelled;
      break;
    }
    const uint32_t begin = static_cast<uint32_t>(film.samples), end = plan.next_end(begin, spp);
    if (ctl.time_budget > 0 && last_seconds_per_sample > 0) {
      const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (elapsed + last_seconds_per_sample * (end - begin) > ctl.time_budget) {
        out.reason = StopReason::time_budget;
        break;
      }
    }
    RenderStats st;
    if (film.samples == 0) {  // a fresh film: the pass renders in place, and is cleared if cancelled
      st = renderer.render(film, begin, end);
      if (st.cancelled) film.reset(film.width, film.height);
    } else {
      if (pass.width != film.width || pass.height != film.height || pass.samples != 0) pass.reset(film.width, film.height);
      st = renderer.render(pass, begin, end, nullptr, nullptr, &film);
      if (!st.cancelled) film.add(pass);
    }
    if (st.cancelled) {
      out.reason = StopReason::cancelled;
      break;
    }
    last_seconds_per_sample = st.seconds / (end - begin);
    out.stats.add_counts(st);
    out.stats.worst_ratio = st.worst_ratio;
    out.stats.pipeline = st.pipeline;
    out.stats.bounce_against_emitters = st.bounce_against_emitters;
    if (ctl.after_pass) ctl.after_pass(film, out.stats);
    if (ctl.target_met && ctl.target_met(film)) {
      out.reason = film.samples < spp ? StopReason::target_met : StopReason::complete;
      break;
    }
  }
  renderer.set_cancel_flag(nullptr);
  return out;
}

}  // namespace tuile
