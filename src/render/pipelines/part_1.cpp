// Part 1 of the registered tile pipelines (render/tile_pipeline.h: pipeline_part_of).
#include "render/tile_run.h"

namespace tuile {
static_assert(1 < pipeline_parts);
template void register_pipeline_part<1>(TileFn*);
}  // namespace tuile
