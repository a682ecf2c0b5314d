#include "commands.h"

#include <iostream>

namespace tuile {

void add_converge_flags(CLI::App& app, ConvergeFlags& f) {
  app.add_option("--reference", f.reference, "reference EXR");
  app.add_option("--strategies", f.strategies, "comma-separated strategies");
  app.add_option("--budget", f.budget, "seconds per strategy");
  app.add_option("--csv", f.csv, "CSV output");
  app.add_option("--plot", f.plot, "plot output");
}

int run_converge(const ConvergeFlags&) {
  std::cerr << "tuile converge: not implemented yet\n";
  return 2;
}

}  // namespace tuile
