// `tuile render`: the image of a scene, rendered in passes that are never lost. The output
// is checked before any work; SIGINT / SIGTERM stop the render at the next tile boundary
// and write the image of the complete passes (exit 130 / 143) and a checkpoint; with
// --checkpoint SECONDS checkpoints are also saved as the render goes, and --resume
// continues the render a checkpoint belongs to; --time-budget and --target-error stop at
// a pass boundary. Every file is written atomically, every EXR carries its spp, seed,
// estimator, sampler, tuile's version, the render time and the command line.
#include <algorithm>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "app/commands.h"
#include "app/render_job.h"
#include "app/prepare.h"
#include "app/signals.h"
#include "measure/metrics.h"
#include "render/checkpoint.h"
#include "render/filter_table.h"
#include "render/passes.h"
#include "render/render.h"
#include "scene/atomic_file.h"
#include "scene/image_io.h"

namespace tuile {

namespace {

// Samples per pixel a budgeted render may reach when --spp is not given.
constexpr uint32_t budget_spp_cap = 1u << 20;

const char* reason_name(StopReason r) {
  switch (r) {
    case StopReason::complete: return "complete";
    case StopReason::cancelled: return "interrupted";
    case StopReason::time_budget: return "time-budget";
    case StopReason::target_met: return "target-error";
    case StopReason::failed: return "failed";
  }
  return "complete";
}

void check_nonnegative(double v, const char* flag) {
  if (!std::isfinite(v) || v < 0) throw std::invalid_argument(std::string(flag) + " must be a finite number >= 0");
}

}  // namespace

RenderJob start_render_job(const RenderFlags& f, std::shared_ptr<Prepared> loaded) {
  const auto t0 = std::chrono::steady_clock::now();
  check_nonnegative(f.checkpoint_seconds, "--checkpoint");
  check_nonnegative(f.time_budget, "--time-budget");
  check_nonnegative(f.target_error, "--target-error");
  if (light_paths_asked(f) && f.target_error > 0)
    throw std::invalid_argument("--target-error estimates the error from the camera's samples alone, which the light "
                                "paths' contributions (--light-paths) are not");
  // the output first, before any work (with -o; a scene's own Film name is checked after load)
  if (!f.output.empty()) check_output_path(f.output, {".exr"});
  RenderJob job;
  const bool loaded_scene = loaded != nullptr;
  if (loaded) {
    loaded->opt = resolve_options(f, loaded->scene);
    job.p = std::move(loaded);
  } else {
    job.p = std::make_shared<Prepared>(prepare(f));
  }
  Scene& scene = job.p->scene;
  RenderOptions& opt = job.p->opt;
  const bool budgeted = f.time_budget > 0 || f.target_error > 0;
  if (budgeted && !f.spp_given && scene.file_spp <= 0) opt.est.spp = budget_spp_cap;
  // -o, else the scene's Film "filename" (as an .exr), else tuile.exr; from Python
  // (`loaded`) only the output asked for, else none (the image is returned)
  job.out = "tuile.exr";
  if (!f.output.empty()) job.out = f.output;
  else if (job.p != nullptr && loaded_scene) job.out.clear();
  else if (!scene.file_output.empty()) job.out = with_extension(scene.file_output, ".exr");
  if (f.output.empty() && !job.out.empty()) check_output_path(job.out, {".exr"});
  if (!job.out.empty())  // its preview and checkpoint are written beside it: neither may be a directory
    for (const std::string& o : {with_extension(job.out, ".png"), checkpoint_path(job.out)}) {
      std::error_code ec;
      if (std::filesystem::is_directory(o, ec))
        throw std::invalid_argument(o + ": is a directory (the render writes " + (o == checkpoint_path(job.out) ? "its checkpoint" : "its PNG preview") +
                                    " there); choose another output name (-o)");
    }
  if (!job.out.empty())  // (an image the scene reads, e.g. its sky map, named as the output: refused before any work)
    for (const std::string& o : {job.out, with_extension(job.out, ".png"), checkpoint_path(job.out)})
      for (const std::string& in : scene.inputs) {
        std::error_code ec;
        if (std::filesystem::exists(o, ec) && std::filesystem::equivalent(o, in, ec))
          throw std::invalid_argument(o + " is a file the scene reads (" + in + "): the render would replace it; choose "
                                      "another output name (-o)");
      }
  if (job.out.empty() && (f.resume || f.checkpoint_seconds > 0))
    throw std::invalid_argument(std::string(f.resume ? "--resume" : "--checkpoint") +
                                " needs --output: the checkpoint is the output's name with .checkpoint");
  job.spp = opt.est.spp;
  job.pixels = static_cast<uint64_t>(scene.camera.width) * static_cast<uint64_t>(scene.camera.height);
  job.plan = f.target_error > 0 ? doubling_passes() : fixed_passes(job.pixels);
  // (a CRC of the whole scene, its meshes and maps: made now only where a checkpoint is read
  // or written as it renders; an interrupted render makes it on its way out)
  if (f.resume || f.checkpoint_seconds > 0) job.fingerprint = render_fingerprint(scene, opt, job.plan);
  if (!job.out.empty()) job.ckpt = checkpoint_path(job.out);
  if (f.resume) {
    Checkpoint c = load_checkpoint(job.ckpt);
    if (c.fingerprint != job.fingerprint)
      throw std::invalid_argument(job.ckpt + ": this checkpoint belongs to another render; it was made by\n" +
                                  c.fingerprint + "and this render is\n" + job.fingerprint +
                                  "(resume with the same scene, resolution, estimator, sampler and seed)");
    // what the fingerprint says, the film and the passes must agree with (a checkpoint of a
    // valid checksum written by hand, or by another build, could say otherwise)
    const bool passes = c.plan.schedule == job.plan.schedule && c.plan.pass_spp == job.plan.pass_spp;
    if (c.film.width != scene.camera.width || c.film.height != scene.camera.height || !passes)
      throw std::invalid_argument(job.ckpt + ": the checkpoint's film (" + std::to_string(c.film.width) + "x" +
                                  std::to_string(c.film.height) + ", " + std::to_string(c.film.samples) +
                                  " spp) or passes do not match its own fingerprint's render (" +
                                  std::to_string(scene.camera.width) + "x" + std::to_string(scene.camera.height) +
                                  "): a damaged or hand-made checkpoint");
    for (const auto* v : {&c.film.sum, &c.film.sum_sq})
      for (const double x : *v)
        if (!std::isfinite(x)) throw std::invalid_argument(job.ckpt + ": the checkpoint's sums hold NaN or infinity");
    if (c.film.samples > job.spp)
      throw std::invalid_argument(job.ckpt + ": the checkpoint holds " + std::to_string(c.film.samples) +
                                  " spp, more than the " + std::to_string(job.spp) + " asked for");
    job.film = std::move(c.film);
  } else {
    job.film.reset(scene.camera.width, scene.camera.height);
  }
  job.setup_seconds = seconds_since(t0);
  return job;
}

void print_scene_warnings(const RenderFlags& f, const RenderJob& job) {
  if (f.quiet) return;
  for (const std::string& w : job.p->scene.warnings) std::cerr << "tuile: warning: " << w << "\n";
  const Scene& s = job.p->scene;
  const bool glowing = std::any_of(s.media.begin(), s.media.end(), [](const Medium& m) { return m.Le.any_positive(); });
  if (s.lights.empty() && !glowing) std::cerr << "tuile: warning: the scene has no light; the image is black\n";
  if (f.resume)
    std::cerr << "tuile: resuming " << job.ckpt << " at " << job.film.samples << " of " << job.spp << " spp\n";
  else if (!job.ckpt.empty() && access(job.ckpt.c_str(), F_OK) == 0)
    std::cerr << "tuile: warning: " << job.ckpt << " (an earlier render's checkpoint) exists: this render starts from 0 spp "
              << "and replaces it if it writes one (to continue that render instead: --resume)\n";
}

int finish_render_job(const RenderFlags& f, RenderJob& job, StopReason reason, const RenderStats& st,
                      double render_seconds, double estimated_error) {
  const RenderOptions& opt = job.p->opt;
  const Film& film = job.film;
  const bool interrupted = reason == StopReason::cancelled || reason == StopReason::failed;
  if (interrupted && film.samples == 0) {  // no pass complete: the files of an earlier render stay as they were
    std::fprintf(stderr, "tuile: %s before its first pass was complete: nothing written (%s and its checkpoint, if any, are "
                         "as they were)\n",
                 reason == StopReason::failed ? "the job failed" : "interrupted", job.out.c_str());
    return reason == StopReason::failed ? 1 : exit_code_for_signal(stop_signal());
  }
  // what the render has, before anything else can go wrong
  bool checkpoint_saved = false;
  if (interrupted || f.checkpoint_seconds > 0) {
    try {
      if (job.fingerprint.empty()) job.fingerprint = render_fingerprint(job.p->scene, opt, job.plan);
      save_checkpoint(job.ckpt, job.fingerprint, job.plan, film);
      checkpoint_saved = true;
    } catch (const std::exception& e) {
      std::cerr << "tuile: warning: " << e.what() << "\n";
    }
  }
  std::vector<ImageLayer> layers;
  if (opt.aov_variance) layers.push_back({"variance", 3, film.variance_of_mean()});
  if (opt.aov_mis_weight) layers.push_back({"mis_weight", 1, film.mis_weight()});
  const std::vector<float> img = film.mean();
  ExrMetadata meta;
  meta.integers = {{"spp", static_cast<int>(film.samples)}, {"seed", static_cast<int>(opt.est.seed)}};
  static const char* samplers[] = {"independent", "stratified", "sobol"};
  meta.text = {{"estimator", describe(opt.est)},
               {"sampler", samplers[static_cast<int>(opt.est.sampler)]},
               {"tuileVersion", TUILE_VERSION},
               {"commandLine", f.command_line},
               {"stoppedBy", reason_name(reason)},
               {"pixelFilter", describe(opt.filter)}};
  meta.reals = {{"renderSeconds", render_seconds}};
  if (f.target_error > 0) meta.reals.emplace_back("estimatedRelMSE", estimated_error);
  write_exr(job.out, film.width, film.height, img, layers, meta);
  write_png(with_extension(job.out, ".png"), film.width, film.height, img);

  if (!f.quiet) {
    std::fprintf(stderr, "tuile: %s %dx%d, %llu spp, %s\n", job.p->scene.source.c_str(), film.width, film.height,
                 static_cast<unsigned long long>(film.samples), describe(opt.est).c_str());
    std::fprintf(stderr, "tuile: setup %.3f s, render %.3f s, %.2f M samples/s -> %s\n", job.setup_seconds,
                 render_seconds, st.seconds > 0 ? static_cast<double>(st.samples) / st.seconds * 1e-6 : 0.0,
                 job.out.c_str());
    if (reason == StopReason::time_budget)
      std::fprintf(stderr, "tuile: time budget of %.3g s: stopped after %llu spp\n", f.time_budget,
                   static_cast<unsigned long long>(film.samples));
    if (f.target_error > 0)
      std::fprintf(stderr, "tuile: estimated relMSE %.3g %s target %.3g after %llu spp (%.4g M samples)\n",
                   estimated_error, estimated_error < f.target_error ? "below the" : "still above the", f.target_error,
                   static_cast<unsigned long long>(film.samples), static_cast<double>(film.samples * job.pixels) * 1e-6);
  }
  if (interrupted) {
    std::fprintf(stderr, "tuile: %s: %s holds the %llu complete spp%s\n",
                 reason == StopReason::failed ? "the job failed" : "interrupted", job.out.c_str(),
                 static_cast<unsigned long long>(film.samples),
                 checkpoint_saved ? ("; continue with --resume (checkpoint " + job.ckpt + ")").c_str() : "");
    return reason == StopReason::failed ? 1 : exit_code_for_signal(stop_signal());
  }
  if (f.stats) {
    const std::vector<float> var = film.variance_of_mean();
    double mv = 0;
    for (float v : var) mv += v;
    mv /= var.empty() ? 1.0 : static_cast<double>(var.size());
    std::printf("rejected_nonfinite camera=%llu light=%llu bsdf=%llu\n",
                static_cast<unsigned long long>(st.rejected_camera), static_cast<unsigned long long>(st.rejected_light),
                static_cast<unsigned long long>(st.rejected_bsdf));
    std::printf("worst_accident %.6g (largest single-sample luminance / its pixel's mean)\n", st.worst_ratio);
    if (opt.est.light_paths) std::printf("mean_variance_of_mean unavailable (the camera's samples alone: --light-paths)\n");
    else std::printf("mean_variance_of_mean %.6g\n", mv);
  }
  return 0;
}

JobRun run_render_job(const RenderFlags& f, RenderJob& job, const std::atomic<bool>* cancel, bool progress) {
  Film& film = job.film;
  const uint32_t spp = job.spp;
  const uint64_t pixels = job.pixels;
  Renderer renderer(job.p->scene, *job.p->accel, job.p->opt);
  JobRun run;
  run.estimated_error = NAN;
  PassControl ctl;
  ctl.cancel = cancel;
  ctl.time_budget = f.time_budget;
  if (f.target_error > 0)
    ctl.target_met = [&](const Film& fl) {
      run.estimated_error = estimated_relmse(fl);
      return run.estimated_error < f.target_error;
    };
  auto last_checkpoint = std::chrono::steady_clock::now();
  const auto render_start = last_checkpoint;
  bool shown = false;
  ctl.after_pass = [&](const Film& fl, const RenderStats& st) {
    if (f.checkpoint_seconds > 0 && seconds_since(last_checkpoint) >= f.checkpoint_seconds) {
      try {
        save_checkpoint(job.ckpt, job.fingerprint, job.plan, fl);
      } catch (const std::exception& e) {  // the render goes on; its image is still written at the end
        std::cerr << "\ntuile: warning: " << e.what() << "\n";
      }
      last_checkpoint = std::chrono::steady_clock::now();
    }
    const double elapsed = seconds_since(render_start);
    if (progress && (elapsed > 1.0 || shown) && st.seconds > 0) {
      const double rate = static_cast<double>(st.samples) / st.seconds;
      const double eta = static_cast<double>((spp - fl.samples) * pixels) / rate;
      std::fprintf(stderr, "\rtuile: %5.1f%%  %.2f M samples/s  ETA %.1f s   ",
                   100.0 * static_cast<double>(fl.samples) / spp, rate * 1e-6, eta);
      shown = true;
    }
  };
  run.res = render_passes(renderer, film, spp, job.plan, ctl);
  if (shown) std::fprintf(stderr, "\n");
  run.seconds = seconds_since(render_start);
  return run;
}

int run_render(const RenderFlags& f) {
  RenderJob job = start_render_job(f);
  print_scene_warnings(f, job);
  const std::atomic<bool>& stop = install_stop_signals();
  const JobRun run = run_render_job(f, job, &stop, !f.quiet && isatty(2));
  return finish_render_job(f, job, run.res.reason, run.res.stats, run.seconds, run.estimated_error);
}

}  // namespace tuile
