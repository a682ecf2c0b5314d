// The estimator and renderer options by the names the command line and scene files use.
#include "render/options.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "render/filter_table.h"
#include "wave/tile.h"

namespace tuile {

void validate(const RenderOptions& o) {
  const Estimator& e = o.est;
  auto finite = [](float v, const char* flag) {
    if (!std::isfinite(v)) throw std::invalid_argument(std::string(flag) + " must be a finite number");
  };
  finite(e.mis.beta, "--beta");
  finite(e.mis.alpha, "--alpha");
  if (!(e.mis.beta > 0)) throw std::invalid_argument("--beta must be > 0");
  if (!(e.mis.alpha >= 0 && e.mis.alpha <= 1)) throw std::invalid_argument("--alpha must be in [0, 1]");
  if (e.light_samples < 1 || e.light_samples > 4096) throw std::invalid_argument("--light-samples must be in 1..4096");
  if (e.bsdf_samples < 1 || e.bsdf_samples > 4096) throw std::invalid_argument("--bsdf-samples must be in 1..4096");
  if (e.strategy == Strategy::ris) {
    if (e.ris_light < 0 || e.ris_light > 1024) throw std::invalid_argument("--ris-light must be in 0..1024");
    if (e.ris_bsdf < 0 || e.ris_bsdf > 1024) throw std::invalid_argument("--ris-bsdf must be in 0..1024");
    if (e.ris_light + e.ris_bsdf < 1) throw std::invalid_argument("--strategy ris needs --ris-light + --ris-bsdf >= 1");
    if (e.pick == LightPick::all)
      throw std::invalid_argument("--strategy ris picks a source per candidate: --light-pick all does not apply");
  }
  if (e.heuristic == Heuristic::optimal) {
    if (e.strategy != Strategy::mis)
      throw std::invalid_argument("--heuristic optimal weighs the light and BSDF techniques: it needs --strategy mis");
    if (e.one_sample() && e.pick == LightPick::all)
      throw std::invalid_argument("--heuristic optimal with --mis-mode one picks one source: --light-pick all does not apply");
  }
  if (e.max_depth < 1 || e.max_depth > 100000) throw std::invalid_argument("--max-depth must be in 1..100000");
  if (e.guide) {
    if (e.max_depth < 2) throw std::invalid_argument("--guide guides paths: it needs --max-depth 2 or more");
    if (e.strategy != Strategy::mis && e.strategy != Strategy::bsdf)
      throw std::invalid_argument("--guide mixes the guide into the BSDF technique: it needs --strategy mis or bsdf");
    if (e.one_sample()) throw std::invalid_argument("--guide needs --mis-mode multi");
    if (e.heuristic == Heuristic::optimal) throw std::invalid_argument("--guide does not combine with --heuristic optimal");
    if (e.guide_learn < 1 || e.guide_learn > 1u << 20) throw std::invalid_argument("--guide-learn must be in 1..1048576");
    if (!(e.guide_alpha > 0.f && e.guide_alpha < 1.f)) throw std::invalid_argument("--guide-alpha must be in (0, 1)");
  }
  if (e.equiangular) {
    if (e.strategy != Strategy::mis && e.strategy != Strategy::light)
      throw std::invalid_argument("--equiangular adds light samples along the rays in media: it needs --strategy mis or light");
    if (e.one_sample()) throw std::invalid_argument("--equiangular needs --mis-mode multi");
    if (e.pick == LightPick::all)
      throw std::invalid_argument("--equiangular picks one source per ray: --light-pick all does not apply");
    if (e.heuristic == Heuristic::optimal) throw std::invalid_argument("--equiangular does not combine with --heuristic optimal");
    if (e.guide) throw std::invalid_argument("--equiangular does not combine with --guide");
  }
  if (e.light_paths) {
    if (e.max_depth < 2)
      throw std::invalid_argument("--light-paths joins paths of two vertices or more to the camera: it needs --max-depth 2 "
                                  "or more");
    if (e.light_paths_glossy && e.strategy == Strategy::ris)
      throw std::invalid_argument("--light-paths=glossy leaves an area light's samples at near-specular vertices to the "
                                  "light tracer, and --strategy ris's BSDF candidates there do not: use mis, light or bsdf");
    if (o.aov_variance)
      throw std::invalid_argument("--light-paths: the variance layer is estimated from the camera's samples alone, "
                                  "which the light paths' contributions are not; leave out --aov variance");
  }
  if (e.bdpt) {
    if (e.guide) throw std::invalid_argument("--bdpt does not combine with --guide");
    if (e.light_paths) throw std::invalid_argument("--bdpt traces light paths of its own: leave out --light-paths");
    if (e.equiangular) throw std::invalid_argument("--bdpt does not combine with --equiangular (its own strategies sample the media)");
    if (e.regularize) throw std::invalid_argument("--bdpt does not combine with --regularize");
    if (e.heuristic == Heuristic::optimal)
      throw std::invalid_argument("--bdpt weighs its strategies by the balance heuristic: --heuristic optimal does not apply");
    if (o.aov_variance)
      throw std::invalid_argument("--bdpt: the variance layer is estimated from the camera's samples alone, which bdpt's "
                                  "light paths are not; leave out --aov variance");
    if (o.est.aov_mis_weight) throw std::invalid_argument("--bdpt: the mis_weight layer is the path tracer's; leave it out");
  }
  if (e.rr_depth < 0 || e.rr_depth > 100000) throw std::invalid_argument("--rr-depth must be in 0..100000");
  if (!(e.rr_threshold > 0.f && e.rr_threshold <= 1000.f))
    throw std::invalid_argument("--rr-threshold must be in (0, 1000]");
  if (o.threads < 0 || o.threads > 1024) throw std::invalid_argument("--threads must be in 0..1024");
  if (o.tile < 1 || o.tile > max_tile_side) throw std::invalid_argument("--tile must be in 1..32");
  std::string param;
  const std::string filter = filter_problem(o.filter, &param);
  if (!filter.empty()) throw std::invalid_argument("--filter " + describe(o.filter) + ": " + param + " must be " + filter);
}

bool equiangular_combines(const Estimator& e) {
  return (e.strategy == Strategy::mis || e.strategy == Strategy::light) && !e.one_sample() && e.pick != LightPick::all &&
         e.heuristic != Heuristic::optimal && !e.guide;
}

Strategy parse_strategy(const std::string& s) {
  if (s == "light") return Strategy::light;
  if (s == "bsdf") return Strategy::bsdf;
  if (s == "mis") return Strategy::mis;
  if (s == "ris") return Strategy::ris;
  throw std::invalid_argument("unknown strategy '" + s + "' (expected light, bsdf, mis or ris)");
}
LightPick parse_light_pick(const std::string& s) {
  if (s == "all") return LightPick::all;
  if (s == "uniform") return LightPick::uniform;
  if (s == "area") return LightPick::area;
  if (s == "power") return LightPick::power;
  if (s == "bvh") return LightPick::bvh;
  throw std::invalid_argument("unknown light pick '" + s + "' (expected all, uniform, area, power or bvh)");
}
LightPoint parse_light_point(const std::string& s) {
  if (s == "area") return LightPoint::area;
  if (s == "solid-angle") return LightPoint::solid_angle;
  throw std::invalid_argument("unknown light point '" + s + "' (expected area or solid-angle)");
}
Heuristic parse_heuristic(const std::string& s) {
  if (s == "balance") return Heuristic::balance;
  if (s == "power") return Heuristic::power;
  if (s == "cutoff") return Heuristic::cutoff;
  if (s == "maximum") return Heuristic::maximum;
  if (s == "optimal") return Heuristic::optimal;
  throw std::invalid_argument("unknown heuristic '" + s + "' (expected balance, power, cutoff, maximum or optimal)");
}
MisMode parse_mis_mode(const std::string& s) {
  if (s == "multi") return MisMode::multi;
  if (s == "one") return MisMode::one;
  throw std::invalid_argument("unknown MIS mode '" + s + "' (expected multi or one)");
}
BounceTrace parse_bounce_trace(const std::string& s) {
  if (s == "auto") return BounceTrace::automatic;
  if (s == "scene") return BounceTrace::scene;
  if (s == "emitters") return BounceTrace::emitters;
  throw std::invalid_argument("unknown bounce-rays mode '" + s + "' (expected auto, scene or emitters)");
}

SamplerKind parse_sampler(const std::string& s) {
  if (s == "independent") return SamplerKind::independent;
  if (s == "stratified") return SamplerKind::stratified;
  if (s == "sobol") return SamplerKind::sobol;
  throw std::invalid_argument("unknown sampler '" + s + "' (expected independent, stratified or sobol)");
}

std::string describe(const Estimator& e) {
  static const char* strategies[] = {"light", "bsdf", "mis", "ris"};
  static const char* picks[] = {"all", "uniform", "area", "power", "bvh"};
  static const char* points[] = {"area", "solid-angle"};
  static const char* heuristics[] = {"balance", "power", "cutoff", "maximum", "optimal"};
  static const char* samplers[] = {"independent", "stratified", "sobol"};
  std::string s = std::string("strategy=") + strategies[static_cast<int>(e.strategy)] +
                  " light-pick=" + picks[static_cast<int>(e.pick)] + " light-point=" + points[static_cast<int>(e.point)];
  if (e.strategy == Strategy::mis)
    s += std::string(" heuristic=") + heuristics[static_cast<int>(e.heuristic)] +
         (e.mode == MisMode::one ? " mis-mode=one" : " mis-mode=multi");
  if (e.strategy == Strategy::ris)
    s += " ris-light=" + std::to_string(e.ris_light) + " ris-bsdf=" + std::to_string(e.ris_bsdf);
  else
    s += " light-samples=" + std::to_string(e.light_samples) + " bsdf-samples=" + std::to_string(e.bsdf_samples);
  s += std::string("") +
       " sampler=" + samplers[static_cast<int>(e.sampler)] + " spp=" + std::to_string(e.spp) +
       " seed=" + std::to_string(e.seed);
  if (e.max_depth > 1) {
    char t[32];
    std::snprintf(t, sizeof t, "%g", static_cast<double>(e.rr_threshold));
    s += " max-depth=" + std::to_string(e.max_depth) + " rr-depth=" + std::to_string(e.rr_depth) + " rr-threshold=" + t;
  }
  if (e.regularize) s += " regularize=on";
  if (e.light_paths) s += e.light_paths_glossy ? " light-paths=glossy" : " light-paths=on";
  if (e.equiangular) s += " equiangular=on";  // (off: the description, and checkpoints' fingerprint, of earlier releases)
  if (e.bdpt) s += " bdpt=on";
  if (e.guide) {  // (likewise)
    char a[32];
    std::snprintf(a, sizeof a, "%g", static_cast<double>(e.guide_alpha));
    s += " guide=on guide-learn=" + std::to_string(e.guide_learn) + " guide-alpha=" + a;
  }
  return s;
}

}  // namespace tuile
