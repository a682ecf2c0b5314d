// The pbrt-v4 scene reader: a subset of the format large enough for the course's scenes
// and Bitterli's pbrt-v4 conversions. Geometry is flattened to world-space triangle
// meshes and spheres; non-diffuse materials are approximated as diffuse (with a warning
// in Scene::warnings). See scenes/README.md for what is supported.
#pragma once
#include <string>

#include "scene/scene.h"

namespace tuile {

// Reads a .pbrt or .pbrt.gz file (and the files it includes and the meshes and images
// it names). Does not call finalize_scene. Throws SceneError with a message of the form
// "FILE:LINE:COL: error: MESSAGE (expected ...)".
Scene load_pbrt(const std::string& path, const LoadOptions& options = {});

// The same for text in memory: virtual_name names it in messages and Mesh::name;
// relative file names (Include, plymesh, imagemap) are resolved against base_dir.
Scene load_pbrt_string(const std::string& text, const std::string& virtual_name,
                       const std::string& base_dir, const LoadOptions& options = {});

}  // namespace tuile
