// What the subcommands share: the scene loaded with its options resolved and its BVH
// built (with the times each took), and two small helpers.
#pragma once
#include <chrono>
#include <memory>
#include <string>

#include "accel/embree.h"
#include "app/cli.h"
#include "render/options.h"
#include "scene/scene.h"

namespace tuile {

struct Prepared {
  Scene scene;
  RenderOptions opt;
  std::unique_ptr<Accel> accel;
  double load_seconds = 0, bvh_seconds = 0;
};

// Loads the scene, resolves the flags against it, builds the BVH. Throws SceneError or
// std::invalid_argument naming the file or the flag.
Prepared prepare(const RenderFlags& f);

double seconds_since(std::chrono::steady_clock::time_point t0);
// path with its extension replaced ("out.exr", ".png" -> "out.png").
std::string with_extension(const std::string& path, const char* ext);

}  // namespace tuile
