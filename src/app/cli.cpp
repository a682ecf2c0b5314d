// The render flags every subcommand takes, resolved against the scene file's settings
// into RenderOptions; scene loading and accelerator set-up with clear errors.
#include "app/cli.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "render/filter_table.h"
#include "render/bdpt.h"
#include "render/light_paths.h"

namespace tuile {

void add_render_flags(CLI::App& app, RenderFlags& f) {
  app.add_option("scene", f.scene, "Scene: a pbrt-v4 file (.pbrt, .pbrt.gz) or built-in:two-panels / built-in:cornell")
      ->capture_default_str();
  app.add_option("--strategy", f.strategy,
                 "light | bsdf | mis | ris (resampled importance sampling of --ris-light light and --ris-bsdf BSDF "
                 "candidates, one shadow ray)")
      ->capture_default_str();
  app.add_option("--ris-light", f.ris_light, "ris: candidates from the light picker per shading point")->capture_default_str();
  app.add_option("--ris-bsdf", f.ris_bsdf, "ris: candidates from BSDF sampling per shading point")->capture_default_str();
  app.add_option("--light-pick", f.light_pick,
                 "all (every source, N points each) | uniform (p = 1/S) | area (p = A/sum A) | power (p ~ power) | "
                 "bvh (a light BVH: p ~ each source's importance for the shading point); default: the scene file's "
                 "lightsampler, else power");
  app.add_option("--light-point", f.light_point, "area (uniform by area, pdf d^2/(cos A)) | solid-angle")
      ->capture_default_str();
  app.add_option("--heuristic", f.heuristic, "balance | power | cutoff | maximum (Veach & Guibas 1995) | optimal (Kondapaneni et al. "
                 "2019: per-pixel optimal weights at the first vertex, power after it)")
      ->capture_default_str();
  app.add_option("--beta", f.beta, "power heuristic exponent")->capture_default_str();
  app.add_option("--alpha", f.alpha, "cutoff heuristic threshold")->capture_default_str();
  app.add_option("--mis-mode", f.mis_mode, "multi (n light + m BSDF samples) | one (one technique at random)")
      ->capture_default_str();
  app.add_option("--light-samples", f.light_samples, "light samples per pixel sample (per source with --light-pick all)")
      ->capture_default_str();
  app.add_option("--bsdf-samples", f.bsdf_samples, "BSDF samples per pixel sample")->capture_default_str();
  app.add_option("--max-depth", f.max_depth,
                 "path vertices that sample lights and the BSDF (pbrt's maxdepth; 1 = direct lighting); default: the "
                 "scene file's Integrator (pbrt's 5 when it gives none), 1 for the built-in scenes")
      ->each([&f](const std::string&) { f.max_depth_given = true; });
  app.add_option("--rr-depth", f.rr_depth,
                 "Russian roulette may end a path after its vertex rr-depth + 1 (pbrt-v4's rule: 1)")
      ->capture_default_str();
  app.add_option("--rr-threshold", f.rr_threshold,
                 "Russian roulette plays where a path's throughput (largest channel, times eta scale) is below it, "
                 "and lets the path go on with probability throughput / threshold; pbrt-v4's rule is 1, the default "
                 "ends fewer paths (more efficient on the rooms measured)")
      ->capture_default_str();
  app.add_option("--regularize", f.regularize,
                 "on | off: pbrt-v4's path regularization, biased: after a path's first non-specular bounce, "
                 "Trowbridge-Reitz alphas below 0.3 become clamp(2 alpha, 0.1, 0.3), smooth surfaces glossy, so "
                 "light sampling finds caustics through them (fewer fireflies, a blurred image of them); default: the "
                 "scene file's Integrator \"regularize\", else off");
  app.add_flag("--guide", f.guide,
               "path guiding (unbiased): a distribution of the light arriving at each region of the scene, learned "
               "from the first --guide-learn samples' paths, drawn from at diffuse points and in media with "
               "probability --guide-alpha and mixed with BSDF sampling (MIS sees the mixture's density); over MPI the "
               "ranks learn together (the single process's image)");
  app.add_flag("--bdpt{on}", f.bdpt,
               "[=auto|on|off] bidirectional path tracing (Veach; pbrt-v4's bdpt, unbiased) instead of the path tracer: "
               "a camera and a light subpath per pixel and sample, every join of a prefix of each weighted by the balance "
               "heuristic (the light of a small or hidden lamp that light samples rarely reach: veach-bidir); area, "
               "point, spot and distant sources and skies, homogeneous media (but a source at infinity with the camera in a "
               "medium), no curves yet; default auto: on where the scene file asks for Integrator "
               "\"bdpt\", bdpt renders the scene and no path tracer's option (--guide, --light-paths, --equiangular "
               "on, --regularize on, --heuristic optimal, --aov, --target-error) is given");
  app.add_flag("--light-paths{on}", f.light_paths,
               "[=auto|on|glossy|off] light tracing for the caustics (unbiased): the paths whose first vertex from the "
               "camera is diffuse or in a medium and whose vertex next to an area light scatters by a delta lobe (a "
               "mirror, smooth glass), or whose first vertex is diffuse or a coated diffuse (coat alpha 0.075 or more) and "
               "whose vertex next to a distant source (a sun) scatters by a glossy lobe of alpha 0.25 or less (0.1 with "
               "glossy), are "
               "traced from the lights and joined to the camera, and the path tracer leaves them out (it finds them only "
               "by chance); glossy: an area light's light off such a glossy lobe too (a small bright source's caustics "
               "off near-mirrors); the flag alone is on (a value follows after '=' or a space); default auto: on in scenes with a sun and such a glossy surface, or with "
               "an area light, smooth glass or a mirror and a medium that scatters (volumetric caustics), or where 0.3% of "
               "the area lights' power or more falls on smooth glass or a mirror from a light that looks small from it "
               "(a lamp's caustics through glass onto surfaces); glossy where 1% "
               "of the area lights' power or more falls on such a surface from a light that looks small from it; unless "
               "--max-depth 1, --aov variance or --target-error");
  app.add_option("--equiangular", f.equiangular,
                 "auto | on | off: in scenes with media, a light sample more per ray through a medium, at a distance "
                 "drawn by equiangular sampling towards a source (Kulla & Fajardo 2012) and MIS-weighted against the "
                 "light samples at the free flights' collisions (unbiased): the light of a small source that the "
                 "medium around it scatters, without the 1 / r^2 of the collisions next to it; default auto: on in "
                 "scenes with a medium that scatters, unless --strategy bsdf or ris, --mis-mode one, --light-pick all, "
                 "--heuristic optimal or --guide");
  app.add_option("--guide-learn", f.guide_learn, "--guide: the samples per pixel it learns from (iterations of 1, 1, 2, 4, ...)")
      ->capture_default_str();
  app.add_option("--guide-alpha", f.guide_alpha, "--guide: the share of directions drawn from the guide")->capture_default_str();
  app.add_option("--spp", f.spp, "samples per pixel (default: the scene file's, else 16)")
      ->each([&f](const std::string&) { f.spp_given = true; });
  app.add_option("--seed", f.seed, "random seed")->capture_default_str();
  app.add_option("--sampler", f.sampler, "independent | stratified | sobol (default sobol)");
  app.add_option("--filter", f.filter,
                 "pixel filter: box | triangle | gaussian | mitchell | sinc (default: the scene file's PixelFilter, "
                 "with its parameters, else box; another filter than the file's takes pbrt-v4's defaults)");
  app.add_option("--threads", f.threads, "worker threads (0 = all cores)")->capture_default_str();
  app.add_option("--tile", f.tile,
                 "tile side in pixels (1..32; default 16, 32 for paths: more paths per tile keep deep vertices' "
                 "packets fuller; the image does not change)")
      ->each([&f](const std::string&) { f.tile_given = true; });
  app.add_option("--res", f.res, "resolution WxH, overrides the scene's film");
  app.add_option("--aov", f.aov, "extra EXR layers: variance,mis_weight");
  app.add_option("--pipeline", f.pipeline,
                 "auto (specialised to the scene's features) | general (every stage, the reference)")
      ->capture_default_str();
  app.add_option("--bounce-rays", f.bounce_rays,
                 "scene (nearest hit in the whole scene) | emitters (the rays that end their path, the last vertex's "
                 "and those of the paths Russian roulette ends there, find their nearest emitter, then an occlusion ray "
                 "to it, or to infinity under a sky where they find none; the others, and those that start in a medium, "
                 "their nearest hit in the whole scene) | auto (emitters when they are at most half of the primitives, "
                 "unless the scene has \"interface\" surfaces between media)")
      ->capture_default_str();
  app.add_option("--bvh", f.bvh,
                 "Embree's layout: auto (compact from 2^23 stored triangles on) | fast (triangles copied into the "
                 "leaves: the fastest traversal) | compact (leaves that index the scene's vertex buffers: ~29 bytes "
                 "per triangle less, a faster build, ~30% fewer samples/s); the image does not change")
      ->capture_default_str();
  app.add_flag("--quiet", f.quiet, "no progress or summary on stderr");
  app.add_flag("--strict", f.strict,
               "as pbrt-v4, stop on an image texture that cannot be read (default: its constant mean, 0.5, with a warning)");
  app.add_flag("--stats", f.stats, "print rejected samples, worst accident and mean variance");
}

void add_render_run_flags(CLI::App& app, RenderFlags& f) {
  app.add_option("--checkpoint", f.checkpoint_seconds,
                 "save the film to OUT.checkpoint every SECONDS (at the end of a pass; atomically; 0, the default: only when interrupted)");
  app.add_flag("--resume", f.resume, "continue the render whose checkpoint is OUT.checkpoint, up to --spp");
  app.add_option("--time-budget", f.time_budget,
                 "render whole passes until the next one would end after SECONDS (--spp, if given, still caps)");
  app.add_option("--target-error", f.target_error,
                 "stop when the image's estimated relMSE falls below X (samples double per pass; --spp caps)");
}

void add_mpi_flags(CLI::App& app, RenderFlags& f) {
  app.add_option("--mpi-timeout", f.mpi_timeout,
                 "under mpirun: end the job when a rank sends nothing for SECONDS while it has work")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 1e6))
      ->check(CLI::Validator(
          [](std::string& s) {  // (a NaN passes CLI::Range: every comparison with it is false)
            const double v = std::strtod(s.c_str(), nullptr);
            return v >= 0.1 && v <= 1e6 ? std::string() : "--mpi-timeout " + s + " is not a number in [0.1, 1e6]";
          },
          "", ""));
}

