// Part 0 of the registered tile pipelines (render/tile_pipeline.h: pipeline_part_of).
#include "render/tile_run.h"

namespace tuile {
static_assert(0 < pipeline_parts);
template void register_pipeline_part<0>(TileFn*);
}  // namespace tuile
