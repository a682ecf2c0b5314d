// The profiled stages' names.
#include "render/profile.h"

namespace tuile {

const char* stage_name(Stage s) {
  static const char* names[] = {"generate",       "intersect camera", "surface hits", "sample lights",
                                "intersect shadow", "sample BSDF",  "intersect bounce", "MIS weight",
                                "accumulate",     "media"};
  return names[static_cast<int>(s)];
}

}  // namespace tuile
