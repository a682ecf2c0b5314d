// The subcommands, callable from main and from tests.
#pragma once
#include <atomic>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "app/cli.h"

namespace tuile {

struct BenchFlags {
  RenderFlags render;
  int repeat = 5, warmup = 1;
  std::string json;
  bool print = true;  // the figures on stdout (the Python module asks for the JSON alone)
};
struct ProfileFlags {
  RenderFlags render;
  std::string trace, json;
  bool roofline = false;
  bool print = true;
};
struct ConvergeFlags {
  RenderFlags render;
  std::string reference, strategies, csv, plot;
  double budget = 10;
  int spp_max = 0;        // 0 = no limit but the budget
  int reference_spp = 0;  // 0 = 64x the largest spp a quick calibration says fits the budget
};

struct FiguresFlags {
  std::string out = "figures";
  int threads = 0;
  bool quick = false;  // smaller images and sample counts (tests)
};

struct DiffFlags {
  std::string a, b;
  double tolerance = 0;  // largest relative difference still accepted (0: bit-identical only)
};

// tuile envmap IN OUT: a latitude-longitude map to pbrt-v4's equal-area square (imgtool
// makeequiarea's job).
struct EnvmapFlags {
  std::string in, out;
  int resolution = 0;  // texels per side (0: the input's width, as imgtool)
  int samples = 4;     // per side of each texel
};

void add_figures_flags(CLI::App& app, FiguresFlags& f);
void add_envmap_flags(CLI::App& app, EnvmapFlags& f);
void add_diff_flags(CLI::App& app, DiffFlags& f);
void add_bench_flags(CLI::App& app, BenchFlags& f);
void add_profile_flags(CLI::App& app, ProfileFlags& f);
void add_converge_flags(CLI::App& app, ConvergeFlags& f);

int run_render(const RenderFlags& f);
int run_info(const RenderFlags& f);
// What `tuile info` prints about a loaded scene ("key: value" lines).
struct Prepared;
std::string info_text(const Prepared& p);
// With `json`, the figures also as a JSON object (what --json writes).
int run_bench(const BenchFlags& f, std::string* json = nullptr);
int run_profile(const ProfileFlags& f, std::string* json = nullptr);
int run_converge(const ConvergeFlags& f);  // src/measure/converge.cpp
// converge's measurement on a loaded scene, without files: each strategy's rows (one per
// doubling pass) and last image; the reference rendered (mis:power, another seed) when
// `reference` is empty, handed to on_reference before the strategies start. The rows on
// stdout when `print`. `cancel` set: ConvergeCancelled at the next tile boundary.
struct ConvergeRow {
  std::string strategy;
  uint64_t spp;
  double seconds, mse, relmse, efficiency;
};
struct ConvergeResult {
  int width = 0, height = 0;
  std::vector<ConvergeRow> rows;
  std::vector<float> reference;
  uint64_t reference_spp = 0;  // 0: the reference was given
  std::vector<std::pair<std::string, std::vector<float>>> images;
};
struct ConvergeCancelled : std::runtime_error {
  ConvergeCancelled() : std::runtime_error("converge was cancelled") {}
};
class Accel;
ConvergeResult converge(const ConvergeFlags& f, Scene& scene, const Accel& accel, std::vector<float> reference, bool print,
                        const std::atomic<bool>* cancel = nullptr,
                        const std::function<void(const std::vector<float>&)>& on_reference = {});
std::vector<std::string> converge_strategy_names();
int run_figures(const FiguresFlags& f);    // src/measure/figures.cpp
int run_diff(const DiffFlags& f);          // src/measure/image_diff.cpp
int run_envmap(const EnvmapFlags& f);      // src/app/commands.cpp

}  // namespace tuile
