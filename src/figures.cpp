#include "commands.h"

#include <iostream>

namespace tuile {

void add_figures_flags(CLI::App& app, FiguresFlags& f) {
  app.add_option("--out", f.out, "output folder")->capture_default_str();
  app.add_option("--threads", f.threads, "worker threads (0 = all cores)");
  app.add_flag("--quick", f.quick, "small images and sample counts");
}

int run_figures(const FiguresFlags&) {
  std::cerr << "tuile figures: not implemented yet\n";
  return 2;
}

}  // namespace tuile
