// Features: what a tile pipeline is specialised for, as one value (a C++20 class-type
// template parameter of run_tile). A pipeline leaves out the stages, lookups and
// dispatches its scenes never need; its name is derived from its features.
//
// The rule for what is a feature and what stays a runtime setting: a feature removes
// work from the hot loop (a stage, a gather, a dispatch on the kind of source) and has
// few values; anything that only changes a number the stages read (heuristic, sample
// counts, sampler, seed) is a runtime field of Estimator.
#pragma once
#include <string>

#include "bsdf/bsdf.h"
#include "light/table.h"

namespace tuile {

struct Features {
  unsigned kinds = kind_all;   // kinds of source the pipeline can meet (kind_area, kind_delta, kind_sky, kind_rects);
                               // with kind_sky the escaped-ray stage runs (wave/escaped.h)
  bool light = true;           // the light-sampling technique's stages run
  bool bsdf = true;            // the BSDF-sampling technique's stages run
  bool pick = true;            // each lane picks a source (else every lane samples one given source)
  bool emitter_lookup = true;  // camera and bounce hits look up the emitter they reached
  unsigned bsdfs = bsdf_all;   // kinds of surface (BsdfBits): bsdf_diffuse, or every kind

  constexpr bool operator==(const Features&) const = default;
};

// Every stage and every lookup, whatever the scene: the reference that every specialised
// pipeline must match bit for bit.
inline constexpr Features general_features{};

// "rect/mis/pick", "delta/light/single", "area/bsdf", "no-lights", ...
inline std::string features_name(const Features& f) {
  if (!f.light && !f.bsdf) return "no-lights";
  const char* kinds = f.kinds == kind_delta                  ? "delta"
                      : f.kinds == (kind_area | kind_rects) ? "rect"
                      : f.kinds == kind_area                 ? "area"
                                                             : "mixed";
  const char* technique = f.light && f.bsdf ? "mis" : f.light ? "light" : "bsdf";
  std::string name = std::string(kinds) + "/" + technique;
  if (f.light) name += f.pick ? "/pick" : "/single";
  if (f.bsdfs != bsdf_diffuse) name += "/materials";
  if ((f.kinds & kind_sky) != 0) name += "/sky";
  return name;
}

}  // namespace tuile
