// The registry of instantiated pipelines (their code: render/tile_run.h, compiled in
// render/pipelines/part_<k>.cpp) and the choice of one for a scene and estimator.
#include "render/tile_pipeline.h"

#include <algorithm>
#include <array>
#include <iterator>
#include <stdexcept>
#include <utility>

namespace tuile {

namespace {

template <int... K> std::array<TileFn, pipeline_count> collect_parts(std::integer_sequence<int, K...>) {
  std::array<TileFn, pipeline_count> table{};
  (register_pipeline_part<K>(table.data()), ...);
  for (size_t i = 0; i < pipeline_count; ++i) {
    if (general_pipeline_only) table[i] = table[0];
    if (!table[i]) throw std::logic_error("pipeline " + features_name(registered_pipelines[i]) + " is in no part");
  }
  return table;
}
// Every registered pipeline's function, filled by the parts once.
const std::array<TileFn, pipeline_count>& registered_functions() {
  static const std::array<TileFn, pipeline_count> table = collect_parts(std::make_integer_sequence<int, pipeline_parts>());
  return table;
}

}  // namespace

Features pipeline_features(const SceneViews& v, const Estimator& est, bool general, std::string& why) {
  if (general) {
    why = "forced with --pipeline general";
    return general_features;
  }
  const bool area = v.has_area(), delta = v.has_delta();
  const bool materials = v.has_materials();
  PipelineFacts x;
  x.scene = v.features;
  x.lights = std::min(v.lights.count, 2);
  x.materials = materials;
  x.delta_surfaces = (v.bsdf_kinds & bsdf_delta_capable) != 0;
  x.strategy = est.strategy;
  x.pick_all = est.pick == LightPick::all;
  x.paths = est.max_depth > 1;
  const Features f = features_for(x);
  why = std::string(area ? "area lights" : "no area light") + ", " + (delta ? "delta lights" : "no delta light") + ", " +
        ((v.features & feat_sky) ? "a sky (the general pipeline), " : "") +
        ((v.features & feat_media) ? "participating media (the general pipeline), " : "") +
        std::to_string(v.lights.count) + " light(s), pick " + (f.pick ? "per lane" : "none") + ", strategy " +
        (est.strategy == Strategy::mis     ? "mis"
         : est.strategy == Strategy::light ? "light"
         : est.strategy == Strategy::ris   ? "ris"
                                           : "bsdf") +
        (materials ? ", surfaces other than diffuse" : ", diffuse surfaces") +
        (est.max_depth > 1 ? ", paths of up to " + std::to_string(est.max_depth) + " vertices" : "");
  return f;
}

PipelineEntry pick_pipeline(const SceneViews& v, const Estimator& est, bool general, std::string& why) {
  const Features f = pipeline_features(v, est, general, why);
  for (size_t i = 0; i < pipeline_count; ++i)
    if (registered_pipelines[i] == f) {
      std::string name = general || f == general_features ? std::string("general") : features_name(f);
      if (general_pipeline_only && i != 0) name += " (run by the general pipeline: TUILE_PIPELINES=general)";
      return {name, registered_functions()[i]};
    }
  throw std::logic_error("no registered pipeline for " + features_name(f));
}

bool pipeline_registered(const Features& f) {
  return std::find(std::begin(registered_pipelines), std::end(registered_pipelines), f) != std::end(registered_pipelines);
}

}  // namespace tuile
