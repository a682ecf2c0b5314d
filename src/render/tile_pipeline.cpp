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
  Features f;
  f.light = v.lights.count > 0 && (est.strategy != Strategy::bsdf || delta);
  const bool ris = est.strategy == Strategy::ris && v.lights.count > 0;
  // a specular surface needs its BSDF samples whatever the strategy: no light sample finds
  // the light it reflects (sample_bsdf traces only those under --strategy light)
  f.bsdf = area && (est.strategy != Strategy::light || (v.bsdf_kinds & bsdf_delta_capable) != 0);
  f.pick = f.light && v.lights.count > 1 && est.pick != LightPick::all;
  f.emitter_lookup = area;  // only area sources are seen by camera and bounce rays
  f.kinds = !area && !delta ? kind_all : !area ? kind_delta : delta ? kind_all : v.all_rects() ? kind_area | kind_rects : kind_area;
  f.bsdfs = materials ? bsdf_all : bsdf_diffuse;
  if (materials) f.kinds = kind_all;  // one pipeline per technique for every other surface
  if (est.max_depth > 1 && (area || delta)) {
    // paths go on along a BSDF sample at every vertex, and their bounce rays look up
    // the emitters they reach whatever the sources
    f.bsdf = true;
    f.emitter_lookup = true;
    if (!area) f.kinds = kind_all;
  }
  if (ris) {  // the BSDF candidates and the last BSDF sample run on every scene with lights
    f.bsdf = true;
    f.emitter_lookup = true;
    if (!area) f.kinds = kind_all;
  }
  if (!f.light && !f.bsdf) f = Features{kind_all, false, false, false, false, bsdf_diffuse};
  why = std::string(area ? "area lights" : "no area light") + ", " + (delta ? "delta lights" : "no delta light") + ", " +
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
      std::string name = general ? std::string("general") : features_name(f);
      if (general_pipeline_only && i != 0) name += " (run by the general pipeline: TUILE_PIPELINES=general)";
      return {name, registered_functions()[i]};
    }
  throw std::logic_error("no registered pipeline for " + features_name(f));
}

bool pipeline_registered(const Features& f) {
  return std::find(std::begin(registered_pipelines), std::end(registered_pipelines), f) != std::end(registered_pipelines);
}

}  // namespace tuile
