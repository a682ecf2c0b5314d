#include "commands.h"

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <iostream>

#include "embree.h"
#include "image_io.h"
#include "render.h"

namespace tuile {

void add_bench_flags(CLI::App& app, BenchFlags& f) {
  app.add_option("--repeat", f.repeat, "timed renders")->capture_default_str();
  app.add_option("--warmup", f.warmup, "untimed renders first")->capture_default_str();
  app.add_option("--json", f.json, "write the figures as JSON");
}
void add_profile_flags(CLI::App& app, ProfileFlags& f) {
  app.add_option("--trace", f.trace, "Chrome trace-event JSON");
  app.add_flag("--roofline", f.roofline, "compare with Embree alone on the same rays");
}
static double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

static std::string png_path_for(const std::string& exr) {
  const size_t dot = exr.find_last_of('.');
  const size_t slash = exr.find_last_of('/');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return exr + ".png";
  return exr.substr(0, dot) + ".png";
}

int run_render(const RenderFlags& f) {
  const auto t0 = std::chrono::steady_clock::now();
  Scene scene = load_scene(f.scene);
  RenderOptions opt = resolve_options(f, scene);
  for (const std::string& w : scene.warnings)
    if (!f.quiet) std::cerr << "tuile: warning: " << w << "\n";
  if (scene.lights.empty() && !f.quiet) std::cerr << "tuile: warning: the scene has no light; the image is black\n";
  std::string out = !f.output.empty() ? f.output : "tuile.exr";
  Accel accel(scene);
  Renderer renderer(scene, accel, opt);
  Film film;
  film.reset(scene.camera.width, scene.camera.height);
  const double setup = seconds_since(t0);
  const RenderStats st = renderer.render(film, 0, opt.est.spp);
  std::vector<ImageLayer> layers;
  if (opt.aov_variance) layers.push_back({"variance", 3, film.variance_of_mean()});
  if (opt.aov_mis_weight) layers.push_back({"mis_weight", 1, film.mis_weight()});
  const std::vector<float> img = film.mean();
  write_exr(out, film.width, film.height, img, layers);
  write_png(png_path_for(out), film.width, film.height, img);
  if (!f.quiet) {
    std::fprintf(stderr, "tuile: %s %dx%d, %u spp, %s\n", scene.source.c_str(), film.width, film.height, opt.est.spp,
                 describe(opt.est).c_str());
    std::fprintf(stderr, "tuile: setup %.3f s, render %.3f s, %.2f M samples/s -> %s\n", setup, st.seconds,
                 st.seconds > 0 ? static_cast<double>(st.samples) / st.seconds * 1e-6 : 0.0, out.c_str());
  }
  if (f.stats) {
    const std::vector<float> var = film.variance_of_mean();
    double mv = 0;
    for (float v : var) mv += v;
    mv /= var.empty() ? 1.0 : static_cast<double>(var.size());
    std::printf("rejected_nonfinite camera=%llu light=%llu bsdf=%llu\n",
                static_cast<unsigned long long>(st.rejected_camera), static_cast<unsigned long long>(st.rejected_light),
                static_cast<unsigned long long>(st.rejected_bsdf));
    std::printf("worst_accident %.6g (largest single-sample luminance / its pixel's mean)\n", st.worst_ratio);
    std::printf("mean_variance_of_mean %.6g\n", mv);
  }
  return 0;
}

int run_info(const RenderFlags& f) {
  const auto t0 = std::chrono::steady_clock::now();
  Scene scene = load_scene(f.scene);
  const double load = seconds_since(t0);
  RenderOptions opt = resolve_options(f, scene);
  const auto t1 = std::chrono::steady_clock::now();
  Accel accel(scene);
  const double bvh = seconds_since(t1);
  size_t area = 0, delta = 0;
  for (const Light& l : scene.lights) (is_delta(l.type) ? delta : area)++;
  std::printf("scene: %s\n", scene.source.c_str());
  std::printf("resolution: %dx%d\n", scene.camera.width, scene.camera.height);
  std::printf("triangles: %zu\nspheres: %zu\nmeshes: %zu\nmaterials: %zu\ntextures: %zu\n", scene.triangle_count(),
              scene.spheres.size(), scene.meshes.size(), scene.materials.size(), scene.textures.size());
  std::printf("lights: %zu (area sources %zu, delta %zu)\n", scene.lights.size(), area, delta);
  std::printf("features:");
  const char* names[] = {"area-lights", "delta-lights", "single-light", "textures", "spheres", "visible-emitters"};
  for (int i = 0; i < 6; ++i)
    if (scene.features & (1u << i)) std::printf(" %s", names[i]);
  std::printf("\nestimator: %s\n", describe(opt.est).c_str());
  for (const std::string& w : scene.warnings) std::printf("approximation: %s\n", w.c_str());
  std::printf("load: %.3f s\nbvh build: %.3f s\n", load, bvh);
  return 0;
}

int run_bench(const BenchFlags&) {
  std::cerr << "tuile bench: not implemented yet\n";
  return 2;
}
int run_profile(const ProfileFlags&) {
  std::cerr << "tuile profile: not implemented yet\n";
  return 2;
}
}  // namespace tuile
