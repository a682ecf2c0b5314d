// Checkpoints: a render's film (double sums, sums of squares, MIS-weight sums, largest
// samples, sample count) saved atomically beside its output, with the fingerprint of what
// produced it, so that `tuile render ... --resume` continues it to the bits of a render
// that never stopped, and refuses anything else.
//
// File: OUT.checkpoint beside the output OUT. Layout (native x86-64 byte order): the
// magic "TUILECKP", a format version, the fingerprint (length and text), the pass plan,
// width, height and sample count, the film's arrays, then a CRC-32 of all the bytes before
// it: a file cut short or damaged is refused, never half-read.
#pragma once
#include <string>

#include "render/film.h"
#include "render/options.h"
#include "render/passes.h"
#include "scene/scene.h"

namespace tuile {

std::string checkpoint_path(const std::string& output);

// What must match for a checkpoint to be resumed: the scene (its source and a CRC-32 of
// its camera, geometry, materials, textures and lights), the resolution, the estimator and
// sampler with their seed (and spp with the stratified sampler, whose strata depend on it),
// whether the MIS-weight AOV is kept, and the pass plan. Threads, tile size, pipeline and
// bounce-ray mode are left out: they do not change the bits.
std::string render_fingerprint(const Scene& scene, const RenderOptions& options, const PassPlan& plan);

struct Checkpoint {
  std::string fingerprint;
  PassPlan plan;
  Film film;
};

// Atomic (scene/atomic_file.h): a kill at any moment leaves the previous checkpoint whole.
void save_checkpoint(const std::string& path, const std::string& fingerprint, const PassPlan& plan, const Film& film);
// Throws std::runtime_error naming the file when it is missing, not a checkpoint, damaged
// or cut short.
Checkpoint load_checkpoint(const std::string& path);

}  // namespace tuile
