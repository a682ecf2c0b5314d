// tuile: one binary, subcommands render | info | bench | profile | converge | figures | diff | envmap.
#include <unistd.h>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "app/cli.h"
#include "app/commands.h"
#include "dist/dist.h"
#include "accel/embree.h"
#include "scene/image_io.h"
#include "render/render.h"
#include "scene/scene.h"

using namespace tuile;

namespace {

bool light_paths_mode(const std::string& w) { return w == "auto" || w == "on" || w == "glossy" || w == "off"; }

// CLI11's message for an option given more than once ("--spp: At Most 1 required but
// received 2"), said plainly; its other messages as they are
std::string parse_error_message(const std::string& what) {
  const std::string mid = ": At Most 1 required but received ";
  const size_t at = what.find(mid);
  if (at == std::string::npos || at == 0) return what;
  return what.substr(0, at) + " is given " + what.substr(at + mid.size()) +
         " times: give each option once (a flag, or one value)";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tuile: a SIMD tile renderer for Monte Carlo direct lighting with variance reduction"};
  app.set_version_flag("--version", std::string("tuile ") + TUILE_VERSION);
  app.require_subcommand(1);

  RenderFlags rf;
  CLI::App* render = app.add_subcommand("render", "render a scene to OpenEXR (+ PNG preview)");
  add_render_flags(*render, rf);
  add_render_run_flags(*render, rf);
  add_mpi_flags(*render, rf);
  render->add_option("-o,--output", rf.output,
                     "output .exr (a .png preview is written beside it); default: the scene's Film filename, else tuile.exr");

  RenderFlags inf;
  CLI::App* info = app.add_subcommand("info", "scene statistics, detected features and the pipeline that will run");
  add_render_flags(*info, inf);

  BenchFlags bf;
  CLI::App* bench = app.add_subcommand("bench", "samples per second over repeated renders");
  add_render_flags(*bench, bf.render);
  add_bench_flags(*bench, bf);
  add_mpi_flags(*bench, bf.render);

  ProfileFlags pf;
  CLI::App* profile = app.add_subcommand("profile", "time per kernel stage");
  add_render_flags(*profile, pf.render);
  add_profile_flags(*profile, pf);

  ConvergeFlags cf;
  CLI::App* converge = app.add_subcommand("converge", "error against run time per strategy");
  add_render_flags(*converge, cf.render);
  add_converge_flags(*converge, cf);

  FiguresFlags ff;
  CLI::App* figures = app.add_subcommand("figures", "the course's figures as labelled PNG contact sheets");
  add_figures_flags(*figures, ff);

  DiffFlags df;
  CLI::App* diff = app.add_subcommand("diff", "compare two EXR images: identical bits, or by how much they differ");
  add_diff_flags(*diff, df);

  EnvmapFlags ef;
  CLI::App* envmap = app.add_subcommand(
      "envmap", "convert a latitude-longitude environment map (HDR, EXR, PFM, PNG) to the equal-area square of pbrt-v4's infinite lights");
  add_envmap_flags(*envmap, ef);

  for (int i = 0; i < argc; ++i) {  // the command line, shell-quoted, for the EXR header
    std::string a = argv[i];
    const bool plain = !a.empty() && a.find_first_of(" \t\n'\"\\$`*?[]{}()<>|&;#~") == std::string::npos;
    if (!plain) {
      std::string q = "'";
      for (char ch : a) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
      a = q + "'";
    }
    rf.command_line += (i ? " " : "") + a;
  }
  // `--light-paths off`, its value after a space as every other option takes one, is read as
  // `--light-paths=off`: the flag's value is optional, and CLI11 alone would take the word
  // for a stray positional argument
  std::vector<std::string> args(argv, argv + argc);
  for (size_t i = 1; i + 1 < args.size(); ++i)
    if ((args[i] == "--light-paths" && light_paths_mode(args[i + 1])) ||
        (args[i] == "--bdpt" && (args[i + 1] == "auto" || args[i + 1] == "on" || args[i + 1] == "off"))) {
      args[i] += "=" + args[i + 1];
      args.erase(args.begin() + static_cast<std::ptrdiff_t>(i) + 1);
    }
  std::vector<const char*> args_c;
  for (const std::string& a : args) args_c.push_back(a.c_str());
  try {
    app.parse(static_cast<int>(args_c.size()), args_c.data());
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
    if (launcher_rank() == 0)  // under mpirun every rank parses the same line: one message
      std::cerr << "tuile: error: " << parse_error_message(e.what()) << "\nRun with --help for more information.\n";
    return 1;
  }
  try {
    const bool ranks = launcher_size() > 1;  // started by mpirun with several ranks
    if (*render) return ranks ? run_render_distributed(rf) : run_render(rf);
    if (*info) return run_info(inf);
    if (*bench) return ranks ? run_bench_distributed(bf) : run_bench(bf);
    if (*profile) return run_profile(pf);
    if (*converge) return run_converge(cf);
    if (*figures) return run_figures(ff);
    if (*diff) return run_diff(df);
    if (*envmap) return run_envmap(ef);
  } catch (const SceneError& e) {
    if (launcher_rank() == 0) std::cerr << "tuile: " << e.what() << "\n";
    return 1;
  } catch (const std::invalid_argument& e) {
    if (launcher_rank() == 0) std::cerr << "tuile: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    if (launcher_rank() == 0) std::cerr << "tuile: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