namespace {

// A flag's value parsed, its error naming the flag ("--light-pick: unknown light pick ...").
template <class F> auto flag_value(const char* flag, bool given, F&& parse) -> decltype(parse()) {
  try {
    return parse();
  } catch (const std::invalid_argument& e) {
    if (!given) throw;  // the scene file's value: the message names it
    throw std::invalid_argument(std::string(flag) + ": " + e.what());
  }
}

}  // namespace

RenderOptions resolve_options(const RenderFlags& f, Scene& scene) {
  RenderOptions o;
  Estimator& e = o.est;
  e.strategy = flag_value("--strategy", true, [&] { return parse_strategy(f.strategy); });
  // ris takes its light candidates from the light BVH unless told otherwise
  const std::string pick = !f.light_pick.empty()             ? f.light_pick
                           : !scene.file_light_pick.empty() ? scene.file_light_pick
                           : e.strategy == Strategy::ris    ? "bvh"
                                                            : "power";
  e.pick = flag_value("--light-pick", !f.light_pick.empty(), [&] { return parse_light_pick(pick); });
  e.ris_light = f.ris_light;
  e.ris_bsdf = f.ris_bsdf;
  e.point = flag_value("--light-point", true, [&] { return parse_light_point(f.light_point); });
  e.heuristic = flag_value("--heuristic", true, [&] { return parse_heuristic(f.heuristic); });
  e.mode = flag_value("--mis-mode", true, [&] { return parse_mis_mode(f.mis_mode); });
  e.mis.beta = f.beta;
  e.mis.alpha = f.alpha;
  e.light_samples = f.light_samples;
  e.bsdf_samples = f.bsdf_samples;
  e.max_depth = f.max_depth_given ? f.max_depth : scene.file_max_depth > 0 ? scene.file_max_depth : 1;
  e.rr_depth = f.rr_depth;
  e.rr_threshold = f.rr_threshold;
  e.guide = f.guide;
  // --bdpt: auto is on where the file asks for pbrt's bdpt, bdpt renders the scene and no
  // option of the path tracer's is given (else a warning says what renders the file)
  if (f.bdpt == "on" || f.bdpt == "true") e.bdpt = true;
  else if (f.bdpt == "off" || f.bdpt == "false") e.bdpt = false;
  else if (f.bdpt.empty() || f.bdpt == "auto") {
    e.bdpt = false;
    if (scene.file_integrator == "bdpt") {
      std::string why = bdpt_refusal(scene);
      if (why.empty() && (f.guide || light_paths_asked(f) || f.equiangular == "on" || f.regularize == "on" ||
                          f.heuristic == "optimal" || !f.aov.empty() || f.target_error > 0))
        why = "an option of the path tracer's is given";
      if (why.empty()) e.bdpt = true;
      else
        std::fprintf(stderr, "tuile: warning: %s: Integrator \"bdpt\" rendered by tuile's path tracer (next-event "
                     "estimation and MIS at every vertex): %s\n", scene.source.c_str(), why.c_str());
    }
  } else throw std::invalid_argument("--bdpt: '" + f.bdpt + "' is not auto, on or off");
  if (e.bdpt && f.target_error > 0)
    throw std::invalid_argument("--bdpt: --target-error reads the camera samples' variance, which bdpt's splats do not "
                                "give; render a fixed --spp");
  if (f.regularize.empty()) e.regularize = scene.file_regularize && !e.bdpt;
  else if (f.regularize == "on") e.regularize = true;
  else if (f.regularize == "off") e.regularize = false;
  else throw std::invalid_argument("--regularize: '" + f.regularize + "' is not on or off");
  e.guide_learn = f.guide_learn;
  e.guide_alpha = f.guide_alpha;
  if (f.spp_given && f.spp < 1) throw std::invalid_argument("--spp must be >= 1");
  const int spp = f.spp_given ? f.spp : scene.file_spp > 0 ? scene.file_spp : 16;
  e.spp = static_cast<uint32_t>(spp);
  const std::string sampler = !f.sampler.empty() ? f.sampler : !scene.file_sampler.empty() ? scene.file_sampler : "sobol";
  e.sampler = flag_value("--sampler", !f.sampler.empty(), [&] { return parse_sampler(sampler); });
  e.seed = f.seed;
  if (f.filter.empty()) o.filter = scene.file_filter;
  else {
    const FilterKind k = parse_filter_kind(f.filter);  // its message names --filter
    o.filter = k == scene.file_filter.kind ? scene.file_filter : default_filter(k);
  }
  o.threads = f.threads;
  o.tile = f.tile_given || e.max_depth == 1 ? f.tile : 32;
  if (!f.res.empty()) {
    // W and H as decimal digits alone (no sign, no spaces): a number too long for an int is
    // absurd, not wrapped round
    const size_t cut = f.res.find_first_of("xX");
    auto axis = [&](const std::string& s, long long& v) {
      if (s.empty() || s.size() > 12 || s.find_first_not_of("0123456789") != std::string::npos) return false;
      v = std::stoll(s);
      return true;
    };
    long long w = 0, h = 0;
    if (cut == std::string::npos || !axis(f.res.substr(0, cut), w) || !axis(f.res.substr(cut + 1), h))
      throw std::invalid_argument("--res '" + f.res + "': expected WxH, e.g. 512x512");
    if (w < 1 || h < 1 || w > 32768 || h > 32768 || static_cast<double>(w) * static_cast<double>(h) > double(1u << 28))
      throw std::invalid_argument("--res '" + f.res + "': absurd resolution (1..32768 per axis, at most 2^28 pixels)");
    scene.camera.width = static_cast<int>(w);
    scene.camera.height = static_cast<int>(h);
  }
  o.bounce = flag_value("--bounce-rays", true, [&] { return parse_bounce_trace(f.bounce_rays); });
  if (f.pipeline == "general") o.general_pipeline = true;
  else if (f.pipeline != "auto") throw std::invalid_argument("--pipeline '" + f.pipeline + "': expected auto or general");
  size_t start = 0;
  while (start < f.aov.size()) {
    size_t end = f.aov.find(',', start);
    if (end == std::string::npos) end = f.aov.size();
    const std::string a = f.aov.substr(start, end - start);
    if (a == "variance") o.aov_variance = true;
    else if (a == "mis_weight") o.aov_mis_weight = o.est.aov_mis_weight = true;
    else if (!a.empty()) throw std::invalid_argument("--aov: unknown layer '" + a + "' (expected variance, mis_weight)");
    start = end + 1;
  }
  // --equiangular: auto is on in a scene with a medium that scatters, where it combines
  // with the estimator
  if (f.equiangular == "on") e.equiangular = true;
  else if (f.equiangular == "off") e.equiangular = false;
  else if (f.equiangular.empty() || f.equiangular == "auto")
    e.equiangular = !e.bdpt && equiangular_combines(e) && std::any_of(scene.media.begin(), scene.media.end(), [](const Medium& m) {
                      return m.supported && m.sigma_s.any_positive();
                    });
  else throw std::invalid_argument("--equiangular: '" + f.equiangular + "' is not auto, on or off");
  // --light-paths: auto is on where the scene holds paths only the light tracer finds at a
  // steady rate (light_paths_pay) and nothing refuses it
  if (e.bdpt && (f.light_paths.empty() || f.light_paths == "auto")) e.light_paths = false;  // (bdpt has them all)
  else if (f.light_paths == "on" || f.light_paths == "true") e.light_paths = true;
  else if (f.light_paths == "glossy") e.light_paths = e.light_paths_glossy = true;
  else if (f.light_paths == "off" || f.light_paths == "false") e.light_paths = false;
  else if (f.light_paths.empty() || f.light_paths == "auto") {
    const LightPathsPay pay =
        e.max_depth >= 2 && !o.aov_variance && !(f.target_error > 0)
            ? light_paths_pay(scene, e.strategy != Strategy::ris)
            : LightPathsPay::no;
    e.light_paths = pay != LightPathsPay::no;
    e.light_paths_glossy = pay == LightPathsPay::glossy;
  }
  else throw std::invalid_argument("--light-paths: '" + f.light_paths + "' is not auto, on, glossy or off");
  validate(o);
  return o;
}

}  // namespace tuile
