// The options of one render (estimator, bounce-ray mode, threads, tile size, AOVs,
// pipeline) and their names on the command line and in scene files.
#pragma once
#include <string>

#include "sample/filter.h"
#include "wave/estimator.h"

namespace tuile {

// What a BSDF (bounce) ray is traced against. scene: its nearest hit in the whole scene.
// emitters: its nearest emitter, then, for the rays that reach the front of one, an
// occlusion ray up to it (2^-12 short, as shadow rays): the same estimator, with far
// fewer nodes visited where the emitters are a small part of the scene. automatic:
// emitters where they are at most half of the scene's primitives.
enum class BounceTrace : int { automatic = 0, scene = 1, emitters = 2 };

struct RenderOptions {
  Estimator est;
  BounceTrace bounce = BounceTrace::automatic;
  int threads = 0;    // 0 = all cores
  int tile = 16;      // 16 or 32 (any 1..32 accepted)
  bool aov_variance = false;
  bool aov_mis_weight = false;
  bool general_pipeline = false;  // --pipeline general: the unspecialised reference
  FilterParams filter;            // the pixel filter (--filter, else the scene file's PixelFilter; default box 1/2)
};

// Throws std::invalid_argument, naming the flag, for settings out of range (every caller
// of the renderer gets the same checks: the command line, converge, figures, tests).
void validate(const RenderOptions& o);
// Whether --equiangular combines with the rest of the estimator (its default, auto, is on
// where it does, in scenes with a medium that scatters).
bool equiangular_combines(const Estimator& e);

// Parses the names used on the command line and in scene files; throw std::invalid_argument.
Strategy parse_strategy(const std::string& s);
LightPick parse_light_pick(const std::string& s);
LightPoint parse_light_point(const std::string& s);
Heuristic parse_heuristic(const std::string& s);
MisMode parse_mis_mode(const std::string& s);
SamplerKind parse_sampler(const std::string& s);
BounceTrace parse_bounce_trace(const std::string& s);
std::string describe(const Estimator& e);

}  // namespace tuile
