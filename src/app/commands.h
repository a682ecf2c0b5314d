// The subcommands, callable from main and from tests.
#pragma once
#include <string>

#include "app/cli.h"

namespace tuile {

struct BenchFlags {
  RenderFlags render;
  int repeat = 5, warmup = 1;
  std::string json;
};
struct ProfileFlags {
  RenderFlags render;
  std::string trace;
  bool roofline = false;
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
int run_bench(const BenchFlags& f);
int run_profile(const ProfileFlags& f);
int run_converge(const ConvergeFlags& f);  // src/measure/converge.cpp
int run_figures(const FiguresFlags& f);    // src/measure/figures.cpp
int run_diff(const DiffFlags& f);          // src/measure/image_diff.cpp
int run_envmap(const EnvmapFlags& f);      // src/app/commands.cpp

}  // namespace tuile
